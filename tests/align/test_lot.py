"""align lot: control limits and capability against hand-computed values, outlier flags and
false flags against their expected rates over seeds, the metadata breakdown, run order,
malformed inputs (one line each, the lot goes on), the outputs (JSON Schema, CSV, HTML) and
the page rendered in headless Chromium."""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from align.cli import main
from align.lot import UnitResult, analyse, capability, control_chart
from align.lot.read import ANGLE_NAMES
from synth.lot import lot_results

ARCSEC = np.pi / 180 / 3600


# ----------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module")
def real_result(session21_result) -> dict:
    """One real session result, run by 'align run' from a session with [metadata] (the
    shared seed-21 run, tests/conftest.py)."""
    return json.loads(session21_result.read_text())


def _unit(k: int, e_arcsec, u_arcsec=0.1, ok=True, meta=None) -> UnitResult:
    e = tuple(float(v) * ARCSEC for v in np.broadcast_to(e_arcsec, (6,)))
    u = tuple(float(v) * ARCSEC for v in np.broadcast_to(u_arcsec, (6,)))
    return UnitResult(f"r{k}.json", f"s{k}", f"u{k}", ok, True, e, u, 20.0, 23, 0.6,
                      metadata=meta or {})


def _write(results: list[dict], folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for d in results:
        p = folder / f"{d['session']}.json"
        p.write_text(json.dumps(d))
        paths.append(p)
    return paths


# ----------------------------------------------------------------------------- statistics

def test_angle_names_are_the_fusions():
    from align.fusion import E_INDEX, E_NAMES
    from align.lot.read import _INDEX

    assert ANGLE_NAMES == E_NAMES and _INDEX == E_INDEX


def test_control_limits_and_capability_hand_computed():
    # x = 1 3 2 5 4″: moving ranges 2 1 3 1 -> MR̄ = 1.75, x̄ = 3,
    # limits 3 ± 2.66·1.75 (2.66 = 3/1.128), σ_w = 1.75/1.128 = 1.551418.
    x = np.array([1, 3, 2, 5, 4], float)
    c = control_chart(x)
    assert c.center == pytest.approx(3) and c.mr_bar == pytest.approx(1.75)
    assert c.sigma_within == pytest.approx(1.551418, rel=1e-6)
    assert c.ucl == pytest.approx(3 + 3 / 1.128 * 1.75) and c.ucl == pytest.approx(7.654, 1e-3)
    assert c.lcl == pytest.approx(3 - 3 / 1.128 * 1.75)
    assert c.mr_ucl == pytest.approx(3.267 * 1.75)
    cap = capability(x, c, 10.0)
    # Cp = 20/(6σ_w) = 2.148571; Cpk = min(10-3, 3+10)/(3σ_w) = 1.504000;
    # s = √2.5: Pp = 20/(6√2.5) = 2.108185, Ppk = 7/(3√2.5) = 1.475730.
    assert cap.cp == pytest.approx(2.148571, rel=1e-6)
    assert cap.cpk == pytest.approx(1.504000, rel=1e-6)
    assert cap.pp == pytest.approx(2.108185, rel=1e-6)
    assert cap.ppk == pytest.approx(1.475730, rel=1e-6)
    # ν = 0.62·4 = 2.48: u(Cp) = Cp/√(2ν); u(Cpk) = √(1/(9·5) + Cpk²/(2ν)).
    assert cap.n == 5 and cap.dof == pytest.approx(2.48)
    assert cap.cp_u == pytest.approx(2.148571 / math.sqrt(4.96), rel=1e-6)
    assert cap.cpk_u == pytest.approx(math.sqrt(1 / 45 + 1.504 ** 2 / 4.96), rel=1e-5)


def test_lot_flags_limits_tolerance_and_marginal_units():
    # E_xY over 6 units: 0 0.5 -0.5 0.2 6.0 0.1″ (unit 4 far off); other angles quiet.
    vals = [0, 0.5, -0.5, 0.2, 6.0, 0.1]
    units = [_unit(k, [v, 0, 0, 0, 0, 0], u_arcsec=[0.3, .1, .1, .1, .1, .1])
             for k, v in enumerate(vals)]
    lot = analyse(units, (), tolerance=5.8 * ARCSEC)
    a = lot.angles[0]
    # MR = .5 1 .7 5.8 5.9 -> MR̄ = 2.78, x̄ = 1.05, UCL = 1.05 + 2.66·2.78 = 8.44: unit 4
    # is inside the limits (it inflates MR̄ itself: 6 units are few) but outside ±5.8″.
    assert a.chart.mr_bar / ARCSEC == pytest.approx(2.78)
    assert a.outside_limits == () and a.outside_tolerance == (4,)
    assert lot.flagged == {4: ["E_xY outside tolerance"]}
    # 5.7″ ± 0.3″ is within ±5.8″ by less than 2u: marginal.
    lot2 = analyse([*units[:4], _unit(4, [5.7, 0, 0, 0, 0, 0], [0.3, .1, .1, .1, .1, .1]),
                    units[5]], (), tolerance=5.8 * ARCSEC)
    assert lot2.angles[0].marginal == (4,) and lot2.angles[0].outside_tolerance == ()
    assert lot.within_tolerance is False and lot2.within_tolerance is True


def test_a_unit_5_sigma_off_is_flagged():
    """A unit 5σ off in a lot of 30: it raises MR̄ by about 2·(5 − 1.13)σ/29, so the limits
    widen to ≈ x̄ ± 3.7σ and x̄ moves by 5σ/30: P(flagged) ≈ P(N(4.8, 1) > 3.7) ≈ 0.87.
    Over 200 seeds the rate must be ≥ 0.80 (3 binomial sd below 0.87)."""
    rng = np.random.default_rng(1301)
    hits = 0
    for _ in range(200):
        x = rng.standard_normal((30, 6))
        x[12, 2] += 5.0
        lot = analyse([_unit(k, x[k]) for k in range(30)])
        hits += 12 in lot.angles[2].outside_limits
    assert hits / 200 >= 0.80


def test_a_clean_lot_of_30_has_the_expected_false_flags():
    """In control, a point falls outside x̄ ± 3σ with probability 0.0027. Over 300 lots of 30
    units × 6 angles (54 000 points, 146 expected) the count must be within 4 Poisson sd
    of that: the limits are neither too tight (false alarms) nor too wide (blind)."""
    rng = np.random.default_rng(1302)
    flags = 0
    for _ in range(300):
        x = 3 + 0.5 * rng.standard_normal((30, 6))
        lot = analyse([_unit(k, x[k]) for k in range(30)])
        flags += sum(len(a.outside_limits) for a in lot.angles)
    from align.lot.stats import FALSE_RATE

    expected = FALSE_RATE * 54000
    assert abs(flags - expected) <= 4 * math.sqrt(expected)


@pytest.mark.parametrize("seed", range(4))
def test_kruskal_matches_scipy(seed):
    from scipy.stats import kruskal

    from align.lot.stats import kruskal_p

    rng = np.random.default_rng(seed)
    groups = [np.round(rng.normal(0.3 * k, 1, 5 + 7 * k), 1) for k in range(3 + seed % 2)]
    assert kruskal_p(groups) == pytest.approx(kruskal(*groups).pvalue, rel=1e-9)


def test_metadata_breakdown_finds_the_camera_and_not_the_operator():
    rng = np.random.default_rng(1303)
    units = []
    for k in range(60):
        cam = "AB"[k % 2]
        e = rng.standard_normal(6)
        if cam == "B":
            e[1] += 3.0  # camera B sees E_xZ 3σ higher
        units.append(_unit(k, e, meta={"camera": cam, "operator": ["kim", "lee", "ann"][k % 3],
                                       "site": "plant 2", "serial": f"SN{k}"}))
    lot = analyse(units)
    by = {m.key: m for m in lot.metadata}
    assert set(by) == {"camera", "operator"}
    assert by["camera"].differs == (False, True, False, False, False, False)
    assert not any(by["operator"].differs)
    skipped = dict(lot.metadata_skipped)
    assert "site" in skipped and "same for every unit" in skipped["site"]
    assert "serial" in skipped
    g = {x.value: x for x in by["camera"].groups}
    assert g["A"].n == g["B"].n == 30
    assert (g["B"].mean[1] - g["A"].mean[1]) / ARCSEC == pytest.approx(3.0, abs=4 * 2 / 30**.5)


def test_run_order_by_date_else_as_given():
    start = dt.datetime(2026, 11, 1, 8, 0)
    order = [3, 0, 4, 1, 2]
    units = [_unit(k, k, meta={"date": (start + dt.timedelta(hours=h)).isoformat()})
             for k, h in enumerate(order)]
    lot = analyse(units)
    assert lot.run_order == "date" and [u.label for u in lot.units] == [
        "u1", "u3", "u4", "u0", "u2"]
    # a date and a time, and a time zone: converted to UTC before sorting
    tz = [_unit(0, 0, meta={"date": "2026-11-01", "time": "09:00:00+02:00"}),
          _unit(1, 0, meta={"date": "2026-11-01T06:30:00Z"})]
    assert [u.label for u in analyse(tz).units] == ["u1", "u0"]
    units[2] = _unit(2, 2)  # one unit without a date: the order given, and why
    lot = analyse(units)
    assert lot.run_order == "given" and [u.label for u in lot.units] == [
        "u0", "u1", "u2", "u3", "u4"]
    assert "1 of 5 sessions have no readable date" in lot.run_order_note


def test_units_not_ok_are_listed_not_used():
    units = [_unit(k, k % 3) for k in range(5)]
    units[2] = UnitResult("r2.json", "s2", "u2", False, True, units[2].e_rad, units[2].u_rad,
                          9.0, 23, 0.9, ("stage marks FAILED",), (("marks", "x.png: bad"),))
    lot = analyse(units)
    assert lot.not_ok == (2,) and 2 not in lot.in_stats and lot.angles[0].n == 4
    assert not lot.ok
    from align.lot import lot_warnings

    w = lot_warnings(lot)
    assert any("unit u2" in x and "stage marks failed: x.png: bad" in x
               and "not in the statistics" in x for x in w)
    # ok but not fused (a result no run writes): still listed, never silently left out
    odd = UnitResult("r9.json", "s9", "u9", True, False, None, None, None, None, None)
    lot = analyse([*units, odd])
    assert lot.not_ok == (2, 5) and not lot.ok
    assert any("unit u9" in x and "not fused" in x for x in lot_warnings(lot))


@pytest.mark.slow
def test_lots_too_small_for_statistics(real_result, tmp_path, capsys):
    """No unit ok: no statistics, but every output written and the exit says so; one unit:
    no chart, no capability, and the JSON still valid against its schema."""
    from align.contract import validate

    results, _ = lot_results(real_result, 2, seed=3)
    results[0] = dict(results[0], ok=False, errors=[{"stage": "platform", "message": "bad"}])
    results[1] = dict(results[1], ok=False, fused=False, errors=[
        {"stage": "fusion", "message": "undetermined"}])
    for k in ("misalignment_rad", "misalignment_u_rad"):
        results[1].pop(k)
    paths = _write(results, tmp_path / "r")
    out = tmp_path / "none"
    assert main(["lot", *map(str, paths), "--report", f"{out}.html", "--json", f"{out}.json",
                 "--csv", f"{out}.csv", "--tolerance-arcsec", "5"]) == 2
    assert "no unit is ok and fused: no statistics" in capsys.readouterr().err
    d = json.loads(Path(f"{out}.json").read_text())
    validate(d, "lot")
    assert d["n_in_statistics"] == 0 and "Units not ok" in Path(f"{out}.html").read_text()
    one = _write(lot_results(real_result, 1, seed=4)[0], tmp_path / "one")
    assert main(["lot", *map(str, one), "--json", f"{out}1.json", "--report", f"{out}1.html",
                 "--tolerance-arcsec", "5"]) == 0
    d = json.loads(Path(f"{out}1.json").read_text())
    validate(d, "lot")
    assert d["angles"][0]["control_chart"] is None and d["angles"][0]["capability"] is None
    assert "Fewer than 2 units: no chart" in Path(f"{out}1.html").read_text()


# ----------------------------------------------------------------------------- session metadata

def test_session_metadata_carried_into_the_result(real_result):
    from align.contract import validate

    assert real_result["metadata"] == {"serial": "SN-0001", "operator": "kim",
                                       "date": "2026-11-20T08:30:00+00:00", "batch": 7}
    validate(real_result, "session")
    u = UnitResult.from_dict(real_result, "r.json")
    assert u.label == "SN-0001" and u.when == dt.datetime(2026, 11, 20, 8, 30)


@pytest.mark.parametrize("text,key", [
    ('[metadata]\ncamera = ["A", "B"]\n', "[metadata] camera"),
    ("[metadata]\nlens = { f = 50 }\n", "[metadata] lens"),
    ("[metadata]\ntemp = nan\n", "[metadata] temp"),
    ("metadata = 5\n", "metadata"),
])
def test_bad_metadata_names_the_key(tmp_path, text, key):
    from align.errors import InputError
    from align.session import load_session

    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "tumble.csv").write_text("pose,ux,uy,uz\na,0,0,1\n")
    toml = text + '[calibration]\nstatic = "tumble.csv"\n' if text.startswith("metadata") \
        else '[calibration]\nstatic = "tumble.csv"\n' + text
    (folder / "session.toml").write_text(toml)
    with pytest.raises(InputError) as exc:
        load_session(folder)
    assert key in str(exc.value)


