"""Independent user 12: the camera stage on real optics (issue 18), tried as a metrology lab would.

The images come from my own generators (``tests/imaging/user12_inputs.py``: OpenCV's lens model,
my own ``cv2.calibrateCamera`` of the real chessboard camera, shot noise, 8/12/16-bit), the real
photographs from ``../shared/data/real``. The tool is called as a user calls it: the CLI
(``python3 -m align``; in-process through ``runpy`` for the cheap checks, so the default run
does not pay the interpreter's start-up again), reading its JSON.

Default run: 4 tests (two of bad inputs on the camera path; the other camera's model, a twin of
the slow sweep; a clipped frame). The rest is ``-m slow``; the session check has no default
twin (one session run costs ~10 s CPU).

My timing check (issue 18's 640x480 <= 60 ms per image: 0.25 s CPU per image, a 1-pixel
image's failed run subtracted as the start-up) is not a test here: a timed test measures the
host, and the project times in ``benchmarks/`` (``benchmarks/marks.py --speed``). The lead
re-measured it as the marginal cost of three more images in one ``align marks`` call
(~50-77 ms per image): the rest was the first image's imports, which the 1-pixel run never
reached.
"""

from __future__ import annotations

import contextlib
import functools
import glob
import io
import json
import resource
import runpy
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.conftest import real_folder
from tests.imaging.user12_inputs import (
    Groove,
    angle_err_arcsec,
    calibrate_chessboard,
    lens_session,
    project,
    render,
    ruled_scale,
    save,
    truth_deg,
)

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------- calling the tool ------------

def cli(*args: str) -> tuple[int, str, str]:
    """``python3 -m align ARGS`` in this process: (exit status, stdout, stderr)."""
    out, err, old = io.StringIO(), io.StringIO(), sys.argv
    sys.argv = ["align", *args]
    code = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            runpy.run_module("align", run_name="__main__", alter_sys=True)
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else 1
    finally:
        sys.argv = old
    return code, out.getvalue(), err.getvalue()


def cli_sub(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "align", *args], capture_output=True, text=True,
                          cwd=ROOT, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def marks_json(files, *extra: str) -> tuple[int, dict, str]:
    code, out, err = cli("marks", *map(str, files), "--json", "-", "-q", *extra)
    return code, json.loads(out), err


def entries(d: dict, name: str) -> list[dict]:
    return [m for m in d["marks"] if Path(m["image"]).name == name]


# ---------------------------------------------------------------- lenses ----------------------

