"""``measure_log`` from a file and from the same rows in memory: one reader, one result.

No log in ../shared/data/real is a goniometer (counter) log (its README: none public was
found), so the comparison runs on seeded synthetic logs only.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

from align import measure_log
from align.cli import main
from align.gonio import UNTIMED_EARTH, UNTIMED_EARTH_STEADY
from axisbase.errors import InputError
from axisbase.units import DEG
from goniometry.errors import LogError
from synth.gonio import GonioSpec, simulate, write_log

NAMES = ("count", "counter", "ref", "t")


def _file_and_rows(tmp_path, spec: GonioSpec):
    path = write_log(simulate(spec), tmp_path / "log.csv")
    # The rows as the file holds them (t written to 9 decimals), read by numpy, not the tool.
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    return path, {k: table[:, i] for i, k in enumerate(NAMES)}


def _same(from_file, from_rows) -> None:
    """The same JSON, number for number, but for the exclusions' lines: a file's name its
    lines, the rows' their indexes (the header line and 1-based lines: 2 apart)."""
    faces = ["f0", "f1", "f2", "f3"]
    a, b = from_file.to_dict(faces), from_rows.to_dict(faces)
    for e in a["exclusions"].values():
        e["lines"] = [ln - 2 for ln in e["lines"]]
    assert json.dumps(a) == json.dumps(b)


@pytest.mark.parametrize("seed", [11, 12])
def test_rows_in_memory_give_the_file_s_result(tmp_path, seed):
    # Faults (missing and spurious pulses) make the exclusions and their lines part of the
    # comparison; 3000 revolutions are a few chunks of the file's and one of the rows'.
    spec = GonioSpec(revolutions=3000, seed=seed, p_missing=1e-3, p_spurious=1e-3)
    path, rows = _file_and_rows(tmp_path, spec)
    from_file = measure_log(path, 4, latitude_rad=50.45 * DEG)
    from_rows = measure_log(rows, 4, latitude_rad=50.45 * DEG)
    _same(from_file, from_rows)
    assert from_file.summary.excluded_revolutions > 0  # (the faults were there to compare)


def test_every_kind_of_rows_and_the_loop_path(tmp_path):
    # Without the latitude the loop runs (another branch of measure_log); a structured array
    # and a pyarrow Table with other header names (aliases, a unit) go the same way.
    path, rows = _file_and_rows(tmp_path, GonioSpec(revolutions=400, seed=5))
    _same(measure_log(path, 4), measure_log(rows, 4))
    from_file = measure_log(path, 4, latitude_rad=50.45 * DEG)
    _same(from_file, measure_log(pa.table(rows), 4, latitude_rad=50.45 * DEG))
    structured = np.zeros(len(rows["t"]), dtype=[("counts", "i8"), ("counter", "i8"),
                                                  ("REF", "i8"), ("t [ms]", "f8")])
    for k, name in zip(NAMES, structured.dtype.names, strict=True):
        structured[name] = rows[k] * (1e3 if k == "t" else 1)
    # t in ms is converted to s (x 1e-3): not bit for bit, the same to far below u.
    ms = measure_log(structured, 4, latitude_rad=50.45 * DEG)
    assert np.allclose(ms.angles.angles_rad, from_file.angles.angles_rad, rtol=0,
                       atol=1e-3 * float(np.min(from_file.angles.u_rad)))


@pytest.mark.parametrize(("column", "row", "value", "what"), [
    ("ref", 9, 2, "ref: must be 0 or 1"),
    ("count", 4, -1, "count: must not be negative"),
    ("t", 6, np.nan, "t: is not a finite number"),
    ("t", 3, 0.0, "t: 0 runs backwards"),
])
def test_a_bad_row_is_named_by_its_index(tmp_path, column, row, value, what):
    _, rows = _file_and_rows(tmp_path, GonioSpec(revolutions=40, seed=2))
    rows[column][row] = value
    with pytest.raises(LogError, match=f"^rows: row {row}: {what}"):
        measure_log(rows, 4, latitude_rad=50.45 * DEG)


def test_a_latitude_in_degrees_is_refused_not_used(tmp_path):
    # Radians inside: 50.45 (degrees by mistake) would remove a wrong Earth rate silently.
    _, rows = _file_and_rows(tmp_path, GonioSpec(revolutions=40, seed=2))
    with pytest.raises(InputError, match=r"latitude_rad = 50\.45: .*radians"):
        measure_log(rows, 4, 50.45)
    with pytest.raises(InputError, match=r"latitude_range_rad = 60: .*radians"):
        measure_log(rows, 4, latitude_range_rad=(0.7, 60.0))


