"""Independent user 16: an alignment station with three cameras of different kinds.

A metrology engineer's view, written from the documentation alone (README, docs/, the
schemas, ``--help``) with an own generator (``user16_inputs.py``: OpenCV lenses mapping rays
forward, blur before sampling, pixel-area integration, shot/read noise, column FPN, 8/12/16
bit, JPEG for the webcam):

* camera A, a wide-angle webcam, 640 x 480, strong barrel (k1 -0.32, k2 +0.11), JPEG q 92;
* camera B, a machine-vision camera, 2448 x 2048, 12 bit, tangential distortion (p1 9e-4,
  p2 -7e-4) and a principal point 16 px off centre;
* camera C, a microscope over a ruled stage micrometer, 16-bit TIFF, no distortion.

Right behaviour passes; each defect is a strict xfail with the figures seen. Tolerances come
from the stated u (z = error / u): for n honest z, RMS z is 1 +- 1/sqrt(2n).
"""
from __future__ import annotations

import dataclasses
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location(
    "user16_inputs", Path(__file__).with_name("user16_inputs.py"))
g = importlib.util.module_from_spec(_spec)
sys.modules["user16_inputs"] = g
_spec.loader.exec_module(g)

ZERO_LENS = "k1=0,k2=0,p=0,aspect=0,pp_px=0"
ZERO_KEYS = {"lens_k1": 0, "lens_k2": 0, "lens_p": 0, "lens_aspect": 0, "lens_pp_px": 0}


def _align(*args, check=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONDONTWRITEBYTECODE="1")
    r = subprocess.run([sys.executable, "-m", "align", *map(str, args)], capture_output=True,
                       text=True, env=env)
    assert r.returncode != 1, r.stderr[-3000:]  # never an internal error
    return r


def _marks(files, *flags, out):
    r = _align("marks", *files, "--json", out, "-q", *flags)
    doc = json.loads(Path(out).read_text())
    return r, doc


def _err_arcsec(measured_deg, truth_deg):
    return ((measured_deg - truth_deg + 90) % 180 - 90) * 3600


def _calibrate(cam, n, ss, folder, seed=7):
    rng = np.random.default_rng(seed)
    files = [g.save(cam, g.render_board(cam, rng, ss=ss, fill=rng.uniform(0.5, 0.85)),
                    folder / f"board_{cam.name}_{i:02d}") for i in range(n)]
    out = folder / f"cam_{cam.name}.json"
    # (The generator's boards are exact: declared so. The default 0.1 % print tolerance,
    # carried where the views cannot separate it, left the webcam's marks 19 of 40 within
    # the lens bound, one short of this user's 20.)
    r = _align("camera", *files, "--json", out, "-q", "--board-tolerance", "0")
    assert r.returncode == 0, r.stderr
    return out


# ----------------------------------------------------------------- default run (fast)


