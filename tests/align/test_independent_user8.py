"""Independent user 8: the camera stage through a lens I calibrated myself, and the triad's
calibration with effects a real accelerometer has.

The inputs come from ``tests/align/user8_inputs.py`` (my own groove profile, a rounded
asymmetric V, integrated over each pixel through a Brown-Conrady lens from
``cv2.calibrateCamera`` on the real chessboard photographs; static tumbles with an asymmetric
scale factor, quantisation, a bias step, vibration) and import nothing from the project. The
CLI runs in process through ``align.cli.main(argv)`` (``ALIGN8_SUBPROCESS=1``: as
``python3 -m align`` from the worktree root). Right behaviour passes; each defect is written
as the tool should behave and marked ``xfail(strict=True)`` with the figures I saw.

Truth conventions. A mark's angle: its direction in the normalised (pinhole, square-pixel)
plane. A tumble's scale factor: (k+ + k-)/2, the output per g along the sensitive axis; its
bias: the output at zero input over k [g] (for an asymmetric scale factor the six-position
convention (u(+g) + u(-g)) / 2k differs by the asymmetry; a test accepts either).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from align.cli import main as align_main  # the CLI's entry point: argv -> exit status
from tests.align import user8_inputs as ui

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# a single Gaussian estimate beyond 3.5 u: 5e-4 of the time
Z1 = 3.5


def align(*args: str) -> subprocess.CompletedProcess:
    """``align ARGS`` in process (the CLI returns its exit status), output captured."""
    if os.environ.get("ALIGN8_SUBPROCESS"):
        return subprocess.run([sys.executable, "-m", "align", *args], cwd=ROOT,
                              capture_output=True, text=True, timeout=600)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = align_main(list(args))
        except SystemExit as e:  # argparse's own refusals
            rc = e.code if isinstance(e.code, int) else 2
    return subprocess.CompletedProcess(list(args), rc, out.getvalue(), err.getvalue())


def _json(r: subprocess.CompletedProcess) -> dict:
    i = r.stdout.find("{")
    assert i >= 0, f"no JSON on stdout (exit {r.returncode}): {r.stderr[-400:]}"
    return json.loads(r.stdout[i:])


# ---------------------------------------------------------------- the camera stage


@pytest.fixture(scope="module")
def lens():
    if not ui.CHESS.is_dir():
        pytest.skip(f"real data folder {ui.CHESS} is absent (it lives in ../shared/data/real)")
    return ui.chessboard_lens()


def exact_camera(k: np.ndarray, d: np.ndarray, folder: Path) -> str:
    """A camera JSON holding my lens exactly, with a tight u (a very good calibration), written
    to the format of ``align/schemas/camera.schema.json``."""
    cam = {"format": "axis-align/camera", "format_version": 3, "tool": "axis-align",
           "tool_version": "0.1.0", "camera_matrix": k.tolist(),
           "dist_coeffs": [float(x) for x in d], "image_size": list(ui.SIZE), "rms_px": 0.1,
           "u": {"fx": 0.05, "fy": 0.05, "cx": 0.05, "cy": 0.05, "k1": 1e-5, "k2": 1e-5,
                 "p1": 1e-6, "p2": 1e-6, "k3": 1e-5, "aspect": 1e-6},
           "per_view_rms_px": {}}
    p = folder / "exact_camera.json"
    p.write_text(json.dumps(cam))
    return str(p)


def measure(sc: ui.Scene, folder: Path, name: str, *args: str):
    p = ui.write(sc, folder / f"{name}.png")
    r = align("marks", str(p), "--json", "-", "-q", "--force", *args)
    return r.returncode, _json(r), r.stderr


def mark_errors(js: dict, truths_rad: list[float]) -> list[tuple[float, float, bool]]:
    """(error ″, u ″, ok) of each mark found, matched to the nearest truth."""
    out = []
    for m in js["marks"]:
        if not m["found"]:
            continue
        e = min((ui.wrap_deg(m["angle_deg"] - np.rad2deg(t)) * 3600 for t in truths_rad),
                key=abs)
        out.append((e, m["angle_u_deg"] * 3600, not m.get("lens_limited", False)))
    return out


def check_covered(rc: int, js: dict, errs, n_expected: int) -> list[str]:
    """What is wrong: a mark missing, or an angle beyond Z1 u with the document ok."""
    bad = []
    if len(errs) != n_expected:
        bad.append(f"{len(errs)} marks found, {n_expected} drawn")
    for e, u, _ in errs:
        if abs(e) > Z1 * u and js["ok"] and rc == 0:
            bad.append(f"error {e:+.1f}″ = {e / u:+.1f} u (u {u:.1f}″) with ok and exit 0")
    return bad


def test_centre_mark_through_exact_camera_is_within_u(lens, tmp_path):
    """A 300 px mark near the centre, 8-bit PNG, my groove through my lens: the angle lies
    within 3.5 u, ok, exit 0 (seen: +4.3″ ± 5.6″)."""
    k, d = lens
    cam = exact_camera(k, d, tmp_path)
    a = np.deg2rad(12.0)
    rc, js, err = measure(ui.Scene([ui.mark_at(k, a, 320, 240)], k, d, seed=0), tmp_path, "c",
                          "--camera", cam)
    errs = mark_errors(js, [a])
    assert check_covered(rc, js, errs, 1) == []
    assert rc == 0 and js["ok"], err


def test_two_marks_in_one_image_both_within_u(lens, tmp_path):
    """Two marks (12° and 95°, 300 and 250 px) in one frame: both found, each within 3.5 u
    (seen: z +1.08 and +0.58)."""
    k, d = lens
    cam = exact_camera(k, d, tmp_path)
    t = [np.deg2rad(12.0), np.deg2rad(95.0)]
    sc = ui.Scene([ui.mark_at(k, t[0], 250, 150), ui.mark_at(k, t[1], 450, 300, length_px=250)],
                  k, d, seed=0)
    rc, js, err = measure(sc, tmp_path, "two", "--camera", cam)
    assert check_covered(rc, js, mark_errors(js, t), 2) == []


@pytest.mark.slow
def test_uncalibrated_lens_is_not_a_confident_answer(lens, tmp_path):
    """Without a camera model the real lens (k1_cv -0.28) bends four marks near the corners by
    up to 2400″: the tool must either cover it or say not ok (seen: exit 2, ok false,
    u ~5000″)."""
    k, d = lens
    t = [np.deg2rad(5), np.deg2rad(85), np.deg2rad(-5), np.deg2rad(92)]
    sc = ui.Scene([ui.mark_at(k, t[0], 150, 100, length_px=220),
                   ui.mark_at(k, t[1], 500, 120, length_px=220),
                   ui.mark_at(k, t[2], 480, 380, length_px=220),
                   ui.mark_at(k, t[3], 130, 350, length_px=220)], k, d, seed=0)
    rc, js, err = measure(sc, tmp_path, "nocam")
    assert check_covered(rc, js, mark_errors(js, t), 4) == []


def test_mark_crossed_by_a_shadow_edge_is_measured(lens, tmp_path):
    """A housing's edge throws a shadow across the face: the mark is still measured (its
    angle within 3.5 u), or the refusal names the shadow."""
    k, d = lens
    cam = exact_camera(k, d, tmp_path)
    a = np.deg2rad(15.0)
    sc = ui.Scene([ui.mark_at(k, a, 320, 240, length_px=350)], k, d, seed=950,
                  shadow=(np.deg2rad(75.0), 0.0, 6.0, 0.2))
    rc, js, err = measure(sc, tmp_path, "shadow", "--camera", cam)
    errs = mark_errors(js, [a])
    assert len(errs) == 1 or "shadow" in err, err
    assert check_covered(rc, js, errs, 1) == []


@pytest.mark.slow
def test_cropped_sensor_principal_point_far_off_centre_is_flagged(lens, tmp_path):
    """A region-of-interest readout: the principal point (120, 90) px off the image centre
    (the --lens default range is 20 px), six marks over the frame, no camera model: every
    angle within 3.5 u or not ok. Seen: the lines' bows disagree with one lens (chi2 ~5000 on
    5 dof), k2 'beyond any lens', every mark lens-limited, exit 2 (one mark +4320″ ± 101″,
    z 43, but lens-limited and not ok)."""
    k, d = lens
    k2 = k.copy()
    k2[0, 2], k2[1, 2] = 319.5 + 120.0, 239.5 + 90.0
    angs = [np.deg2rad(x) for x in (5, -8, 85, 95, 12, -3)]
    pos = [(160, 90), (470, 100), (110, 300), (540, 330), (320, 400), (330, 230)]
    sc = ui.Scene([ui.mark_at(k2, a, x, y, length_px=200) for a, (x, y) in zip(angs, pos,
                                                                             strict=True)],
                  k2, d, seed=0)
    rc, js, err = measure(sc, tmp_path, "roi")
    errs = mark_errors(js, angs)
    assert check_covered(rc, js, errs, 6) == []
    assert all(not ok for e, u, ok in errs if abs(e) > Z1 * u), errs  # lens-limited


@pytest.mark.slow
def test_whole_chain_boards_to_camera_to_marks(lens, tmp_path):
    """The whole chain through my lens: seven chessboards rendered at the real photographs'
    board poses, `align camera` on them, then marks measured through that model: each angle
    within 3.5 u or not ok, and the mid-field ones ok. Seen: the model's fx 538.77 ± 0.38
    (truth 538.42), k1 -0.27874 ± 0.0028 (truth -0.27872); mid-field marks +4.3, -7.6, +5.8,
    -2.5″ with u 15″ (RMS z 0.32), exit 0; corner marks lens-limited (u 88-102″ from k2),
    exit 2, within 0.52 u."""
    k, d = lens
    boards = []
    for i, (rv, tv) in enumerate(ui.chessboard_poses()):
        boards.append(str(tmp_path / f"board{i}.png"))
        cv2.imwrite(boards[-1], ui.render_board(k, d, rv, tv, seed=i))
    cam = str(tmp_path / "camera.json")
    r = align("camera", *boards, "--json", cam, "-q")
    assert r.returncode == 0, r.stderr
    bad, mid_ok = [], []
    for s in range(3):
        for name, (x, y, length) in {"mid": (260, 200, 250), "corner": (150, 110, 200)}.items():
            a = np.deg2rad(20.0 + 10 * s)
            sc = ui.Scene([ui.mark_at(k, a, x, y, length_px=length)], k, d, seed=600 + s)
            rc, js, err = measure(sc, tmp_path, f"{name}{s}", "--camera", cam)
            bad += check_covered(rc, js, mark_errors(js, [a]), 1)
            if name == "mid":
                mid_ok.append(rc == 0 and js["ok"])
    assert bad == []
    assert all(mid_ok), mid_ok


CAMERA_CASES = {
    # name: (mark pixel x, y, length, Scene keywords, Mark keywords)
    "centre": (320, 240, 300, {}, {}),
    "corner": (130, 110, 200, {}, {}),
    "short": (200, 300, 120, {}, {}),
    "jpeg75": (320, 240, 300, {"jpeg": 75}, {}),
    "jpeg30": (320, 240, 350, {"jpeg": 30}, {}),
    "bits12": (320, 240, 300, {"bits": 12}, {}),
    "bits16": (320, 240, 300, {"bits": 16}, {}),
    "defocus": (320, 240, 400, {"defocus_px": 2.5}, {}),
    "vignette_dim": (450, 350, 250, {"vignette": 0.6, "full_well": 4000.0}, {}),
    # a face tilted to the camera: a symmetric groove's imaged width 5 px +- 30 % end to end
    "tilted_face": (320, 240, 350, {}, {"asym": 0.0, "width_gain": 0.6}),
    # rolling shutter on a shaking camera: rows shifted 0.3 px sin(2 pi row / 110)
    "rolling_shutter": (320, 240, 350, {"shake": (0.3, 110.0, 1.0)}, {}),
    # a bright (polished) groove on a darker face
    "bright_groove": (320, 240, 350, {"level": 0.5}, {"contrast": -0.5}),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CAMERA_CASES))
def test_camera_cases_over_seeds(lens, tmp_path, case):
    """Over 6 seeds each angle lies within 3.5 u (or the mark is not ok) and the normalised
    errors' RMS is at most 1.93 (the RMS of 6 unit normals exceeds it with p = 1e-3).
    Seen (4-8 seeds): centre RMS z 0.86, corner 0.95 (8 seeds, mean z +0.6), short 0.67,
    JPEG q75 1.07, q30 0.77, 12-bit 0.62, 16-bit 0.64, defocus 0.55, tilted face 0.77,
    rolling shutter 0.60 over the 3 marks with 2.2-2.7 periods of the wiggle along them (the
    wiggle fitted off before the lens check, align/lens_wiggle.py; the 3 with 1.85 periods,
    no wiggle, lens-limited: not ok). JPEG q30 over these 6 seeds: RMS z 1.66 (z -2.6 to
    +1.0; u a little short, not several times)."""
    k, d = lens
    cam = exact_camera(k, d, tmp_path)
    x, y, length, kw, mkw = CAMERA_CASES[case]
    zs, bad = [], []
    for s in range(6):
        a = np.deg2rad(30.0 + 7.0 * s)
        sc = ui.Scene([ui.mark_at(k, a, x, y, length_px=length, **mkw)], k, d, seed=200 + s,
                      **kw)
        rc, js, err = measure(sc, tmp_path, f"{case}{s}", "--camera", cam)
        errs = mark_errors(js, [a])
        bad += check_covered(rc, js, errs, 1)
        zs += [e / u for e, u, ok in errs if ok]
    assert bad == []
    assert np.sqrt(np.mean(np.square(zs))) <= 1.93, np.round(zs, 2)


# ---------------------------------------------------------------- the triad's calibration


def calibrate(tr: ui.Triad, seed: int, folder: Path, ups=None, **kw):
    ups = ui.cube26() if ups is None else ups
    p = ui.write_tumble(ui.tumble_rows(tr, ups, seed, **kw), folder / f"tumble{seed}.csv")
    r = align("calibrate", str(p), "--units", "g", "--json", "-", "-q", "--force")
    return r.returncode, _json(r), r.stderr


def cal_z(tr: ui.Triad, js: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """z of the scale factors, of the biases against the zero-input truth, and against the
    six-position convention (u(+g) + u(-g)) / 2k = o/k + asym."""
    k = np.array(js["scale_factors_v_per_g"])
    ku = np.array(js["scale_factors_u_v_per_g"])
    b = np.array(js["bias_g"])
    bu = np.array(js["bias_u_g"])
    kt = np.array(tr.k)
    b0 = np.array(tr.o) / kt
    return (k - kt) / ku, (b - b0) / bu, (b - b0 - np.array(tr.asym)) / bu


def cal_problems(rc: int, js: dict, err: str, tr: ui.Triad) -> list[str]:
    """A confident wrong answer: a parameter beyond Z1 u (the bias under both conventions)
    while exit 0, ok true and no warning at all."""
    zk, zb0, zb6 = cal_z(tr, js)
    zb = np.where(np.abs(zb0) < np.abs(zb6), zb0, zb6)
    flagged = rc != 0 or not js["ok"] or bool(js["warnings"]) or "WARNING" in err
    out = []
    if not flagged:
        for name, z in (("k", zk), ("bias", zb)):
            for i, zi in enumerate(z):
                if abs(zi) > Z1:
                    out.append(f"{name}_{'xyz'[i]} off by {zi:+.1f} u, exit 0, ok, no warning")
    return out


def test_clean_tumble_within_u(tmp_path):
    """26 poses, white noise 0.3 mg a sample, no effect: every k and bias within 3.5 u, ok,
    exit 0, no effect added (seen: |z| <= 2.7)."""
    tr = ui.Triad()
    rc, js, err = calibrate(tr, 0, tmp_path)
    zk, zb, _ = cal_z(tr, js)
    assert rc == 0 and js["ok"], err
    assert np.all(np.abs(zk) <= Z1) and np.all(np.abs(zb) <= Z1), (zk, zb)
    assert js["effects"] == []


def test_asymmetric_scale_factor_is_covered_or_flagged(tmp_path):
    """A scale factor 300 ppm larger for +g than for -g on each axis (a pendulous
    accelerometer's asymmetry): the biases must lie within 3.5 u under one of the two bias
    conventions, or the result must be flagged."""
    tr = ui.Triad(asym=(3e-4, -3e-4, 3e-4))
    rc, js, err = calibrate(tr, 1, tmp_path)
    assert cal_problems(rc, js, err, tr) == []


@pytest.mark.slow
def test_asymmetric_scale_factor_over_seeds(tmp_path):
    bad = []
    for s in range(6):
        tr = ui.Triad(asym=(3e-4, -3e-4, 3e-4))
        rc, js, err = calibrate(tr, s, tmp_path)
        bad += [f"seed {s}: {p}" for p in cal_problems(rc, js, err, tr)]
    assert bad == []


def test_large_asymmetric_scale_factor_is_not_ok(tmp_path):
    """Whatever the warnings, a bias 20 u off under both conventions must not be ok/exit 0."""
    tr = ui.Triad(asym=(1e-3, -8e-4, 6e-4))
    rc, js, err = calibrate(tr, 0, tmp_path)
    _, zb0, zb6 = cal_z(tr, js)
    worst = np.minimum(np.abs(zb0), np.abs(zb6)).max()
    assert worst <= Z1 or rc != 0 or not js["ok"], (zb0, zb6, rc, js["ok"])


def k_lin_problems(rc: int, js: dict, err: str, tr: ui.Triad) -> list[str]:
    """k against the linear coefficient of u = k (a + K3 a^3) (the tool's own model equation,
    docs/calibration-effects.md: k multiplies x, the higher terms are separate), beyond Z1 u
    with exit 0, ok and no warning."""
    zk, _, _ = cal_z(tr, js)
    flagged = rc != 0 or not js["ok"] or bool(js["warnings"]) or "WARNING" in err
    return [] if flagged else [f"k_{'xyz'[i]} off by {z:+.1f} u, exit 0, ok, no warning"
                               for i, z in enumerate(zk) if abs(z) > Z1]


def test_cubic_nonlinearity_is_covered_or_flagged(tmp_path):
    tr = ui.Triad(k3=(1e-4, -1e-4, 1e-4))
    rc, js, err = calibrate(tr, 0, tmp_path)
    assert k_lin_problems(rc, js, err, tr) == []


@pytest.mark.slow
def test_cubic_nonlinearity_over_seeds(tmp_path):
    bad = []
    for s in range(6):
        tr = ui.Triad(k3=(1e-4, -1e-4, 1e-4))
        rc, js, err = calibrate(tr, s, tmp_path)
        bad += [f"seed {s}: {p}" for p in k_lin_problems(rc, js, err, tr)]
    assert bad == []


def test_settling_creep_is_covered_or_flagged(tmp_path):
    """After each turn the reading creeps the last 3e-4 of the way (anelastic flexure): the
    pose means carry the previous attitude's trace. The samples within each pose show it (a
    decaying trend); k and bias within 3.5 u, or flagged."""
    tr = ui.Triad(creep=3e-4)
    rc, js, err = calibrate(tr, 0, tmp_path)
    assert cal_problems(rc, js, err, tr) == []


@pytest.mark.slow
def test_settling_creep_over_seeds(tmp_path):
    bad = []
    for c in (2e-4, 3e-4, 1e-3):
        for s in range(8):
            tr = ui.Triad(creep=c)
            rc, js, err = calibrate(tr, s, tmp_path)
            bad += [f"creep {c} seed {s}: {p}" for p in cal_problems(rc, js, err, tr)]
    assert bad == []


@pytest.mark.parametrize("tilt_deg", [0.3, 2.0])
def test_six_faces_off_square_are_covered(tmp_path, tilt_deg):
    """Six labelled faces (+x, -x, ...), each tilted by 0.3° (inside the default
    --fixture-error 0.5°) or 2° (beyond it) about a random axis: the known-pose method's k and
    bias within 3.5 u (or flagged). Seen: 0.3°: |z| <= 1.5, beta's u ~0.5° carries the
    fixture; 2°: unexplained structure warned, u widened x7-14, |z| <= 2.0."""
    tr = ui.Triad()
    p = ui.write_tumble(ui.tumble_rows(tr, ui.tilted_faces(tilt_deg, 0), 0, labels=ui.FACES),
                        tmp_path / "faces.csv")
    r = align("calibrate", str(p), "--units", "g", "--json", "-", "-q", "--force")
    js = _json(r)
    assert cal_problems(r.returncode, js, r.stderr, tr) == []
    zk, zb, _ = cal_z(tr, js)
    assert np.all(np.abs(zk) <= Z1) and np.all(np.abs(zb) <= Z1), (zk, zb)


@pytest.mark.parametrize("name, triad", [
    # quantum 2 mg with 0.1 mg noise: every pose mean off by up to 1 mg, deterministically
    ("quantised", ui.Triad(noise=1e-4, lsb=2e-3)),
    # a temperature step: the bias jumps by 1 mg on each axis a third into the run
    pytest.param("bias_step", ui.Triad(step_g=(1e-3, -1e-3, 1e-3), step_t=70.0),
                 marks=pytest.mark.slow),
    # 10 mg of vibration at 100.3 Hz sampled at 100 Hz: aliased to a 0.3 Hz wander
    pytest.param("vibration", ui.Triad(vib_g=0.01, vib_hz=100.3), marks=pytest.mark.slow),
])
def test_unlisted_effects_are_covered_or_flagged(tmp_path, name, triad):
    """Effects the docs do not list: each parameter within 3.5 u, or the result flagged.
    Seen: quantised |z| <= 2.5 (u widened, unexplained structure warned); bias step |z| <= 1.2
    (u 0.4 mg, no warning); vibration |z| <= 1.2 (u widened, warned)."""
    rc, js, err = calibrate(triad, 0, tmp_path)
    assert cal_problems(rc, js, err, triad) == []
    zk, zb, _ = cal_z(triad, js)
    # a flagged result still must not be far off: within 3.5 u once widened
    assert np.all(np.abs(zk) <= Z1) and np.all(np.abs(zb) <= Z1), (zk, zb)


@pytest.mark.slow
def test_quantisation_dominated_narrow_groove_over_seeds(lens, tmp_path):
    """A narrow (3 px), faint (8 %) groove at 89.8-89.9°, little blur (0.4 px), 8-bit with
    0.15 DN of noise: the pixel quantisation, not the noise, dominates and is correlated along
    a mark so close to the pixel grid. Over 16 seeds: RMS z <= 1.57 (the RMS of 16 unit
    normals exceeds it with p = 1e-3) and every |z| <= 4.0 (the
    Bonferroni bound for 16 at 1e-3), or the mark not ok. Seen: RMS z 1.3, largest +3.58
    (seed 501: +17.1″ ± 4.8″, exit 0, ok, no warning) - u is a little short here, not
    several times."""
    k, d = lens
    cam = exact_camera(k, d, tmp_path)
    zs, bad = [], []
    for s in range(16):
        a = np.deg2rad(89.8) + 0.001 * s
        sc = ui.Scene([ui.mark_at(k, a, 320, 240, length_px=350, contrast=0.08, width_px=3.0)],
                      k, d, seed=500 + s, full_well=1e6, read_e=5, blur_px=0.4)
        rc, js, err = measure(sc, tmp_path, f"q{s}", "--camera", cam)
        errs = mark_errors(js, [a])
        bad += [f"seed {500 + s}: {e:+.1f}″ ± {u:.1f}″" for e, u, ok in errs
                if abs(e) > 4.0 * u and js["ok"]]
        bad += [] if len(errs) == 1 else [f"seed {500 + s}: {len(errs)} marks"]
        zs += [e / u for e, u, ok in errs]
    assert bad == []
    assert np.sqrt(np.mean(np.square(zs))) <= 1.57, np.round(zs, 2)


# ---------------------------------------------------------------- a whole session


def effect_session(folder: Path, seed: int, kind: str, value) -> tuple[int, dict, dict]:
    """``align synth session`` (the tool's own example, with its truth), then my sensor's
    effect put into both of its accelerometer files (tumble.csv, platform.csv), then
    ``align run``. kind "asym": u' = u + eps_i |u_i| (a scale factor (1 + eps) for one sign of
    the input, (1 - eps) for the other; the output offset is 1e-3 of full scale, so |u - o|
    and |u| differ negligibly); "k3": u' = u + K3 u^3 / k^2 (k from truth.json); "creep":
    each pose's samples carry value x (previous pose's mean - this pose's) e^(-t / 0.5 s)."""
    r = align("synth", "session", str(folder), "--seed", str(seed), "-q")
    assert r.returncode == 0, r.stderr
    truth = json.loads((folder / "truth.json").read_text())
    k = np.array(truth["scale_factors_v_per_g"])
    for name in ("tumble.csv", "platform.csv"):
        lines = (folder / name).read_text().splitlines()
        rows = [line.split(",") for line in lines[1:]]
        u = np.array([[float(x) for x in f[1:4]] for f in rows])
        if kind == "asym":
            u = u + np.array(value) * np.abs(u)
        elif kind == "k3":
            u = u + value * u ** 3 / k ** 2
        elif kind == "creep":
            t = np.array([float(f[4]) for f in rows])
            poses = [f[0] for f in rows]
            labels = list(dict.fromkeys(poses))
            sel = {lab: np.array([q == lab for q in poses]) for lab in labels}
            means = {lab: u[sel[lab]].mean(axis=0) for lab in labels}
            v = u.copy()
            for prev, lab in zip(labels[:-1], labels[1:], strict=True):
                m = sel[lab]
                decay = np.exp(-(t[m] - t[m].min()) / 0.5)
                v[m] += value * np.outer(decay, means[prev] - means[lab])
            u = v
        out = [lines[0]] + [",".join([f[0], *(f"{x:.9e}" for x in u[i]), *f[4:]])
                            for i, f in enumerate(rows)]
        (folder / name).write_text("\n".join(out) + "\n")
    res = folder / "res.json"
    r = align("run", str(folder), "--json", str(res), "-q", "--force")
    return r.returncode, json.loads(res.read_text()), truth


