"""align lot: a unit in several results is counted once, with a warning naming the result
used and why (identical copy, the same data processed again, a new measurement)."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from align.cli import main
from align.lot import UnitResult, analyse, lot_csv, lot_warnings
from align.lot.document import lot_body

ARCSEC = np.pi / 180 / 3600


def _unit(k: int, e_arcsec: float, label: str | None = None, ok: bool = True, **kw
          ) -> UnitResult:
    e = (e_arcsec * ARCSEC,) * 6
    return UnitResult(f"r{k}.json", f"s{k}", label or f"u{k}", ok, True, e, (0.1 * ARCSEC,) * 6,
                      20.0, 23, 0.6, **kw)


def _lot(n=8, seed=0):
    rng = np.random.default_rng(seed)
    return [_unit(k, float(v), sha256=f"h{k}", inputs_sha256=(f"i{k}",),
                  created_utc=f"2026-11-0{1 + k % 9}T10:00:00Z")
            for k, v in enumerate(rng.normal(0, 1, n))]


def test_an_identical_copy_is_counted_once():
    units = _lot()
    copy = replace(units[2], file="r2_copy.json")
    lot = analyse([*units, copy])
    ref = analyse(units)
    assert len(lot.in_stats) == 8 and lot.angles[0].mean == ref.angles[0].mean
    assert lot.angles[0].chart.mr_bar == ref.angles[0].chart.mr_bar
    (d,) = lot.duplicates
    assert (d.label, lot.units[d.used].file) == ("u2", "r2.json")
    assert d.relations == ("an identical copy, same SHA-256",)
    assert lot.ok and lot.not_ok == ()            # left out is not 'not ok'
    w = [x for x in lot_warnings(lot) if "unit u2" in x]
    assert len(w) == 1 and "counted once, r2.json used" in w[0] and "r2_copy.json left out" in w[0]
    body = lot_body(lot)
    assert body["n_in_statistics"] == 8 and body["units"][8]["counted_as"] == "r2.json"
    assert body["duplicates"][0]["left_out"][0]["file"] == "r2_copy.json"
    rows = list(csv.DictReader(io.StringIO(lot_csv(lot))))
    assert [r["counted_as"] for r in rows if r["file"] == "r2_copy.json"] == ["r2.json"]


def test_which_result_of_a_unit_is_used():
    units = _lot()
    # the same data processed again, newer: the newer is used
    again = replace(units[3], file="r3_again.json", sha256="x", created_utc="2026-12-01T00:00:00Z",
                    e_rad=(9 * ARCSEC,) * 6)
    lot = analyse([*units, again])
    (d,) = lot.duplicates
    assert lot.units[d.used].file == "r3_again.json" and "created_utc" in d.why
    assert d.relations == ("the same session data processed again, same input files",)
    # measured again, both dated: the latest measurement, whatever the order given
    early = replace(units[3], metadata={"date": "2026-11-02"}, inputs_sha256=("a",))
    late = replace(units[3], file="r3_late.json", sha256="y", inputs_sha256=("b",),
                   metadata={"date": "2026-11-05"}, created_utc="2026-11-01T00:00:00Z")
    lot = analyse([late, *units[:3], early])
    (d,) = lot.duplicates
    assert lot.units[d.used].file == "r3_late.json" and "date" in d.why
    assert d.relations == ("another measurement of the unit, other input files",)
    # a failed result and a rerun that is ok: the ok one, and the failed one is not 'not ok'
    failed = replace(units[4], ok=False, failed_stages=(("platform", "bad"),),
                     created_utc="2027-01-01T00:00:00Z", sha256="z")
    lot = analyse([*units, failed])
    (d,) = lot.duplicates
    assert lot.units[d.used].file == "r4.json" and d.why == "the only one ok and fused"
    assert lot.ok and len(lot.in_stats) == 8
    # nothing to tell them apart: the last given
    a = replace(units[5], created_utc=None, sha256="p")
    b = replace(units[5], file="r5_b.json", created_utc=None, sha256="q")
    lot = analyse([a, b])
    assert lot.units[lot.duplicates[0].used].file == "r5_b.json"
    assert lot.duplicates[0].why == "the last given"


def test_distinct_units_are_never_merged():
    """40 units with distinct labels, some sharing data or a session name: no duplicate."""
    units = [replace(u, session="same", inputs_sha256=("one",)) for u in _lot(40, seed=2)]
    lot = analyse(units)
    assert lot.duplicates == () and len(lot.in_stats) == 40
    assert not any("results: counted once" in w for w in lot_warnings(lot))


@pytest.fixture(scope="module")
def result(session21_result) -> Path:
    """A real session result (the shared seed-21 run, tests/conftest.py; ``lot_results``
    replaces its metadata per unit)."""
    return session21_result


def test_cli_a_copy_in_the_folder(result, tmp_path, capsys):
    from align.contract import validate
    from synth.lot import lot_results

    res = tmp_path / "res"
    res.mkdir()
    for d in lot_results(json.loads(result.read_text()), 5, seed=3)[0]:
        (res / f"{d['session']}.json").write_text(json.dumps(d))
    (res / "unit00002_copy.json").write_bytes((res / "unit00002.json").read_bytes())
    out = tmp_path / "lot"
    assert main(["lot", str(res), "--json", f"{out}.json", "--report", f"{out}.html"]) == 0
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if "SN00002" in x]
    assert len(line) == 1 and "in 2 results: counted once" in line[0]
    assert "unit00002.json used" in line[0] and "unit00002_copy.json left out" in line[0]
    d = json.loads(Path(f"{out}.json").read_text())
    validate(d, "lot")
    assert d["n_in_statistics"] == 5 and all(a["n"] == 5 for a in d["angles"])
    assert "Units in several results" in Path(f"{out}.html").read_text()