# ----------------------------------------------------------------------------- the command

@pytest.mark.slow
def test_lot_command_end_to_end(real_result, tmp_path, capsys):
    from align.contract import validate

    results, truth = lot_results(real_result, 40, seed=1304, mean_rad=[10 * ARCSEC] * 6,
                                 sigma_rad=1 * ARCSEC, shifts={25: (3, 8.0)},
                                 metadata={"camera": ["A", "B"], "table": ["T1"]},
                                 start=dt.datetime(2026, 11, 2, 6, 0))
    results[7] = dict(results[7], ok=False,
                      errors=[{"stage": "goniometer", "message": "gonio.csv: empty"}])
    folder = tmp_path / "results"
    paths = _write(results, folder)
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "trunc.json").write_text(paths[0].read_text()[:500])
    (bad / "list.json").write_text("[1, 2]")
    (bad / "newer.json").write_text(json.dumps(dict(results[1], format_version=99)))
    (bad / "cal.json").write_text(json.dumps({"format": "axis-align/calibration",
                                              "format_version": 2}))
    nulls = json.loads(json.dumps(results[2]))
    nulls["misalignment_rad"][0][1] = None
    (bad / "null.json").write_text(json.dumps(nulls))
    (bad / "latin1.json").write_bytes(b'{"session": "\xe9"}')
    out = {k: tmp_path / f"lot.{k}" for k in ("html", "csv", "json")}
    code = main(["lot", str(folder), str(bad), "--report", str(out["html"]), "--csv",
                 str(out["csv"]), "--json", str(out["json"]), "--tolerance-arcsec", "20"])
    cap = capsys.readouterr()
    assert code == 2  # files not read and a unit not ok: the lot is not complete
    assert "Traceback" not in cap.err
    for name, why in [("trunc.json", "not valid JSON"), ("list.json", "not a JSON object"),
                      ("newer.json", "format version 99 is newer"),
                      ("cal.json", "not 'axis-align/session'"),
                      ("null.json", "misalignment_rad[0][1] = None"),
                      ("latin1.json", "not UTF-8")]:
        lines = [x for x in cap.err.splitlines() if name in x]
        assert len(lines) == 1 and why in lines[0], (name, lines)
    d = json.loads(out["json"].read_text())
    validate(d, "lot")
    assert d["format"] == "axis-align/lot" and d["format_version"] == 1
    assert len(d["inputs"]) == 46 and d["run_order"] == "date"
    assert d["n_units"] == 40 and d["n_in_statistics"] == 39 and len(d["rejected"]) == 6
    assert d["ok"] is False
    e_yz = d["angles"][3]
    assert e_yz["name"] == "E_yZ" and "SN00025" in e_yz["outside_limits"]
    # 10″ ± 1″ against ±20″; unit 25 at 10 + 8 = 18″ (u < 0.2″): inside, by more than 2u.
    assert e_yz["outside_tolerance"] == [] and e_yz["capability"]["n"] == 39
    cam = next(m for m in d["metadata"] if m["key"] == "camera")
    assert [g["n"] for g in cam["groups"]] == [20, 19]
    rows = list(csv.DictReader(io.StringIO(out["csv"].read_text())))
    assert len(rows) == 40 and rows[0]["unit"] == "SN00000" and rows[0]["meta_camera"] == "A"
    assert float(rows[5]["E_yZ_arcsec"]) == pytest.approx(truth[5, 3] / ARCSEC, abs=1e-4)
    assert next(r for r in rows if r["unit"] == "SN00007")["in_statistics"] == "False"
    html = out["html"].read_text()
    assert html.index("Warnings") < html.index("Per angle")
    # distributions, 6 control charts, camera and date (by day); table is the same for all
    assert "SN00025: E_yZ" in html and html.count("data:image/png;base64") == 9
    assert [m["key"] for m in d["metadata"]] == ["camera", "date"] and d["metadata"][1]["by_day"]
    assert "table" in [m["key"] for m in d["metadata_not_compared"]]
    # Nothing is overwritten.
    before = out["json"].read_text()
    assert main(["lot", str(folder), "--json", str(out["json"])]) == 2
    assert "exists" in capsys.readouterr().err and out["json"].read_text() == before


