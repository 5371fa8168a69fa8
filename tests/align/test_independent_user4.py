"""Independent user tests (user4): lens/camera marks, ruled scales, tolerances and decisions,
init -> check -> run, --resume and plan.

Written from README.md, docs/ and --help only; inputs come from tests/align/user4_inputs.py
(numpy/OpenCV), or from the `align synth session` / `align init` command lines.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

import pytest

from tests.cli import run_cli

sys.path.insert(0, str(Path(__file__).resolve().parent))
from user4_inputs import (  # noqa: E402
    angle_diff_arcsec,
    render_marks,
    render_ruled,
    write_camera_json,
    write_png,
)

ROOT = Path(__file__).resolve().parents[2]
W, H = 640, 480
F = 1.325 * 0.5 * math.hypot(W, H)          # f = 1.325 R, as the docs' test grid
LENS = (-0.3, 0.1, 0.0, 0.0)                # OpenCV k1, k2, p1, p2
LENS_FREE = "k1=0,k2=0,p=0,aspect=0,pp_px=0"


def align(*args):
    """``align ARGS`` from the project's root (in this process: ``tests.cli``); the result
    reads like ``subprocess.run``'s (``returncode``, ``stdout``, ``stderr``)."""
    return run_cli(*args, cwd=ROOT)


def marks_json(img_path, *extra):
    r = align("marks", img_path, "--json", "-", "-q", *extra)
    assert r.returncode in (0, 2), r.stderr
    return r, json.loads(r.stdout)


def found(doc):
    return [m for m in doc["marks"] if m.get("found", True)]


# ---------------------------------------------------------------- (1) marks through a lens

POSITIONS = {
    "centre": [(319.5, 239.5, 0.3, 240.0)],
    "off_centre": [(319.5, 100.0, 0.3, 240.0)],
    "corner": [(120.0, 90.0, 30.0, 160.0)],
}


@pytest.mark.slow
@pytest.mark.parametrize("where", sorted(POSITIONS))
def test_exact_camera_model_gives_ok_angle_within_3u(tmp_path, where):
    marks = POSITIONS[where]
    img = render_marks(W, H, marks, f=F, dist=LENS, seed=11, ss=2)
    p = write_png(tmp_path / "m.png", img)
    cam = write_camera_json(tmp_path / "cam.json", W, H, F, LENS)
    r, doc = marks_json(p, "--camera", cam)
    assert r.returncode == 0 and doc["ok"] is True, r.stderr
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], marks[0][2])
    assert abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])
    assert m["angle_u_arcsec"] < 60


@pytest.mark.slow
@pytest.mark.parametrize("where", sorted(POSITIONS))
def test_no_camera_single_mark_through_lens_says_calibrate(tmp_path, where):
    marks = POSITIONS[where]
    img = render_marks(W, H, marks, f=F, dist=LENS, seed=12, ss=2)
    p = write_png(tmp_path / "m.png", img)
    r, doc = marks_json(p)
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], marks[0][2])
    if r.returncode == 0:
        assert abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])
    else:
        assert r.returncode == 2 and doc["ok"] is False
        assert m["lens_limited"] is True
        assert "calibrate the camera" in r.stderr
        assert abs(err) <= 3 * m["angle_u_arcsec"]


@pytest.mark.slow
def test_wrong_camera_model_is_flagged_and_u_covers(tmp_path):
    """A camera JSON without distortion for a k1 = -0.3 lens: the marks must test it."""
    marks = POSITIONS["off_centre"]
    img = render_marks(W, H, marks, f=F, dist=LENS, seed=13, ss=2)
    p = write_png(tmp_path / "m.png", img)
    cam = write_camera_json(tmp_path / "cam.json", W, H, F, (0.0, 0.0, 0.0, 0.0))
    r, doc = marks_json(p, "--camera", cam)
    assert "differs from its calibration" in r.stderr
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], marks[0][2])
    assert abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])


def test_bad_camera_json_is_one_line_exit_2(tmp_path):
    img = render_marks(W, H, POSITIONS["centre"], seed=14, ss=1)
    p = write_png(tmp_path / "m.png", img)
    cam = write_camera_json(tmp_path / "cam.json", W, H, F, (0.0, 0.0, 0.0))  # 3 coeffs: pad
    doc = json.loads(cam.read_text())
    doc["camera_matrix"][0][0] = -F                                        # focal < 0
    cam.write_text(json.dumps(doc))
    r = align("marks", p, "--camera", cam)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "cam.json" in r.stderr