def test_generator_lens_and_truth_conventions():
    """The generator itself: the lens inversion round-trips, and a noise-free mark's
    principal axis (image moments of its absorption) is the truth's angle."""
    cam = g.WEBCAM
    u = np.array([[3.0, 600.0, 320.0], [470.0, 10.0, 240.0]])
    v = np.array([[2.0, 470.0, 240.0], [5.0, 300.0, 11.0]])
    ux, uy = g._undistort(cam, u, v)
    xn, yn = (ux - cam.cx) / cam.f, (uy - cam.cy) / cam.f
    xd, yd = g.distort(cam, xn, yn)
    assert np.max(np.abs(xd * cam.f + cam.cx - u)) < 1e-6
    assert np.max(np.abs(yd * cam.f + cam.cy - v)) < 1e-6
    # barrel: a corner pixel maps further out in the pinhole image
    assert abs(ux[0, 0] - cam.cx) > abs(u[0, 0] - cam.cx)
    # the interpolated map of a box's sub-samples is the exact inversion to 1e-4 px
    px, py = g.pinhole_coords(cam, 0, 0, 40, 30, 1)
    Y0, X0 = np.mgrid[0:30, 0:40].astype(float)
    ex, ey = g._undistort(cam, X0, Y0)
    assert np.max(np.hypot(px - ex, py - ey)) < 1e-4
    # a distortion-free camera: absorption moments give the angle (y down, angle towards -y)
    cam0 = dataclasses.replace(g.MICRO, width=200, height=160, fpn=0.0, ss=2)
    m = g.Mark(90.0, 85.0, 27.0, 120.0, width=3.0, depth=0.5)
    ang, off = g.truth(cam0, m)
    Y, X = np.mgrid[0:cam0.height, 0:cam0.width].astype(float)
    ux, uy = g.pinhole_coords(cam0, 0, 0, cam0.width, cam0.height, 1)
    assert np.allclose(ux, X) and np.allclose(uy, Y)
    a = math.radians(ang)
    n = np.array([math.sin(a), math.cos(a)])
    dx, dy = m.xc - (cam0.width - 1) / 2, m.yc - (cam0.height - 1) / 2
    assert abs(dx * n[0] + dy * n[1] - off) < 1e-12
    w = np.clip(g._box(((X - m.xc) * n[0] + (Y - m.yc) * n[1]), 1.5, 1.0)
                * g._box((X - m.xc) * math.cos(a) - (Y - m.yc) * math.sin(a), 60, 1.0), 0, None)
    mx, my = (w * X).sum() / w.sum(), (w * Y).sum() / w.sum()
    cxx = (w * (X - mx) ** 2).sum()
    cyy = (w * (Y - my) ** 2).sum()
    cxy = (w * (X - mx) * (Y - my)).sum()
    theta = 0.5 * math.degrees(math.atan2(2 * cxy, cxx - cyy))  # from +x towards +y (down)
    assert abs(-theta - ang) < 0.01


def test_pp_px_default_is_one_number():
    """(Was a strict xfail: the table said 20, `--help` and docs/formats.md 40.)"""
    table = (ROOT / "docs/commands/marks.md").read_text()
    row = next(line for line in table.splitlines() if line.startswith("| `pp_px`"))
    doc_default = float(row.split("|")[2])
    helptext = _align("marks", "--help").stdout.replace("\n", "").replace(" ", "")
    assert f"pp_px={doc_default:g}" in helptext


# ----------------------------------------------------------------- slow sweeps


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("user16")


@pytest.fixture(scope="module")
def machine_model(work):
    return _calibrate(g.MACHINE, 10, 2, work)


@pytest.mark.slow
def test_webcam_calibrated_marks_anywhere_u_covers_error(work, webcam_model):
    """Webcam (strong barrel, JPEG): 12 chessboards -> `align camera` -> 40 marks anywhere in
    the frame, any direction, defocus gradients, bent prints. Every angle not lens-limited is
    within 4 u of the truth and their RMS z is at most 1.3 (seen: n 32-36, RMS z 0.5-0.74,
    max |z| 1.6)."""
    cam = g.WEBCAM
    # (the module's one calibration of the webcam: a second `align camera` to the same
    # file is refused, as it should be, and errored the fixture that came after it)
    model = webcam_model
    files, truths = [], []
    for s in range(40):
        m = g.random_mark(cam, np.random.default_rng(1000 + s))
        img = g.render_marks(cam, [m], np.random.default_rng(s))
        files.append(g.save(cam, img, work / f"w{s:02d}"))
        truths.append(g.truth(cam, m)[0])
    _, doc = _marks(files, "--camera", model, out=work / "webcam.json")
    z = []
    for f, t in zip(files, truths, strict=True):
        ms = [mk for mk in doc["marks"] if Path(mk["image"]).name == f.name]
        assert len(ms) == 1 and ms[0]["found"], (f.name, ms)
        if not ms[0]["lens_limited"]:
            z.append(_err_arcsec(ms[0]["angle_deg"], t) / ms[0]["angle_u_arcsec"])
    z = np.array(z)
    assert len(z) >= 20
    assert np.abs(z).max() < 4.0, z
    assert np.sqrt(np.mean(z ** 2)) < 1.3, z


