"""Sessions: session.toml checks naming the key, stage failures kept per stage, the run/apply/
synth commands, batches in parallel, and never overwriting anything."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from align.cli import main
from align.errors import InputError
from align.session import load_session
from synth.session import SessionSpec, write_session
from tests.conftest import strip_images


@pytest.fixture
def session(session21) -> Path:
    """The session of seed 21 (folder ``unit7``), written once for the run: read-only."""
    return session21


def _copy(session: Path, tmp_path: Path, name: str = "copy") -> Path:
    dst = tmp_path / name
    shutil.copytree(session, dst)
    return dst


def _edit(folder: Path, old: str, new: str) -> None:
    p = folder / "session.toml"
    text = p.read_text()
    assert old in text
    p.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize("old,new,message", [
    ('log = "gonio.csv"', 'log = "nope.csv"', "[goniometer] log = 'nope.csv': no such file"),
    ('housing = "x"', 'housing = "w"', "[[images]] #1 housing = 'w': not one of x, y, z"),
    ('view = "A"', 'view = "Q"', "[[images]] #1 view = 'Q': no [views.Q] table"),
    ('nominal = "horizontal"', 'nominal = "vertical"', "contradictory nominal orientation"),
    ("nominal_deg = [90.0, 90.0, 90.0, 90.0]", "nominal_deg = [90.0, 180.0, 45.0, 45.0]",
     "contradictory nominal orientation"),
    ("nominal_deg = [90.0, 90.0, 90.0, 90.0]", "nominal_deg = [90.0, 90.0, 90.0, 80.0]",
     "must sum to 360"),
    ('right = "+X"', 'right = "+Z"', "[views.A]: right = '+Z' and up = '+Z' are the same axis"),
    ('[views.A]\ncamera = "A"', '[views.A]\ncamera = "C"',
     "[views.A] camera = 'C': no [cameras.C] table (known: A, B)"),
    ('[views.Ar]\ncamera = "A"\n', '[views.Ar]\n',
     "[views.Ar] no camera key (default 'Ar'): no [cameras.Ar] table (known: A, B)"),
    ("latitude_deg = 50.45", "latitude = 50.45", "unknown key(s) latitude"),
    ('direction = "ccw"', 'directon = "ccw"', "[goniometer]: unknown key(s) directon"),
    ('L000 = { up = "+Z", table_deg = 0.0 }', 'L000 = { up = "+W", table_deg = 0.0 }',
     "[platform].poses L000 up = '+W'"),
])
def test_bad_session_names_the_key(session, tmp_path, old, new, message, capsys):
    folder = _copy(session, tmp_path)
    _edit(folder, old, new)
    with pytest.raises(InputError, match=None) as exc:
        load_session(folder)
    assert message in str(exc.value)
    assert main(["run", str(folder)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_too_few_sources_to_determine_E(session, tmp_path, capsys):
    """The calibration alone sees only sums E_ij + E_ji: the run must say what is missing."""
    folder = tmp_path / "cal_only"
    folder.mkdir()
    shutil.copy(session / "tumble.csv", folder)
    (folder / "session.toml").write_text('[calibration]\nstatic = "tumble.csv"\n'
                                         'scale_sign = "-"\n')
    assert main(["run", str(folder)]) == 2
    out = capsys.readouterr()
    assert "do not determine the misalignment" in out.out + out.err
    assert "E_xY" in out.out + out.err


@pytest.mark.slow
def test_run_writes_json_report_and_calibration_and_never_overwrites(session, tmp_path,
                                                                     capsys):
    js, rep, cal = tmp_path / "r.json", tmp_path / "r.html", tmp_path / "cal.json"
    assert main(["run", str(session), "--json", str(js), "--report", str(rep),
                 "--calibration", str(cal)]) == 0
    d = json.loads(js.read_text())
    E = np.array(d["misalignment_rad"])
    U = np.array(d["misalignment_u_rad"])
    assert E.shape == (3, 3) and U.shape == (3, 3)
    assert np.all(np.diag(E) == 0) and np.all(U[~np.eye(3, dtype=bool)] > 0)
    truth = np.array(json.loads((session / "truth.json").read_text())["misalignment_rad"])
    off = ~np.eye(3, dtype=bool)
    assert np.all(np.abs(E - truth)[off] < 4.5 * U[off])
    for key in ("effects", "unexplained_structure", "observations", "stages", "chi2"):
        assert key in d
    html = rep.read_text()
    assert html.count("data:image/png;base64") >= 10  # marks, gonio, calibration, fusion
    assert "Misalignment matrix" in html and "Fusion loop" in html
    before = js.read_text()
    assert main(["run", str(session), "--json", str(js)]) == 2
    assert "exists" in capsys.readouterr().err
    assert js.read_text() == before
    # Outputs may not be one of the session's inputs.
    assert main(["run", str(session), "--json", str(session / "gonio.csv")]) == 2


def test_a_stage_failure_is_reported_and_the_rest_still_fuse(session, tmp_path):
    folder = _copy(session, tmp_path)
    (folder / "z_B.png").write_bytes(b"not a png at all")
    out = tmp_path / "r.json"
    # A failed stage: the result is still written, but it is not ok and the exit says so.
    assert main(["run", str(folder), "--json", str(out)]) == 2
    d = json.loads(out.read_text())
    assert any(e["stage"] == "marks" and "z_B.png" in e["message"] for e in d["errors"])
    assert not d["ok"] and d["fused"] and len(d["stages"]["marks"]) == 7
    assert any("z_B.png" in w and "FAILED" in w for w in d["warnings"])


def test_a_defect_in_a_stage_is_that_stages_internal_error(session, tmp_path, monkeypatch,
                                                           capsys):
    """A bug (not bad input) in the goniometer stage and in one camera's images: each is its
    stage's 'internal error — please report' with the traceback on the log, the other stages
    and the other camera's images still run and fuse, and the exit status is 1 (as 'align
    marks' gives for a bug in an image), not 2 (bad input)."""
    import align.session.run as run

    real_measure_camera = run.measure_camera

    def broken_gonio(*a, **k):
        raise TypeError("simulated bug")

    def broken_on_b(images, *a, label="", **k):
        if label == "B":
            raise ZeroDivisionError("simulated bug")
        return real_measure_camera(images, *a, label=label, **k)

    monkeypatch.setattr(run, "measure_log", broken_gonio)
    monkeypatch.setattr(run, "measure_camera", broken_on_b)
    out = tmp_path / "r.json"
    assert main(["run", str(session), "--json", str(out)]) == 1
    d = json.loads(out.read_text())
    errors = {e["stage"]: e for e in d["errors"]}
    assert set(errors) == {"goniometer", "marks"}
    assert errors["goniometer"]["message"] == ("internal error — please report "
                                               "(TypeError: simulated bug)")
    assert errors["marks"]["message"] == ("camera B: internal error — please report "
                                          "(ZeroDivisionError: simulated bug)")
    assert all(e["internal"] for e in errors.values())
    assert not d["ok"] and d["fused"] and len(d["stages"]["marks"]) == 4  # camera A's
    assert "calibration" in d["stages"] and "goniometer" not in d["stages"]
    err = capsys.readouterr().err
    assert err.count("Traceback") == 2 and "ZeroDivisionError: simulated bug" in err