@pytest.mark.slow
def test_straight_mark_declared_lens_free_is_within_3u(tmp_path):
    marks = [(319.5, 100.0, 0.3, 300.0)]
    img = render_marks(W, H, marks, seed=4, ss=3)
    p = write_png(tmp_path / "m.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE)
    assert r.returncode == 0 and doc["ok"]
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], 0.3)
    assert abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])


def test_bent_mark_lens_free_angle_within_3u(tmp_path):
    # A parabolic bow symmetric about the mark's middle: chord, straight fit and tangent at
    # the middle all have the nominal direction, so the truth is unambiguous.
    img = render_marks(800, 600, [(399.5, 150.0, 0.3, 400.0)], seed=4, bow_px=2.0, ss=3)
    p = write_png(tmp_path / "bent.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE)
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], 0.3)
    assert r.returncode == 2 or abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])


@pytest.mark.slow
def test_bent_mark_is_named_bent(tmp_path):
    img = render_marks(800, 600, [(399.5, 150.0, 0.3, 400.0)], seed=1, bow_px=2.0, ss=3)
    p = write_png(tmp_path / "bent.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE)
    assert "the mark is bent" in r.stderr
    (m,) = found(doc)
    assert "bent_mark_chord_vs_fit" in m["angle_u_terms_arcsec"]


@pytest.mark.slow
def test_three_straight_marks_one_lens_not_called_bent(tmp_path):
    three = [(200, 150, 10.0, 250), (600, 450, -20.0, 250), (650, 150, 75.0, 250)]
    img = render_marks(800, 600, three, f=1.325 * 500.0, dist=LENS, seed=2, ss=3)
    p = write_png(tmp_path / "three.png", img)
    r, doc = marks_json(p)
    assert "bent" not in r.stderr


@pytest.mark.slow
def test_three_straight_marks_one_lens_within_3u_or_not_ok(tmp_path):
    three = [(200, 150, 10.0, 250), (600, 450, -20.0, 250), (650, 150, 75.0, 250)]
    img = render_marks(800, 600, three, f=1.325 * 500.0, dist=LENS, seed=2, ss=3)
    p = write_png(tmp_path / "three.png", img)
    r, doc = marks_json(p)
    ms = sorted(found(doc), key=lambda m: m["angle_deg"])
    assert len(ms) == 3
    for m, t in zip(ms, sorted(x[2] for x in three), strict=True):
        err = angle_diff_arcsec(m["angle_deg"], t)
        if r.returncode == 0:
            assert abs(err) <= 3 * m["angle_u_arcsec"]
        else:
            assert abs(err) <= 3 * m["angle_u_arcsec"] or m["lens_limited"]


# ---------------------------------------------------------------- (2) ruled scale

@pytest.mark.slow
def test_ruled_scale_all_lines_and_pitch(tmp_path):
    img, marks = render_ruled(800, 600, 70.0, 9, seed=3)
    p = write_png(tmp_path / "scale.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE)
    ms = found(doc)
    assert len(ms) == 9, r.stderr
    fam = ms[0]["family"]
    assert fam["lines"] == 9
    assert fam["steps"] == list(range(9))
    assert abs(fam["pitch_px"] - 70.0) <= max(3 * fam["pitch_u_px"], 0.02)
    assert abs(angle_diff_arcsec(fam["angle_deg"], 90.0)) <= 3 * fam["angle_u_arcsec"]
    assert fam["deviant"] == []


@pytest.mark.slow
def test_ruled_scale_tilted_missing_graduation(tmp_path):
    """A tilted scale (89 deg) with one graduation missing: the step is skipped, pitch kept."""
    img, marks = render_ruled(1000, 700, 90.0, 8, angle_deg=89.0, seed=5)
    # erase graduation 3 by re-rendering without it
    keep = [m for i, m in enumerate(marks) if i != 3]
    img = render_marks(1000, 700, keep, seed=5)
    p = write_png(tmp_path / "scale.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE)
    ms = found(doc)
    assert len(ms) == 7, r.stderr
    fam = ms[0]["family"]
    assert fam["lines"] == 7
    assert abs(fam["pitch_px"] - 90.0) <= max(3 * fam["pitch_u_px"], 0.02)
    steps = sorted(fam["steps"])
    assert steps[-1] - steps[0] == 7 and len(steps) == 7


@pytest.mark.slow
def test_ruled_scale_min_length_counts_not_reported(tmp_path):
    img, marks = render_ruled(800, 600, 70.0, 9, seed=3)
    p = write_png(tmp_path / "scale.png", img)
    r, doc = marks_json(p, "--lens", LENS_FREE, "--min-length", "220")
    ms = found(doc)
    long_ = sum(1 for m in marks if m[3] >= 220)
    assert len(ms) == long_
    assert ms[0]["lines_not_reported"] == len(marks) - long_
    assert "not reported" in r.stderr


# ---------------------------------------------------------------- sessions: fixtures

@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """align synth session for valid files, then an `align init` session built from them."""
    base = tmp_path_factory.mktemp("u4")
    r = align("synth", "session", base / "syn", "--seed", "3", "-q")
    assert r.returncode == 0, r.stderr
    s = base / "unit"
    r = align("init", s, "--gonio", "--tumble", "--static", "-q")
    assert r.returncode == 0, r.stderr
    for f in ("tumble.csv", "gonio.csv", "platform.csv"):
        shutil.copy(base / "syn" / f, s / f)
    toml = (s / "session.toml").read_text()
    syn_toml = (base / "syn" / "session.toml").read_text()
    sign = '"-"' if 'scale_sign = "-"' in syn_toml else '"+"'
    toml = toml.replace('serial = "FILL IN"', 'serial = "U4-1"')
    toml = toml.replace('operator = "FILL IN"', 'operator = "user4"')
    toml = toml.replace('scale_sign = "+"              # FILL IN', f"scale_sign = {sign} #")
    toml = toml.replace("# latitude_deg = 50.45", "latitude_deg = 50.45")
    (s / "session.toml").write_text(toml)
    out = base / "unit.json"
    r = align("run", s, "--json", out, "-q")
    assert r.returncode == 0, r.stderr
    return s, out, json.loads(out.read_text())


def by_name(doc, key):
    vals = [doc[key][i][j] for i in range(3) for j in range(3) if i != j]
    return dict(zip(doc["angle_names"], vals, strict=True))


def worst_abs(doc):
    return max(abs(v) for row in doc["misalignment_arcsec"] for v in row)


def set_tolerance(s: Path, body: str):
    toml = (s / "session.toml").read_text()
    if "\n[tolerance]" in toml:
        toml = toml[: toml.index("\n[tolerance]")]
    toml = toml.replace("# [tolerance]", "# (tolerance)")
    (s / "session.toml").write_text(toml + "\n[tolerance]\n" + body + "\n")


def copy_session(session, tmp_path):
    s, _, _ = session
    d = tmp_path / s.name
    shutil.copytree(s, d)
    return d


# ---------------------------------------------------------------- (4) init -> check -> run

@pytest.mark.slow
def test_init_unfilled_session_check_names_each_problem(tmp_path):
    s = tmp_path / "blank"
    assert align("init", s, "--gonio", "--tumble", "-q").returncode == 0
    r = align("check", s)
    assert r.returncode == 2
    assert "serial" in r.stderr + r.stdout and "gonio.csv" in r.stderr + r.stdout


def test_init_refuses_to_replace_without_force(tmp_path):
    s = tmp_path / "blank"
    s.mkdir()
    (s / "session.toml").write_text("# mine\n")
    r = align("init", s, "--gonio")
    assert r.returncode == 2
    assert (s / "session.toml").read_text() == "# mine\n"


@pytest.mark.slow
def test_init_built_session_checks_and_runs(session):
    s, out, doc = session
    r = align("check", s)
    assert r.returncode == 0, r.stderr
    assert doc["ok"] is True and doc["fused"]
    assert doc["disposition"]["verdict"] == "NO TOLERANCE"


# ---------------------------------------------------------------- (3) tolerances, decisions

def _lot(result, *args):
    r = align("lot", result, "--json", "-", "-q", *args)
    doc = json.loads(r.stdout) if r.stdout.strip().startswith("{") else None
    return r, doc


@pytest.mark.slow
def test_lot_verdicts_constructed(session):
    _, out, doc = session
    E = by_name(doc, "misalignment_arcsec")
    U = by_name(doc, "misalignment_u_arcsec")
    worst = max(E, key=lambda n: abs(E[n]))
    big = abs(E[worst])
    # PASS: every angle well inside
    r, lot = _lot(out, "--tolerance-arcsec", f"{big + 50:.3f}", "--fail-on-reject")
    assert r.returncode == 0 and lot["dispositions"][0]["verdict"] == "PASS"
    # FAIL: the largest angle 30" outside
    r, lot = _lot(out, "--tolerance-arcsec", f"{big - 30:.3f}")
    assert r.returncode == 0 and lot["dispositions"][0]["verdict"] == "FAIL"
    assert lot["dispositions"][0]["worst"] == worst
    r, lot = _lot(out, "--tolerance-arcsec", f"{big - 30:.3f}", "--fail-on-reject")
    assert r.returncode == 3
    # INCONCLUSIVE: inside by half a guard band (guarded, k = 2)
    t = big + U[worst]
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}")
    assert lot["dispositions"][0]["verdict"] == "INCONCLUSIVE"
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}", "--fail-on-reject")
    assert r.returncode == 3
    # the same limit with simple acceptance: PASS; with k = 0: PASS
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}", "--decision", "simple",
                  "--fail-on-reject")
    assert r.returncode == 0 and lot["dispositions"][0]["verdict"] == "PASS"
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}", "--guard-k", "0")
    assert lot["dispositions"][0]["verdict"] == "PASS"
    # just outside by half a guard band: simple FAIL, guarded INCONCLUSIVE
    t = big - U[worst]
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}", "--decision", "simple")
    assert lot["dispositions"][0]["verdict"] == "FAIL"
    r, lot = _lot(out, "--tolerance-arcsec", f"{t:.4f}")
    assert lot["dispositions"][0]["verdict"] == "INCONCLUSIVE"