@pytest.mark.slow
def test_camera_quiet_prints_only_warnings(work):
    rng = np.random.default_rng(11)
    cam = g.WEBCAM
    files = [g.save(cam, g.render_board(cam, rng, ss=2), work / f"q{i}") for i in range(8)]
    r = _align("camera", *files, "--json", work / "q.json", "-q")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "", r.stdout


def _ok_within_3u(doc, files, truths) -> int:
    """How many of the images' single marks are not lens-limited; each of those is asserted
    within 3 u of its truth."""
    ok = 0
    for f, t in zip(files, truths, strict=True):
        (mk,) = [mk for mk in doc["marks"] if Path(mk["image"]).name == f.name]
        z = _err_arcsec(mk["angle_deg"], t) / mk["angle_u_arcsec"]
        if not mk["lens_limited"]:
            ok += 1
            assert abs(z) < 3, (f.name, z)
    return ok


def _bent_centre_marks(cam, folder, n=8):
    files, truths = [], []
    for s in range(n):
        r = np.random.default_rng(3000 + s)
        m = g.random_mark(cam, r, where="centre")
        m = dataclasses.replace(m, angle_deg=r.uniform(-90, 90),
                                sagitta=r.choice([-1, 1]) * r.uniform(0.5, 1.0),
                                length=min(m.length, 0.45 * cam.height))
        img = g.render_marks(cam, [m], np.random.default_rng(s))
        files.append(g.save(cam, img, folder / f"bent{s}"))
        truths.append(g.truth(cam, m)[0])
    return files, truths


@pytest.mark.slow
def test_machine_bent_centre_marks_with_declared_ranges_are_measured(work):
    """Machine-vision camera, no model, the engineer's small lens ranges: eight single bent
    marks (sagitta 0.5-1 px, 660-920 px) near the centre are read as bent, their chords
    within 3 u (seen: 8 of 8 ok, u 16-55″, max |z| 1.32)."""
    cam = g.MACHINE
    files, truths = _bent_centre_marks(cam, work)
    _, doc = _marks(files, "--lens", "k1=0.005,k2=0.001,p=0.0005,aspect=0.001,pp_px=20",
                    out=work / "bent_ranges.json")
    ok = _ok_within_3u(doc, files, truths)
    assert ok >= 6


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "a calibrated camera makes a centred bent mark worse than no model: 8 single bent marks "
    "(sagitta 0.5-1 px, 660-920 px, near the centre of the 2448x2048 camera) through its "
    "`align camera` model: 4 of 8 lens-limited (camera_or_bent: 'either the mark is bent or "
    "the lens differs from its calibration (k1 +0.0378 on top of it), and one mark cannot "
    "tell which'), u 78-275″, errors up to +142″ (bent1: +141.9″ at u 106.9″); the same "
    "images with only small declared ranges: 8 of 8 ok, u 16-55″, errors <= 20″, max |z| "
    "1.32 (another 8, seeds 2000-2007: 7 of 8 lens-limited, u 154-318″, error -365″). "
    "docs/camera.md: 'a single centred bent mark through the real lens's exact model ... Now "
    "neither warns and the bent mark is named'. Not fixed, on purpose (branch bent16): the "
    "marks call for |k1| 0.07-0.51 on top of the model (0.0013 +- 0.0011 at the "
    "half-diagonal), within the plausible ranges (0.3): a lens that is not its calibration "
    "is as plausible as a bent mark, and the two readings differ by a tilt of 2 s t / l^2 "
    "(t: the middle from the foot of the perpendicular from the principal point) whatever "
    "the change's size; the 6 of 16 beyond any plausible lens (|k1| 0.36-2.0) are named bent, "
    "within 0.8 u; the 10 lens-limited ones' u covers their errors (within 1.4 u). "
    "Bounding the change by twice the model's own distortion named all 16 bent (u 4-18″, "
    "max |z| 1.7) but read one straight mark through a model that left out its lens's k1 "
    "(-0.27) 12874″ off, ok (z +98; lens-limited before). docs/camera.md now says so"))