def test_lot_command_refuses_missing_paths_and_files_twice(real_result, tmp_path, capsys):
    paths = _write(lot_results(real_result, 3, seed=1)[0], tmp_path / "r")
    assert main(["lot", str(tmp_path / "nope.json")]) == 2
    assert "nope.json: no such file or folder" in capsys.readouterr().err
    assert main(["lot", str(paths[0]), str(tmp_path / "r")]) == 2
    assert "given twice" in capsys.readouterr().err
    # platform calibrations written beside the results are not results (told by their
    # format field, not their name: issue 22)
    (tmp_path / "r" / "unit00000.cal.json").write_text(
        '{"format": "axis-align/platform-calibration", "format_version": 3}')
    from align.lot import result_files

    assert [p.name for p in result_files([tmp_path / "r"])] == [p.name for p in paths]
    (tmp_path / "empty").mkdir()
    assert main(["lot", str(tmp_path / "empty")]) == 2
    assert "no .json files" in capsys.readouterr().err
    assert main(["lot", str(paths[0]), "--tolerance-arcsec", "-1"]) == 2
    assert "--tolerance-arcsec" in capsys.readouterr().err


def test_a_result_saved_differently_reads_the_same(real_result, tmp_path):
    """A byte-order mark or compact JSON change nothing; a NaN token (never written by this
    tool: its JSON is strict) is refused, naming the line."""
    from align.lot import read_results

    d = lot_results(real_result, 1, seed=5)[0][0]
    text = json.dumps(d, indent=2)
    files = {"plain": text.encode(), "bom": b"\xef\xbb\xbf" + text.encode(),
             "compact": json.dumps(d, separators=(",", ":")).encode(),
             "nan": text.replace('"chi2": ', '"chi2": NaN, "x": ', 1).encode()}
    for name, raw in files.items():
        (tmp_path / f"{name}.json").write_bytes(raw)
    got = {r.path.stem: r for r in read_results(sorted(tmp_path.iterdir()))}
    assert got["plain"].unit.e_rad == got["bom"].unit.e_rad == got["compact"].unit.e_rad
    assert got["plain"].unit.e_rad is not None
    assert got["nan"].unit is None and "not valid JSON (line" in got["nan"].rejected.reason