def test_rows_that_are_not_a_log_are_refused_by_name():
    with pytest.raises(LogError, match=r"^rows: column names: .* lacks ref"):
        measure_log({"count": [1, 2], "counter": [1, 2]}, 4)
    with pytest.raises(LogError, match=r"^rows: row 1: count: '2\.5' is not a whole number"):
        measure_log({"count": [1.0, 2.5], "counter": [1, 2], "ref": [1, 0]}, 4)
    with pytest.raises(LogError, match=r"^rows: columns of different lengths"):
        measure_log({"count": [1, 2], "counter": [1, 2], "ref": [1]}, 4)
    with pytest.raises(LogError, match=r"^rows: a list is not rows of a table"):
        measure_log([[1, 1, 1]], 4)


def test_each_exclusion_carries_its_machine_code_and_the_document_validates(tmp_path):
    # Missing and spurious pulses: two kinds of exclusion, each with its code beside the
    # sentence a reader sees (a program tests the code, never the wording).
    import goniometry.exclusions as gx
    from align.contract import FORMATS, validate
    from align.documents import gonio_document

    spec = GonioSpec(revolutions=3000, seed=11, p_missing=1e-3, p_spurious=1e-3)
    path, _ = _file_and_rows(tmp_path, spec)
    run = measure_log(path, 4, latitude_rad=50.45 * DEG)
    d = gonio_document(run, ["f0", "f1", "f2", "f3"], None, {}, [])
    codes = {e["code"] for e in d["exclusions"].values()}
    assert {"missing_pulse", "spurious_pulse"} <= codes, d["exclusions"]
    for reason, e in d["exclusions"].items():
        assert e["code"] == gx.CODES[reason] and e["count"] == len(e["lines"]), (reason, e)
    assert d["format_version"] == FORMATS["gonio"] == 4
    validate(d, "gonio")
    # every reason the pass can give has its own code
    reasons = {v for k, v in vars(gx).items() if k.startswith("R_")}
    assert reasons == set(gx.CODES) and len(set(gx.CODES.values())) == len(reasons)


@pytest.mark.parametrize("seed", range(3))
def test_a_log_without_times_is_warned_unless_the_table_is_asserted_steady(tmp_path, seed):
    """No t column, no --latitude: the Earth rate's share on a table whose speed varies in a
    revolution can be neither removed nor bounded (not in u), so it is a warning, not a note
    (before: a note only, warnings empty; an independent user's 0.1 rev/s, 15 % ripple log was
    28-32 u off). --steady-table asserts the share cancels: a note then, no such warning."""
    spec = GonioSpec(revolutions=40, rev_per_s=0.1, ripple=0.15, with_time=False, seed=seed)
    path = write_log(simulate(spec), tmp_path / "nt.csv")
    run = measure_log(path, 4)
    assert any(w.startswith(f"no t column: {UNTIMED_EARTH}") for w in run.warnings), run.warnings
    steady = measure_log(path, 4, steady_table=True)
    assert not any(UNTIMED_EARTH in w for w in steady.warnings), steady.warnings
    assert any(UNTIMED_EARTH_STEADY in n for n in steady.notes), steady.notes


def test_both_directions_without_times_cancel_the_earth_rate_s_share(tmp_path):
    """With --reverse-log the plain mean cancels the Earth rate's share (it flips sign with
    the direction), so neither run's untimed warning is repeated; the angles within 4 u."""
    runs = {}
    for d in (1, -1):
        spec = GonioSpec(revolutions=40, rev_per_s=0.5, ripple=0.05, with_time=False,
                         direction=d, latency_s=0.0, seed=7)
        runs[d] = (write_log(sim := simulate(spec), tmp_path / f"d{d}.csv"), sim)
    run = measure_log(runs[1][0], 4, reverse_log=runs[-1][0])
    assert not any(UNTIMED_EARTH in w for w in run.warnings), run.warnings
    z = (run.angles.angles_rad - runs[1][1]["truth"]["angles_rad"]) / run.angles.u_rad
    assert np.all(np.abs(z) < 4), z


def test_an_untimed_log_is_not_ok_unless_the_table_is_declared_steady(tmp_path):
    # Without times the Earth rate's share on a table that may not be steady is not in u:
    # warned AND not ok (exit 2, JSON ok false); --steady-table asserts it away (exit 0).
    log = write_log(simulate(GonioSpec(revolutions=40, seed=3, with_time=False)),
                    tmp_path / "g.csv")
    assert main(["gonio", str(log), "--faces", "ref,y,x,z", "--json", str(tmp_path / "a.json"),
                 "-q"]) == 2
    doc = json.loads((tmp_path / "a.json").read_text())
    assert doc["ok"] is False and any("NOT in u" in w for w in doc["warnings"])
    assert main(["gonio", str(log), "--faces", "ref,y,x,z", "--steady-table", "--json",
                 str(tmp_path / "b.json"), "-q"]) == 0
    assert json.loads((tmp_path / "b.json").read_text())["ok"] is True