@pytest.mark.parametrize("units,fails", [("m/s2", True), ("g", False)])
def test_a_calibration_unit_the_readings_contradict_is_caught(session, tmp_path, units, fails):
    """The synthetic triad reads ~2.4 V per g: declared m/s² (9.81 per g expected, 4x off:
    nearer another unit) the calibration stage fails naming the key; declared g (2.4x off:
    not nearer another unit, but far beyond a triad's tolerance) it is warned of. (The
    session without its images: the marks play no part in the calibration's units.)"""
    folder = strip_images(session, tmp_path / "plain")
    _edit(folder, 'static = "tumble.csv"', f'static = "tumble.csv"\nunits = "{units}"')
    out = tmp_path / "r.json"
    main(["run", str(folder), "--json", str(out)])
    d = json.loads(out.read_text())
    failed = [e for e in d["errors"] if e["stage"] == "calibration"]
    if fails:
        assert not d["ok"] and failed and "[calibration] units" in failed[0]["message"]
    else:
        assert not failed
        assert any("scale factor" in w and "[calibration] units" in w for w in d["warnings"])


@pytest.mark.slow
def test_batch_runs_in_parallel_and_keeps_going(session, tmp_path, capsys):
    good2 = _copy(session, tmp_path, "unit8")
    bad = _copy(session, tmp_path, "unit9")
    _edit(bad, 'log = "gonio.csv"', 'log = "missing.csv"')
    outdir = tmp_path / "results"
    code = main(["run", str(session), str(good2), str(bad), "--json", str(outdir),
                 "--jobs", "2"])
    assert code == 2
    cap = capsys.readouterr()
    assert "2 of 3 sessions done, 1 failed" in cap.out
    assert "unit9: FAILED" in cap.err and "missing.csv" in cap.err
    assert sorted(p.name for p in outdir.iterdir()) == ["unit7.json", "unit8.json"]