def _calibrate(files: list[str]):
    objp = np.zeros((54, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj, img = [], []
    for f in files:
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if ok:
            obj.append(objp)
            img.append(cv2.cornerSubPix(g, c, (5, 5), (-1, -1), (3, 30, 1e-3)))
    r = cv2.calibrateCameraExtended(obj, img, (640, 480), None, None)
    return r[1], r[2].ravel()[:5], r[5].ravel()[:9]


@functools.cache
def stereo_lenses():
    """My calibrations of the rig's left and right cameras (7 views each): K, dist, std."""
    folder = real_folder("opencv-chessboard")
    files = sorted(glob.glob(str(folder / "*.jpg")))
    return (_calibrate([f for f in files if "left" in f]),
            _calibrate([f for f in files if "right" in f]))


def model_json(path: Path, k, d, std) -> Path:
    """A camera model in the documented format (camera.schema.json), from my OpenCV
    calibration: its covariance the formal one, diagonal."""
    names = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
    path.write_text(json.dumps({
        "format": "axis-align/camera", "format_version": 4,
        "camera_matrix": np.asarray(k).tolist(), "dist_coeffs": np.asarray(d).tolist(),
        "image_size": [640, 480], "views": 7, "cov_params": names,
        "cov": np.diag(np.asarray(std) ** 2).tolist(),
        "u": dict(zip(names, np.asarray(std).tolist(), strict=True))}))
    return path


# ---------------------------------------------------------------- (5) bad inputs --------------

def test_bad_images_on_the_camera_path_one_line_each(tmp_path):
    """A corrupt JPEG, a 1-pixel PNG, a uniform (saturated) frame and a camera model of
    another image size: each one line naming the file and what is wrong, exit 2, no traceback."""
    img = render([Groove(160, 120, 30, 150)], None, None, (320, 240), seed=5)
    ok, buf = cv2.imencode(".jpg", img)
    (tmp_path / "corrupt.jpg").write_bytes(buf.tobytes()[: len(buf) // 2])
    save(tmp_path / "one.png", np.array([[128]], np.uint8))
    save(tmp_path / "white.png", np.full((240, 320), 255, np.uint8))
    save(tmp_path / "small.png", img)
    k, d, std = stereo_lenses()[0]
    cam = model_json(tmp_path / "cam.json", k, d, std)
    code, out, err = cli("marks", str(tmp_path / "corrupt.jpg"), str(tmp_path / "one.png"),
                         str(tmp_path / "white.png"), str(tmp_path / "small.png"),
                         "--camera", str(cam), "-q")
    assert code == 2
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    for name, what in (("corrupt.jpg", "corrupt"), ("one.png", "1x1"), ("white.png", "uniform"),
                       ("small.png", "640x480")):
        hit = [ln for ln in lines if name in ln]
        assert len(hit) == 1 and what in hit[0], (name, lines)


def test_bad_camera_model_names_file_and_key(tmp_path):
    """A camera model with a missing key, a wrong type, a NaN, cut short, absent: one line
    naming the file and the key, exit 2, no traceback."""
    save(tmp_path / "m.png", np.full((48, 64), 128, np.uint8))
    k, d, std = stereo_lenses()[0]
    good = json.loads(model_json(tmp_path / "good.json", k, d, std).read_text())
    cases = {
        "missing.json": ({kk: v for kk, v in good.items() if kk != "dist_coeffs"}, "dist_coeffs"),
        "type.json": ({**good, "camera_matrix": "535"}, "camera_matrix"),
        "nan.json": ({**good, "dist_coeffs": [float("nan")] * 5}, "dist_coeffs"),
    }
    for name, (obj, _key) in cases.items():
        (tmp_path / name).write_text(json.dumps(obj))
    (tmp_path / "cut.json").write_text(json.dumps(good)[:150])
    cases["cut.json"] = (None, "")
    cases["absent.json"] = (None, "not found")
    for name, (_, key) in cases.items():
        code, out, err = cli("marks", str(tmp_path / "m.png"), "--camera",
                             str(tmp_path / name), "-q")
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert code == 2 and "Traceback" not in err, (name, err)
        assert len(lines) == 1 and name in lines[0] and key in lines[0], (name, lines)


# ---------------------------------------------------------------- (1) the other camera's model -

# left camera's lens, the right camera's model given with --camera (a stereo rig's two
# cameras mixed up, or a lens that changed since its calibration): marks from my sweep
WRONG_MODEL_CASES = [(200, 150, -30, 250), (70, 380, 89.93, 120), (320, 110, 0.03, 500),
                     (140, 240, 0.08, 200), (560, 410, -60, 100), (320, 90, 90, 150)]


def _wrong_model_z(tmp_path, cases, seed0=100):
    (kl, dl, _), (kr, dr, sr) = stereo_lenses()
    cam = model_json(tmp_path / "right.json", kr, dr, sr)
    files, truths = [], []
    for i, (x, y, a, length) in enumerate(cases):
        g = Groove(x, y, a, length)
        files.append(save(tmp_path / f"w{i}.png", render([g], kl, dl, seed=seed0 + i)))
        truths.append(truth_deg(g, kl))
    code, d, err = marks_json(files, "--camera", str(cam))
    zs = []
    for f, t in zip(files, truths, strict=True):
        for m in entries(d, f.name):
            assert m["found"], m["error"]
            e = angle_err_arcsec(m["angle_deg"], t)
            u = m["angle_u_deg"] * 3600
            zs.append((f.name, e, u, e / u))
    return code, d, zs


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the right camera's model (mine, formal cov) on the "
                   "left camera's lens: a 250 px mark at (200,150) reads +1089\" off at +-311\" "
                   "(z 3.5; +1089\" at +-112\", z 9.75, with the tool's own right-camera model): "
                   "the one mark shows no departure from the model (p 0.65; 0.89), nothing is "
                   "warned; lens-limited (not ok, exit 2) by the model's own u only")
def test_other_cameras_model_u_covers_what_it_warns_about(tmp_path):
    """One mark of the slow sweep below (kept out of the default run: ~1.3 s CPU)."""
    code, d, zs = _wrong_model_z(tmp_path, WRONG_MODEL_CASES[:1])
    assert code == 2 or d["warnings"]
    assert all(abs(z) <= 3 for *_, z in zs), zs


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="6 marks through the left lens, the right camera's "
                   "model (mine, formal cov): z +3.5, +1.5, +9.4, -0.46, -3.9, -0.59 (the 4th "
                   "and 6th now found departing through the model's principal point, cy -8.3 / "
                   "cx +14.3 px, and carried as undetermined: -713\" at +-1557\"); the other "
                   "marks show no departure (p 0.65, 0.0076, 0.0023, 0.092): all six "
                   "lens-limited (not ok), u the model's own; the tool's own model: up to 9.75")
def test_other_cameras_model_sweep(tmp_path):
    code, d, zs = _wrong_model_z(tmp_path, WRONG_MODEL_CASES)
    for z in zs:
        print("other camera's model:", z)
    assert max(abs(z) for *_, z in zs) <= 3


# ---------------------------------------------------------------- (1) the sweep ---------------

SWEEP = [(320, 240, 30, 300), (320, 240, 0.05, 400), (320, 240, 89.95, 300),
         (320, 90, 90, 150), (320, 390, 90.05, 150), (140, 240, 0.08, 200),
         (500, 240, 45, 200), (90, 80, 20, 80), (560, 410, -60, 100), (70, 380, 89.93, 120),
         (570, 80, 0.04, 120), (320, 240, 36.87, 560), (320, 110, 0.03, 500),
         (330, 250, -70, 450), (200, 150, -30, 250), (450, 330, 60, 250)]


@pytest.mark.slow
def test_chessboard_lens_sweep_with_and_without_camera(tmp_path):
    """Marks through my calibration of the real chessboard camera (its left camera's 7
    views, as the tool's own `align camera` is run on them: the folder holds a stereo rig's
    left AND right views, which `align camera` now refuses as one camera, issue 18),
    80-560 px, centre to corners, within 0.1 deg of the axes; measured with the default
    lens ranges and with the tool's own model. Every reported angle within 3 u; every
    lens-limited mark not ok (exit 2); median u by distance from the centre printed."""
    folder = real_folder("opencv-chessboard")
    k, d, rms, n = calibrate_chessboard(folder, "left0*.jpg")
    cam = tmp_path / "cam.json"
    # --free-k3: my calibration frees k3 as OpenCV does by default; the tool's default leaves
    # k3 out unless the views determine it (docs/camera.md), so compare like for like.
    r = cli_sub("camera", *sorted(glob.glob(str(folder / "left0*.jpg"))), "--free-k3",
                "--json", str(cam), "-q")
    assert r.returncode == 0, r.stderr
    tool = json.loads(cam.read_text())
    # the tool's calibration and mine agree (same corners, same OpenCV solver, same model)
    assert np.allclose(tool["camera_matrix"], k, atol=0.05)
    files = []
    for i, (x, y, a, length) in enumerate(SWEEP):
        g = Groove(x, y, a, length)
        th = np.deg2rad(a)
        ends = project(np.array([[x, y]]) + np.outer([-length / 2, length / 2],
                                                     [np.cos(th), np.sin(th)]), k, d)
        assert ends.min() > 3 and ends[:, 0].max() < 636 and ends[:, 1].max() < 476
        files.append(save(tmp_path / f"s{i:02d}.png", render([g], k, d, seed=i)))
    rows = []
    for label, extra in (("default lens", ()), ("--camera", ("--camera", str(cam)))):
        code, out, err = cli("marks", *map(str, files), "--min-length", "80", "--json", "-",
                             "-q", *extra)
        res = json.loads(out)
        assert "Traceback" not in err
        for i, (x, y, a, length) in enumerate(SWEEP):
            mid = project(np.array([[x, y]], float), k, d)[0]
            rad = float(np.hypot(*(mid - [319.5, 239.5])))
            for m in entries(res, f"s{i:02d}.png"):
                if not m["found"]:
                    rows.append((label, i, rad, length, None, None, None, m["error"]))
                    continue
                e = angle_err_arcsec(m["angle_deg"], truth_deg(Groove(x, y, a, length), k))
                u = m["angle_u_deg"] * 3600
                rows.append((label, i, rad, length, e, u, m.get("lens_limited"), None))
                if m.get("lens_limited"):
                    assert not res["ok"] and code == 2
                assert abs(e) <= 3 * u, (label, i, e, u)
    for row in rows:
        print("sweep:", row)
    for label in ("default lens", "--camera"):
        for lo, hi in ((0, 60), (60, 200), (200, 400)):
            us = [r[5] for r in rows if r[0] == label and r[5] and lo <= r[2] < hi]
            if us:
                print(f"median u {label} r {lo}-{hi} px: {np.median(us):.0f}\" (n {len(us)})")
    found = [r for r in rows if r[4] is not None]
    assert len(found) >= 2 * len(SWEEP) - 2


# ---------------------------------------------------------------- (2) a session ---------------

@pytest.mark.slow
def test_session_undeclared_lens_no_false_roll(tmp_path):
    """Cameras + goniometer, camera A through the chessboard lens undeclared (marks 140 px
    off-centre): no false roll, E within 3 u, and a real 30″ roll of A named. (Was a strict
    xfail: the roll not named, forced into the fusion 15 ± 13″; with the centres out to the
    grooves' ends and the loop's sets across instruments, 27 Nov: max |z| 1.86, 1.84, 1.84,
    camera_roll[A] added in the rolled session only.)"""
    k, d, _, _ = calibrate_chessboard(real_folder("opencv-chessboard"))
    worst, rolls = [], []
    for seed, roll in ((0, 0.0), (1, 0.0), (1, 30.0)):
        folder = tmp_path / f"s{seed}_{roll:g}"
        truth = lens_session(folder, seed, k, d, roll_arcsec=roll)
        r = cli_sub("run", str(folder), "--json", str(folder / "res.json"), "-q")
        assert "Traceback" not in r.stderr
        res = json.loads((folder / "res.json").read_text())
        e = np.array(res["misalignment_rad"]) - np.array(truth["misalignment_rad"])
        u = np.array(res["misalignment_u_rad"])
        z = np.where(u > 0, e / np.where(u > 0, u, 1), 0)
        print("session", seed, roll, "z", np.round(z, 2).tolist(), "effects",
              [x.get("name") for x in res["effects"]])
        worst.append(float(np.max(np.abs(z))))
        rolls.append(any("roll" in str(x.get("name")) for x in res["effects"]))
    assert max(worst) <= 3
    assert rolls == [False, False, True]


# ---------------------------------------------------------------- (3) a ruled scale -----------

@pytest.mark.slow
def test_ruled_scale_every_line_family_and_pitch(tmp_path):
    """A 12-bit stage micrometer in a 16-bit TIFF: 23 lines (150/230 px, 60 px pitch),
    numerals, dust across 3 lines: every line found, the family's chi2/dof plausible, angle
    and pitch within 3 u of my truth (lens declared distortion-free)."""
    for seed in (0, 1):
        img, truth = ruled_scale(seed=seed)
        f = save(tmp_path / f"scale{seed}.tif", img)
        code, d, err = marks_json([f], "--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")
        fam = [m["family"] for m in d["marks"] if m.get("family")]
        assert fam, d["warnings"]
        fam = fam[0]
        t = -truth["angle_deg"]
        e = angle_err_arcsec(fam["angle_deg"], t)
        print("scale", seed, "lines", fam["lines"], "chi2/dof", round(fam["chi2_dof"], 2),
              "angle err", round(e, 2), "u", round(fam["angle_u_arcsec"], 2), "pitch",
              fam["pitch_px"], "+-", fam["pitch_u_px"])
        assert fam["lines"] == truth["n_lines"] and fam["failed"] == 0
        assert 0.2 < fam["chi2_dof"] < 2.5
        assert abs(e) <= 3 * fam["angle_u_arcsec"]
        assert abs(fam["pitch_px"] - truth["pitch_px"]) <= 3 * max(fam["pitch_u_px"], 1e-9)


def _dense_family(tmp_path, seed, lens_free=True, **kw):
    img, truth = ruled_scale(seed=seed, **kw)
    f = save(tmp_path / f"dense{seed}.tif", img)
    flags = ("--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0") if lens_free else ()
    code, d, err = marks_json([f], *flags)
    fam = [m["family"] for m in d["marks"] if m.get("family")]
    return code, d, (fam[0] if fam else None), truth


DENSE = {"size": (640, 480), "n_lines": 19, "pitch": 24.0, "short_len": 70.0,
         "long_len": 110.0}


def test_dense_ruling_every_line_and_its_pitch(tmp_path):
    """Default twin of the slow dense-ruling sweep: seed 0."""
    code, d, fam, truth = _dense_family(tmp_path, 0, **DENSE)
    assert fam is not None and fam["lines"] == truth["n_lines"], (code, len(d["marks"]))
    assert abs(fam["pitch_px"] - truth["pitch_px"]) <= 3 * max(fam["pitch_u_px"], 1e-9)


@pytest.mark.slow
def test_dense_ruling_over_seeds(tmp_path):
    bad = []
    for seed in range(4):
        code, d, fam, truth = _dense_family(tmp_path, seed, **DENSE)
        got = (code, None if fam is None else (fam["lines"], fam["pitch_px"], fam["pitch_u_px"]))
        print("dense ruling", seed, got)
        if fam is None or fam["lines"] != 19 or abs(fam["pitch_px"] - 24) > 3 * fam["pitch_u_px"]:
            bad.append((seed, got))
    assert not bad, bad


@pytest.mark.slow
def test_ruled_scale_through_lens_steps_and_pitch(tmp_path):
    (kl, dl, _), _ = stereo_lenses()
    k = kl.copy()
    k[:2] *= 2.5
    code, d, fam, truth = _dense_family(tmp_path, 3, lens_free=False, k=k, d=dl,
                                         pitch=70.0)
    print("lens ruling", code, fam and (fam["lines"], fam["pitch_px"], fam["pitch_u_px"],
                                        fam["steps"]))
    assert fam is not None and fam["steps"] == list(range(truth["n_lines"]))
    assert abs(fam["pitch_px"] - 70.0) <= 3 * fam["pitch_u_px"]


# ---------------------------------------------------------------- (4) real photographs --------

@pytest.mark.slow
def test_real_photographs_refused_or_flagged_in_one_line():
    """The real photographs as they come: no traceback; each image's refusal is one line
    naming it; a result with a lens-limited angle is not ok (exit 2). Times printed."""
    files = sorted(glob.glob(str(real_folder("opencv-chessboard") / "*01.jpg")))
    files += sorted(glob.glob(str(real_folder("opencv-lines") / "*.jpg")))
    for f in files:
        t0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        w = time.time()
        r = cli_sub("marks", f, "--json", "-", "-q")
        t1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (t1.ru_utime + t1.ru_stime) - (t0.ru_utime + t0.ru_stime)
        assert "Traceback" not in r.stderr, f
        d = json.loads(r.stdout)
        failed = [m for m in d["marks"] if not m["found"]]
        print(f"real {Path(f).name}: exit {r.returncode} ok {d['ok']} marks "
              f"{len(d['marks']) - len(failed)} failed {len(failed)} cpu {cpu:.2f}s "
              f"wall {time.time() - w:.2f}s")
        for m in failed:
            assert m["error"] and "\n" not in m["error"] and Path(f).name in m["error"]
        if any(m.get("lens_limited") for m in d["marks"]):
            assert r.returncode == 2 and not d["ok"]


# ---------------------------------------------------------------- (5) clipped frame -----------

def test_clipped_background_is_named(tmp_path):
    img = render([Groove(320, 240, 30, 300, depth=0.3)], None, None, seed=3, bits=16,
                 full_well=60000).astype(float)
    ramp = 1.0 + 0.8 * np.arange(640)[None, :] / 640
    f = save(tmp_path / "ramp16.png", np.clip(img * ramp, 0, 65535).astype(np.uint16))
    code, d, err = marks_json([f], "--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")
    said = [w.replace(str(f), "IMG") for w in d["warnings"]]   # the path may hold "clip"
    assert any("clip" in w or "saturat" in w or "over-exposed" in w for w in said), said