def test_lot_json_to_stdout(real_result, tmp_path, capsys):
    paths = _write(lot_results(real_result, 5, seed=2)[0], tmp_path / "r")
    assert main(["lot", *map(str, paths), "--json", "-"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["n_units"] == 5 and "lot: 5 session results" in cap.err


# ----------------------------------------------------------------------------- the page

def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return name
    pytest.skip("headless Chromium is absent (Debian package 'chromium'; .ci/run installs it)")


@pytest.mark.slow  # (a headless browser; the page's own checks stay in the default run)
def test_report_renders_in_headless_chromium(real_result, tmp_path):
    from PIL import Image

    browser = _chromium()
    results, _ = lot_results(real_result, 30, seed=1305, sigma_rad=1.5 * ARCSEC,
                             shifts={20: (0, 9.0)}, metadata={"operator": ["kim", "lee"]})
    paths = _write(results, tmp_path / "r")
    page = tmp_path / "lot.html"
    assert main(["lot", *map(str, paths), "--report", str(page), "--tolerance-arcsec",
                 "6", "-q"]) == 0
    # The page has no script; a copy with one reports, on the console, every image that
    # did not decode (a broken data URI logs nothing by itself).
    probe = tmp_path / "probe.html"
    probe.write_text(page.read_text().replace("</body>", (
        "<script>window.addEventListener('load', () => { let ok = 0;"
        "for (const i of document.images) { if (i.complete && i.naturalWidth > 0) ok++;"
        " else console.error('broken image ' + i.alt); }"
        "console.log('images decoded ' + ok); });</script></body>")))
    shot = tmp_path / "shot.png"
    run = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
         "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000",
         "--window-size=1200,2400", f"--screenshot={shot}", probe.as_uri()],
        capture_output=True, text=True, timeout=120)
    console = [x for x in run.stderr.splitlines() if ":CONSOLE" in x]
    assert shot.is_file(), run.stderr[-2000:]
    n_img = page.read_text().count("<img ")
    assert console == [c for c in console if f'"images decoded {n_img}"' in c], console
    assert len(console) == 1, console
    img = np.asarray(Image.open(shot).convert("L"), float)
    assert img.shape[0] >= 2000 and img.std() > 20  # text, tables and figures, not blank
    assert (img < 128).mean() > 0.01


def test_a_result_whose_E_has_a_diagonal_is_not_read(real_result, tmp_path):
    """E has a zero diagonal: a result with E_xx = 0.01 (corrupt or edited) is one line."""
    from align.lot import read_results

    d = json.loads(json.dumps(lot_results(real_result, 1, seed=6)[0][0]))
    d["misalignment_rad"][1][1] = 0.01
    (tmp_path / "diag.json").write_text(json.dumps(d))
    (r,) = read_results([tmp_path / "diag.json"])
    assert r.unit is None and "misalignment_rad[1][1] = 0.01: the diagonal" in r.rejected.reason