def test_apply_corrects_readings_into_the_platform_frame(session, session21_result, tmp_path):
    """Readings of the session's own platform poses come back as their nominal directions
    (the platform calibration 'align run --calibration' wrote of this session, once for the
    run: tests/conftest.py)."""
    cal = session21_result.parent / "pc.json"
    readings = tmp_path / "readings.csv"
    lines = (session / "platform.csv").read_text().splitlines()
    readings.write_text("ux,uy,uz,t\n" + "\n".join(",".join(r.split(",")[1:])
                                                   for r in lines[1:] if r.startswith("Xup")))
    before = readings.read_text()
    out = tmp_path / "corrected.csv"
    assert main(["apply", str(cal), str(readings), "--out", str(out), "--tilt"]) == 0
    assert readings.read_text() == before
    a = np.genfromtxt(out, delimiter=",", names=True)
    mean = np.array([a["ax_g"].mean(), a["ay_g"].mean(), a["az_g"].mean()])
    # Xup: specific force along +X; 20 ug a sample over 200 samples plus calibration u.
    assert abs(mean[0] - 1) < 50e-6 and np.all(np.abs(mean[1:]) < 15e-6), mean
    assert "roll_deg" in a.dtype.names
    assert main(["apply", str(cal), str(readings), "--out", str(out)]) == 2
    assert main(["apply", str(readings), str(readings), "--out", str(tmp_path / "x.csv")]) == 2


def test_synth_session_command_declares_only_what_it_is_told(tmp_path):
    out = tmp_path / "s"
    assert main(["synth", "session", str(out), "--seed", "3", "--effect",
                 "camera_roll_A=20", "--undeclared", "reference_offset=15"]) == 0
    toml = (out / "session.toml").read_text()
    assert "roll_arcsec = 20.0" in toml and "reference_offset" not in toml
    truth = json.loads((out / "truth.json").read_text())
    assert truth["effects"] == {"camera_roll_A": 20.0, "reference_offset": 15.0}
    assert main(["synth", "session", str(out)]) == 2  # never overwrites
    assert main(["synth", "session", str(tmp_path / "t"), "--effect", "warp=3"]) == 2


def test_demo_runs_a_session_and_reports_its_error(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d"), "--seed", "2"]) == 0
    out = capsys.readouterr().out
    assert "misalignment E" in out and "error against truth" in out
    assert "camera_roll[A]" in out  # the undeclared roll is named
    assert (tmp_path / "d" / "report.html").is_file()
    z = float(out.split("normalised errors (error / u): RMS")[1].split()[0])
    assert 0.2 < z < 2.5
    assert main(["demo", "--out", str(tmp_path / "d")]) == 2  # never overwrites


@pytest.mark.slow
def test_session_with_both_table_directions(tmp_path):
    from align.session import run_session

    folder = tmp_path / "both"
    truth = write_session(folder, SessionSpec(seed=22, reverse_run=True))
    assert 'reverse_log = "gonio_cw.csv"' in (folder / "session.toml").read_text()
    res = run_session(load_session(folder))
    assert res.gonio.reverse is not None and res.gonio.direction is not None
    assert res.gonio.angles.revolutions == 2 * res.gonio.reverse.angles.revolutions
    f = res.fusion
    off = ~np.eye(3, dtype=bool)
    E0 = np.array(truth["misalignment_rad"])
    assert np.all(np.abs(f.E - E0)[off] < 4.5 * f.E_u[off])


def test_session_nominal_far_from_the_measured_faces_is_warned(tmp_path):
    """As for 'align gonio --nominal': a session's nominal_deg more than 1° from what the log
    measures (a wrong face order, say) is a warning in the result, not silent deviations."""
    from align.session import load_session, run_session
    from synth.session import SessionSpec
    from tests.conftest import imageless_session

    s = imageless_session(tmp_path, SessionSpec(seed=4))
    toml = (s / "session.toml").read_text()
    assert "nominal_deg = [90.0, 90.0, 90.0, 90.0]" in toml
    (s / "session.toml").write_text(toml)
    clean = run_session(load_session(s)).to_dict()
    assert not any("nominal" in w for w in clean["warnings"])
    (s / "session.toml").write_text(toml.replace("nominal_deg = [90.0, 90.0, 90.0, 90.0]",
                                                 "nominal_deg = [95.0, 90.0, 85.0, 90.0]"))
    off = run_session(load_session(s)).to_dict()
    assert any("nominal" in w for w in off["warnings"]), off["warnings"]


@pytest.mark.parametrize("test, p, chi2", [("periodogram", 1.4e-4, 12.21), (None, None, 55.0)])
def test_a_not_ok_fusion_says_which_test_found_the_disagreement(test, p, chi2):
    """A fusion with structure left but an unremarkable chi2 (12.21 / 15 dof, p 0.66: a
    newcomer's own session) named only the chi2 as the reason, which read as a contradiction;
    the reason now names the test that found it (periodogram, its p) before the chi2."""
    from types import SimpleNamespace

    from align.loop import LoopSummary
    from align.session.run import SessionResult

    loop = LoopSummary((), 1.0, 1.0, 0.8, 0.8, True, test, p, "")
    f = SimpleNamespace(gross=False, consistent=False, disagreement=None, chi2=chi2, dof=15,
                        loop=loop)
    said = SessionResult(session=SimpleNamespace(tolerance=None), fusion=f).problems
    why = "periodogram, p = 0.00014; chi2 12.21 / 15 dof" if test else "chi2 55 / 15 dof"
    assert said == [f"fusion: the instruments disagree beyond their uncertainties ({why})"]