def test_machine_bent_centre_marks_with_model_are_named_bent(work, machine_model):
    cam = g.MACHINE
    files, truths = _bent_centre_marks(cam, work)
    _, doc = _marks(files, "--camera", machine_model, out=work / "bent_model.json")
    ok = _ok_within_3u(doc, files, truths)
    assert ok >= 6, ok


def _micrometer_frames(folder, seeds):
    cam = g.MICRO
    files, truths = [], []
    for s in seeds:
        r = np.random.default_rng(500 + s)
        ang, pitch, n = r.uniform(-90, 90), r.uniform(40, 80), int(r.integers(5, 10))
        xc, yc = cam.width / 2 + r.uniform(-150, 150), cam.height / 2 + r.uniform(-100, 100)
        img, _ = g.render_family(cam, xc, yc, ang, pitch, n, r.uniform(300, 600),
                                 np.random.default_rng(s), blur=r.uniform(0.8, 2.0))
        files.append(g.save(cam, img, folder / f"micro{s:02d}"))
        truths.append(((ang + 90) % 180 - 90, pitch, n))
    return files, truths


@pytest.fixture(scope="module")
def micrometer(work):
    """64 stage-micrometer frames (5-9 rulings, pitch 40-80 px, any direction, blur 0.8-2 px)
    measured in one `align marks` call; returns (files, truths, doc)."""
    files, truths = _micrometer_frames(work, range(64))
    _, doc = _marks(files, "--lens", ZERO_LENS, "--max-marks", "12", out=work / "micro.json")
    return files, truths, doc


def _families(micrometer):
    files, truths, doc = micrometer
    for f, (ang, pitch, n) in zip(files, truths, strict=True):
        ms = [mk for mk in doc["marks"] if Path(mk["image"]).name == f.name and mk["found"]]
        fam = next((mk["family"] for mk in ms if mk.get("family")), None)
        yield f, ang, pitch, n, ms, fam


@pytest.mark.slow
def test_micrometer_every_line_and_the_family_angle(micrometer):
    """Microscope, 16-bit TIFF, lens declared absent: every ruling of the stage micrometer
    is found, and the family's mean angle is honest: RMS z <= 1.25 over 64 frames (1 +- 0.09
    for an honest u), max |z| < 3.5 (seen: 64 of 64 complete, RMS z 1.01, max |z| 3.09)."""
    z = []
    for f, ang, _pitch, n, ms, fam in _families(micrometer):
        assert len(ms) == n and fam is not None, (f.name, len(ms), n)
        z.append(_err_arcsec(fam["angle_deg"], ang) / fam["angle_u_arcsec"])
    z = np.array(z)
    assert np.abs(z).max() < 3.5, z
    assert np.sqrt(np.mean(z ** 2)) < 1.25, z


@pytest.mark.slow
def test_micrometer_pitch_u_covers_its_error(micrometer):
    """The family's pitch u covers its error over the 64 frames: max |z| < 3.5, RMS z < 1.2
    (1 +- 0.09 for an honest u). Seen: RMS 0.82, max |z| 2.29 (before the texture's control
    variate was centred: RMS 1.00, micro25 41.35466 +- 0.00024 px for 41.35557, z -3.81 —
    its outer line moved by the coupling's noise times the shading's slope)."""
    z = np.array([(fam["pitch_px"] - pitch) / fam["pitch_u_px"]
                  for _f, _a, pitch, _n, _ms, fam in _families(micrometer)])
    assert np.abs(z).max() < 3.5, z
    assert np.sqrt(np.mean(z ** 2)) < 1.2, z


@pytest.mark.slow
def test_micrometer_no_phantom_grating(micrometer):
    phantom = [w for w in micrometer[2]["warnings"] if "grating" in w]
    assert not phantom, phantom