@pytest.mark.slow
@pytest.mark.parametrize("seed, kind, value", [
    (3, "asym", (0.0, 0.0, 0.0)), (3, "asym", (3e-4, -3e-4, 3e-4)),
    (5, "asym", (1e-4, -1e-4, 1e-4)),
    (3, "k3", 1e-4), (5, "k3", 1e-4), (3, "creep", 2e-4), (5, "creep", 2e-4)])
def test_session_with_sensor_effects_is_flagged(tmp_path, seed, kind, value):
    """`align run` on the tool's synthetic session with my sensor's effects: E within 3.5 u
    or the run not ok. Seen: clean seed 3 ok, |z| <= 1.8; 300 ppm: E_yX -16.5″ ± 2.0″ (z -8.2)
    but exit 2, ok false (calibration NOT OK: nonlinearity_k2 and bias_drift cannot be told
    apart; the fusion's instruments disagree); 100 ppm (seed 5): E_yX z -4.3, exit 2, ok
    false. K3 100 ug/g^3: exit 2 (calibration not ok), |z| <= 2.0; creep 2e-4: seed 3 exit 2,
    seed 5 ok with u widened, |z| <= 2.5."""
    rc, js, truth = effect_session(tmp_path / "s", seed, kind, value)
    e = np.array(js["misalignment_rad"])
    u = np.array(js["misalignment_u_rad"])
    t = np.array(truth["misalignment_rad"])
    off = ~np.eye(3, dtype=bool)
    z = (e - t)[off] / u[off]
    assert np.all(np.abs(z) <= Z1) or (rc != 0 and not js["ok"]), (np.round(z, 2), rc)
    if kind == "asym" and not any(value):
        assert rc == 0 and js["ok"] and np.all(np.abs(z) <= Z1), (np.round(z, 2), rc)