@pytest.mark.slow
def test_lot_bad_tolerance_flags_one_line(session):
    _, out, _ = session
    for args in (["--tolerance-arcsec", "10,-10"], ["--tolerance-arcsec", "-1"],
                 ["--tolerance-arcsec", "60", "--guard-k", "11"]):
        r = align("lot", out, *args)
        assert r.returncode == 2, args
        assert "Traceback" not in r.stderr and "tolerance" in r.stderr + "tolerance"


@pytest.mark.slow
def test_run_tolerance_in_toml_with_nominal(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, _, doc = session
    exy = doc["misalignment_arcsec"][0][1]
    # nominal = the value + 5", zone +-20": PASS
    set_tolerance(s, f"arcsec = 30000\nE_xY = 20\nnominal_arcsec = {{ E_xY = {exy + 5:.3f} }}")
    r = align("run", s, "--json", tmp_path / "a.json", "-q", "--fail-on-reject")
    assert r.returncode == 0, r.stderr
    d = json.loads((tmp_path / "a.json").read_text())["disposition"]
    a = {x["name"]: x for x in d["angles"]}["E_xY"]
    assert d["verdict"] == "PASS"
    assert a["lower_arcsec"] == pytest.approx(exy + 5 - 20, abs=2e-3)
    # nominal off by 50": FAIL, exit 3 with --fail-on-reject
    set_tolerance(s, f"arcsec = 30000\nE_xY = 20\nnominal_arcsec = {{ E_xY = {exy + 50:.3f} }}")
    r = align("run", s, "--json", tmp_path / "b.json", "-q", "--fail-on-reject")
    assert r.returncode == 3, r.stderr
    d = json.loads((tmp_path / "b.json").read_text())["disposition"]
    assert d["verdict"] == "FAIL" and d["worst"] == "E_xY"
    # the command line overrides the limits, nominals stay: +-30000 around it -> PASS
    r = align("run", s, "--json", tmp_path / "c.json", "-q", "--tolerance-arcsec", "30000",
              "--fail-on-reject")
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_run_tolerance_reversed_limits_refused(session, tmp_path):
    s = copy_session(session, tmp_path)
    set_tolerance(s, "E_xZ = [90, -30]")
    r = align("check", s)
    assert r.returncode == 2 and "E_xZ" in r.stdout + r.stderr
    r = align("run", s, "-q")
    assert r.returncode == 2 and "E_xZ" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
def test_failed_stage_is_not_measured_exit_2_with_fail_on_reject(session, tmp_path):
    s = copy_session(session, tmp_path)
    (s / "gonio.csv").write_text("count,counter,ref\n1,1,1\n")
    (s / "platform.csv").write_text("pose,ux,uy,uz\nL000,0,0,1\n")
    r = align("run", s, "--json", tmp_path / "r.json", "-q", "--tolerance-arcsec", "1e6",
              "--fail-on-reject")
    assert r.returncode == 2, r.stderr
    if (tmp_path / "r.json").exists():
        d = json.loads((tmp_path / "r.json").read_text())
        assert d["ok"] is False
        assert d["disposition"]["verdict"] in ("NOT MEASURED",)


# ---------------------------------------------------------------- (5) --resume and plan

@pytest.mark.slow
def test_resume_redoes_changed_input(session, tmp_path):
    s = copy_session(session, tmp_path)
    res = tmp_path / "res"
    res.mkdir()
    assert align("run", s, "--json", f"{res}/", "-q").returncode == 0
    with open(s / "tumble.csv", "a") as fh:
        fh.write("# a comment changes the sha256, not the data\n")
    r = align("run", s, "--json", f"{res}/", "--resume")
    assert r.returncode == 0
    assert "redone" in r.stderr + r.stdout and "tumble.csv" in r.stderr + r.stdout
    r = align("run", s, "--json", f"{res}/", "--resume")
    assert "skipped" in r.stderr + r.stdout


@pytest.mark.slow
def test_resume_with_changed_tolerance_flag_is_not_stale(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, _, doc = session
    res = tmp_path / "res"
    res.mkdir()
    r = align("run", s, "--json", f"{res}/", "-q", "--tolerance-arcsec", "30000")
    assert r.returncode == 0
    tight = worst_abs(doc) - 30            # the largest angle is 30" outside: FAIL
    r = align("run", s, "--json", f"{res}/", "-q", "--resume", "--tolerance-arcsec",
              f"{tight:.2f}", "--fail-on-reject")
    d = json.loads((res / f"{s.name}.json").read_text())
    assert d["disposition"]["verdict"] == "FAIL"
    assert r.returncode == 3


@pytest.mark.slow
def test_resume_keeps_fail_exit_3(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, _, doc = session
    res = tmp_path / "res"
    res.mkdir()
    tight = f"{worst_abs(doc) - 30:.2f}"
    r = align("run", s, "--json", f"{res}/", "-q", "--tolerance-arcsec", tight, "--fail-on-reject")
    assert r.returncode == 3
    r = align("run", s, "--json", f"{res}/", "-q", "--tolerance-arcsec", tight, "--fail-on-reject",
              "--resume")
    assert r.returncode == 3


@pytest.mark.slow
def test_plan_on_fail_and_on_no_tolerance(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, out, doc = session
    r = align("plan", out, "--json", "-")
    assert r.returncode == 0, r.stderr
    plan = json.loads(r.stdout)
    assert plan["format"] == "axis-align/plan"
    U = by_name(doc, "misalignment_u_arcsec")
    assert plan["target"] == max(U, key=U.get)           # no tolerance: the largest u
    assert plan["u_before_arcsec"] == pytest.approx(max(U.values()), rel=1e-6)
    for o in plan["options"]:
        assert o["u_after_arcsec"] < plan["u_before_arcsec"]
    tight = f"{worst_abs(doc) - 30:.2f}"
    j = tmp_path / "fail.json"
    assert align("run", s, "--json", j, "-q", "--tolerance-arcsec", tight).returncode == 0
    r = align("plan", j)
    assert r.returncode == 0
    assert "FAIL" in r.stdout and "leaves it a FAIL" in r.stdout


def test_plan_on_non_json_is_one_line(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    r = align("plan", p)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "x.csv" in r.stderr


@pytest.mark.slow
def test_empty_acceptance_zone_never_pass_and_p_conform(session, tmp_path):
    """Nominal = the measured value, limits +-1.8 u, k = 2: the guard bands cover the zone."""
    s = copy_session(session, tmp_path)
    _, _, doc = session
    E, U = by_name(doc, "misalignment_arcsec"), by_name(doc, "misalignment_u_arcsec")
    lims = "".join(f"{n} = {1.8 * U[n]:.5f}\n" for n in E)
    noms = ", ".join(f"{n} = {E[n]:.5f}" for n in E)
    set_tolerance(s, f'decision = "simple"\nk = 2.0\n{lims}nominal_arcsec = {{ {noms} }}')
    r = align("run", s, "--json", tmp_path / "simple.json", "-q", "--fail-on-reject")
    assert r.returncode == 0, r.stderr               # simple acceptance: inside -> PASS
    d = json.loads((tmp_path / "simple.json").read_text())["disposition"]
    assert d["verdict"] == "PASS" and d["rule"] == "simple"
    r = align("run", s, "--json", tmp_path / "g.json", "-q", "--decision", "guarded",
              "--fail-on-reject")
    assert r.returncode == 3, r.stderr
    d = json.loads((tmp_path / "g.json").read_text())["disposition"]
    assert d["verdict"] == "INCONCLUSIVE" and d["rule"] == "guarded"
    want = math.erf(1.8 / math.sqrt(2))             # Phi(1.8) - Phi(-1.8)
    for a in d["angles"]:
        assert a["verdict"] == "INCONCLUSIVE"
        assert a["p_conform"] == pytest.approx(want, abs=2e-3)
    assert d["p_conform_all"] < want


@pytest.mark.slow
def test_lens_option_bad_values_refused_in_one_line(tmp_path):
    img = render_marks(320, 240, [(159.5, 119.5, 0.3, 150.0)], seed=15, ss=1)
    p = write_png(tmp_path / "m.png", img)
    for bad, says in (("k1=-0.1", ">= 0"), ("k3=0.1", "k1, k2, p")):
        r = align("marks", p, "--lens", bad)
        assert r.returncode == 2 and says in r.stderr and "Traceback" not in r.stderr, bad


@pytest.mark.slow
def test_camera_model_for_another_image_size_is_not_measured(tmp_path):
    img = render_marks(400, 300, [(199.5, 149.5, 0.3, 150.0)], seed=16, ss=1)
    p = write_png(tmp_path / "m.png", img)
    cam = write_camera_json(tmp_path / "cam.json", 640, 480, 530.0, LENS)
    r, doc = marks_json(p, "--camera", cam)
    assert r.returncode == 2 and doc["ok"] is False
    assert doc["marks"][0]["found"] is False and "640x480" in r.stderr


@pytest.mark.slow
def test_ruled_scale_through_lens_with_camera_pitch(tmp_path):
    w, h = 800, 600
    f = 1.325 * 0.5 * math.hypot(w, h)
    marks = [(399.5 + (i - 4) * 70.0, 299.5, 90.0, 260.0 if i % 5 == 0 else 180.0)
             for i in range(9)]
    img = render_marks(w, h, marks, f=f, dist=LENS, seed=21, ss=2)
    p = write_png(tmp_path / "scale.png", img)
    cam = write_camera_json(tmp_path / "cam.json", w, h, f, LENS)
    r, doc = marks_json(p, "--camera", cam)
    ms = found(doc)
    assert len(ms) == 9
    # the members' own (undistorted) offsets are right: 70 px apart
    xs = sorted(m["offset_px"] * math.copysign(1.0, m["angle_deg"]) for m in ms)
    assert all(abs((b - a) - 70.0) < 0.5 for a, b in zip(xs, xs[1:], strict=False))
    fam = ms[0]["family"]
    assert sorted(fam["steps"]) == list(range(9))
    assert abs(fam["pitch_px"] - 70.0) <= 3 * fam["pitch_u_px"]


@pytest.mark.slow
def test_check_validates_camera_model_named_in_session(tmp_path):
    s = tmp_path / "syn"
    assert align("synth", "session", s, "--seed", "5", "-q").returncode == 0
    import cv2
    img = cv2.imread(str(s / "x_A.png"), cv2.IMREAD_UNCHANGED)
    h, w = img.shape[:2]
    cam = write_camera_json(s / "camA.json", w, h, 1000.0, (0.0, 0.0, 0.0, 0.0))
    doc = json.loads(cam.read_text())
    doc["camera_matrix"][0][2] = 5000.0                  # principal point off the image
    cam.write_text(json.dumps(doc))
    toml = (s / "session.toml").read_text()
    toml = toml.replace("[cameras.A]\n", '[cameras.A]\nmodel = "camA.json"\n', 1)
    (s / "session.toml").write_text(toml)
    r = align("check", s)
    assert r.returncode == 2 and "camA.json" in r.stdout + r.stderr


@pytest.mark.slow
def test_lot_tolerance_flag_keeps_session_nominals(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, _, doc = session
    E = by_name(doc, "misalignment_arcsec")
    noms = ", ".join(f"{n} = {E[n]:.4f}" for n in E)
    set_tolerance(s, f"arcsec = 30000\nnominal_arcsec = {{ {noms} }}")
    out = tmp_path / "r.json"
    r = align("run", s, "--json", out, "-q", "--tolerance-arcsec", "10")
    assert r.returncode == 0, r.stderr
    assert json.loads(out.read_text())["disposition"]["verdict"] == "PASS"   # run: nominals stay
    r, lot = _lot(out, "--tolerance-arcsec", "10")
    d = lot["dispositions"][0]
    assert {a["name"]: a["nominal_arcsec"] for a in d["angles"]} == pytest.approx(
        {n: round(E[n], 4) for n in E}, abs=1e-3)
    assert d["verdict"] == "PASS"


@pytest.mark.slow
@pytest.mark.parametrize("where", ["centre", "off_centre"])
def test_declared_lens_range_honest_gives_angle_within_3u(tmp_path, where):
    """--lens declaring ranges that hold the true lens (k1 0.171, k2 0.032 at R): never a
    confident wrong angle."""
    marks = POSITIONS[where]
    img = render_marks(W, H, marks, f=F, dist=LENS, seed=31, ss=2)
    p = write_png(tmp_path / "m.png", img)
    r, doc = marks_json(p, "--lens", "k1=0.2,k2=0.04,p=0.0001,aspect=0,pp_px=0")
    (m,) = found(doc)
    err = angle_diff_arcsec(m["angle_deg"], marks[0][2])
    assert abs(err) <= 3 * m["angle_u_arcsec"], (err, m["angle_u_arcsec"])
    assert (r.returncode == 0) == (not m["lens_limited"])


@pytest.mark.slow
def test_plan_on_failed_session_says_so(tmp_path):
    s = tmp_path / "syn"
    assert align("synth", "session", s, "--seed", "5", "-q").returncode == 0
    import cv2
    h, w = cv2.imread(str(s / "x_A.png"), cv2.IMREAD_UNCHANGED).shape[:2]
    cam = write_camera_json(s / "camA.json", w, h, 1000.0, (0.0, 0.0, 0.0, 0.0))
    doc = json.loads(cam.read_text())
    doc["camera_matrix"][0][2] = 5000.0
    cam.write_text(json.dumps(doc))
    toml = (s / "session.toml").read_text()
    # A camera model is the lens: the synthetic session's declared lens ranges for camera A
    # go (a model beside them is refused naming both keys).
    head, _, rest = toml.partition("[cameras.A]\n")
    section, nxt, tail = rest.partition("\n[")
    section = "\n".join(ln for ln in section.splitlines() if not ln.startswith("lens_"))
    (s / "session.toml").write_text(
        head + '[cameras.A]\nmodel = "camA.json"\n' + section + nxt + tail)
    out = tmp_path / "r.json"
    r = align("run", s, "--json", out, "-q")
    assert r.returncode == 2
    res = json.loads(out.read_text())
    assert res["ok"] is False and res["disposition"]["verdict"] == "NOT MEASURED"
    r = align("plan", out)
    assert r.returncode == 2 and "NOT MEASURED" in r.stderr


@pytest.mark.slow
def test_lot_decision_flag_alone_keeps_session_tolerance(session, tmp_path):
    s = copy_session(session, tmp_path)
    _, _, doc = session
    set_tolerance(s, f"arcsec = {worst_abs(doc) + 50:.2f}")
    out = tmp_path / "r.json"
    r = align("run", s, "--json", out, "-q", "--decision", "simple")
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())["disposition"]
    assert d["verdict"] == "PASS" and d["rule"] == "simple"
    r, lot = _lot(out, "--decision", "simple")
    assert lot["dispositions"][0]["verdict"] == "PASS"