def _micro_session(work, name, seed, e_arcsec, **kw):
    """A session of two machine-vision cameras (declared distortion-free) with the six
    angles ``e_arcsec`` (E_xY, E_xZ, E_yX, E_yZ, E_zX, E_zY) [″]; returns (folder, result
    JSON path)."""
    names = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")
    E = {n: v * g.ARCSEC for n, v in zip(names, e_arcsec, strict=True)}
    folder = work / name
    g.write_session(folder, seed, {"A": g.MICRO, "B": g.MICRO}, E=E, where="centre",
                    lens_keys={"A": ZERO_KEYS, "B": ZERO_KEYS}, **kw)
    return folder, work / f"{name}.json"


@pytest.mark.slow
def test_session_verdict_follows_the_numbers(work):
    folder, out = _micro_session(work, "sess_fail", 3, (10, 120, -57, 20, -15, 5))
    _align("run", folder, "--json", out, "-q")
    doc = json.loads(out.read_text())
    e, u = doc["misalignment_arcsec"][0][2], doc["misalignment_u_arcsec"][0][2]
    # the numbers: E_xZ is measured (within 4 u of the truth) and beyond 60″ + 2u
    assert abs(e - 120) < 4 * u
    assert e - 60 > 2 * u
    assert doc["disposition"]["verdict"] == "FAIL", doc["disposition"]["reason"]


@pytest.mark.slow
def test_plan_names_a_declared_range_as_declared(work):
    folder, out = _micro_session(work, "sess_plan", 4, (10, 28, -5, 20, -15, 5),
                                 tolerance_arcsec=30)
    r = _align("run", folder, "--json", out, "-q")
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(out.read_text())
    e, u = doc["misalignment_arcsec"][0][2], doc["misalignment_u_arcsec"][0][2]
    assert abs(e - 28) < 4 * u
    assert doc["disposition"]["verdict"] == "INCONCLUSIVE"
    assert "as declared" in r.stderr
    plan = _align("plan", out)
    assert plan.returncode == 0, plan.stderr
    assert "default range" not in plan.stdout, plan.stdout


@pytest.mark.slow
def test_session_finds_two_rolled_cameras(work):
    A = g.ARCSEC
    E = {"E_xY": 10 * A, "E_xZ": 60 * A, "E_yX": -62 * A, "E_yZ": 20 * A, "E_zX": -15 * A,
         "E_zY": 5 * A}
    folder = work / "sess_rolls"
    truth = g.write_session(folder, 5, {"A": g.MICRO, "B": g.MICRO}, E=E, where="centre",
                            lens_keys={"A": ZERO_KEYS, "B": ZERO_KEYS}, ref_u_arcsec=0.5)
    assert min(abs(r) for r in truth["roll_arcsec"].values()) > 15  # both rolls are large
    out = work / "sess_rolls.json"
    _align("run", folder, "--json", out, "-q")
    doc = json.loads(out.read_text())
    found = {e["name"]: e for e in doc["effects"]}
    for cam_name, roll in truth["roll_arcsec"].items():
        e = found.get(f"camera_roll[{cam_name}]")
        assert e is not None, (cam_name, roll, doc["problems"])
        assert abs(e["estimate"] / A - roll) < 4 * e["u"] / A
    assert doc["ok"], doc["problems"]


@pytest.fixture(scope="module")
def webcam_model(work):
    return _calibrate(g.WEBCAM, 12, 3, work)


@pytest.mark.slow
def test_fail_reason_names_a_failing_angle(work, webcam_model, machine_model):
    folder = work / "sess_worst"
    g.write_session(folder, 16, {"A": g.WEBCAM, "B": g.MACHINE},
                    models={"A": webcam_model, "B": machine_model}, where="off")
    out = work / "sess_worst.json"
    _align("run", folder, "--json", out, "-q")
    dp = json.loads(out.read_text())["disposition"]
    assert dp["verdict"] == "FAIL", dp
    worst = next(a for a in dp["angles"] if a["name"] == dp["worst"])
    assert worst["verdict"] == "FAIL", (worst, dp["reason"])
