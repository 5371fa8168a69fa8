"""Independent user 9: the camera stage with scribe marks rendered from physics, through lenses
I calibrate (``cv2.calibrateCamera`` on the real chessboard photographs) or vary myself.

The inputs come from ``tests/align/user9_inputs.py`` (my own groove profiles -- a V with a
flat, a U, a double line -- rendered at 8 x 8 samples per pixel, blurred there by the optics,
area-averaged, photon + read noise, quantised) and import nothing from the project. The CLI
runs in process through ``align.cli.main(argv)``. Right behaviour passes; each defect is
written as the tool should behave and marked ``xfail(strict=True)`` with the figures I saw.

Truth: a mark's angle is its direction in the ideal (normalised, square-pixel) plane, from +x
towards -y, in (-90, 90] degrees (docs/commands/marks.md).

Tolerances. A single Gaussian estimate lies beyond 4 u with probability 6e-5; a test over a
handful of marks allows |z| <= 4 each (the brief's "no |z| > 4"), so a correct tool fails it
with p < 1e-3 for up to 16 marks. Where a result may be *flagged* instead (exit status 2,
``ok`` false, ``lens_limited``), a flagged result passes: only a confident wrong answer
fails.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from align.cli import main as align_main  # the CLI's entry point: argv -> exit status
from tests.align import user9_inputs as ui

Z_MAX = 4.0  # per mark; p = 6e-5 for a Gaussian z (see the module docstring)


def align(*args: str) -> tuple[int, str, str]:
    """``align ARGS`` in process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = align_main([str(a) for a in args])
        except SystemExit as e:  # argparse's own refusals
            rc = e.code if isinstance(e.code, int) else 2
    return rc, out.getvalue(), err.getvalue()


def marks(paths, *extra) -> tuple[int, dict, str]:
    """``align marks PATHS --json -``: (exit status, the JSON, stderr)."""
    rc, out, err = align("marks", *paths, "--json", "-", *extra)
    i = out.find("{")
    assert i >= 0, f"no JSON on stdout (exit {rc}): {err[-400:]}"
    return rc, json.loads(out[i:]), err


def matched(scene: ui.Scene, found: list[dict]) -> list[dict | None]:
    """For each of my grooves, the reported mark whose line passes nearest its middle on the
    sensor and whose angle is nearest its own (None when nothing is near: 40 px, 1 deg; the
    reported offset is the undistorted line's, so a distorted middle may be tens of px off)."""
    lens = scene.lens
    w, h = lens.size
    res = []
    for g in scene.grooves:
        m0, _ = ui.groove_geometry(lens, g)
        mid = ui.project(lens, np.array([m0[0]]), np.array([m0[1]]))[0]
        best, score = None, np.inf
        for m in found:
            if not m.get("found"):
                continue
            a = np.deg2rad(m["angle_deg"])
            dist = abs((mid - [(w - 1) / 2, (h - 1) / 2]) @ [np.sin(a), np.cos(a)]
                       - m["offset_px"])
            da = abs(ui.angle_error_arcsec(m["angle_deg"], g.angle_deg)) / 3600
            if dist < 40 and da < 1 and dist + 10 * da < score:
                best, score = m, dist + 10 * da
        res.append(best)
    return res


def confident_wrong(scene: ui.Scene, rc: int, doc: dict) -> list[str]:
    """Each of my grooves reported ok with its angle beyond Z_MAX u of the truth, or not
    reported at all while the document says all is well."""
    bad = []
    for g, m in zip(scene.grooves, matched(scene, doc["marks"]), strict=False):
        if m is None:
            if rc == 0 and doc["ok"]:
                bad.append(f"{g.angle_deg:+.3f} deg mark at {g.centre_px} missing, yet ok")
            continue
        flagged = rc != 0 or not doc["ok"] or m.get("lens_limited")
        z = ui.angle_error_arcsec(m["angle_deg"], g.angle_deg) / m["angle_u_arcsec"]
        if not flagged and abs(z) > Z_MAX:
            bad.append(f"{g.angle_deg:+.3f} deg at {g.centre_px}: read {m['angle_deg']:+.5f}"
                       f" +- {m['angle_u_arcsec']:.2f}\" (z {z:+.2f}), ok")
    return bad


def z_scores(scene: ui.Scene, doc: dict) -> list[float]:
    out = []
    for g, m in zip(scene.grooves, matched(scene, doc["marks"]), strict=False):
        assert m is not None, f"{g} not found: {doc['warnings']}"
        out.append(ui.angle_error_arcsec(m["angle_deg"], g.angle_deg) / m["angle_u_arcsec"])
    return out


@pytest.fixture(scope="module")
def chess():
    if not ui.CHESS.is_dir():
        pytest.skip(f"real data folder {ui.CHESS} is absent (it lives in ../shared/data/real)")
    lens = ui.chessboard_calibration()[0]
    ui.ideal_map(lens)  # the lens's map, once per module (~1 s)
    return lens


def shoot(scene: ui.Scene, seed: int, folder: Path, name: str = "mark", ext: str = ".png",
          jpeg: int | None = None) -> Path:
    return ui.write_image(ui.render(scene, seed), folder / f"{name}{ext}", jpeg)


# ------------------------------------------------------- through my calibrated camera model


# where marks are: centre, off-centre, near a corner, along the frame's top edge, full frame
PLACES = [((320, 240), 0.0, 400), ((100, 80), 30.0, 150), ((560, 420), -20.0, 120),
          ((600, 240), 85.0, 300), ((320, 240), 37.0, 560), ((320, 240), 5.0, 100)]


def exact_model_trial(lens, folder, profile, places, seeds):
    cam = ui.camera_json(lens, folder / "cam.json")
    bad, zs, flagged = [], [], 0
    for seed in seeds:
        for i, (c, a, L) in enumerate(places):
            scene = ui.Scene((ui.Groove(c, a, L, profile=profile),), lens)
            rc, doc, _ = marks([shoot(scene, 10 * seed + i, folder), "--force", "--camera", cam])
            bad += confident_wrong(scene, rc, doc)
            if rc == 0:
                zs += z_scores(scene, doc)
            else:
                flagged += 1
    return bad, zs, flagged


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
@pytest.mark.parametrize("profile,places", [
    # the V with a flat over all six places and seeds is the slow sweep below
    pytest.param("vflat", PLACES[:3], marks=pytest.mark.slow), ("u", PLACES[3:]),
    pytest.param("double", PLACES[::2], marks=pytest.mark.slow)])
def test_marks_through_my_exact_camera_model_are_within_u(chess, tmp_path, profile, places):
    """Marks (100-560 px, centre to corner) through the real lens, my calibration given as
    the camera model (exact: the renderer uses it): each within 4 u, or flagged."""
    bad, zs, flagged = exact_model_trial(chess, tmp_path, profile, places, [1])
    assert not bad, bad
    assert len(zs) >= 2, f"only {len(zs)} of 3 marks measured without a flag"


@pytest.mark.slow
@pytest.mark.parametrize("profile", ["vflat", "u", "double"])
def test_marks_through_my_exact_camera_model_over_seeds(chess, tmp_path, profile):
    """The six places x 3 seeds: none beyond 4 u unflagged; RMS z of the unflagged ones below
    1.5 (chi2_n / n > 2.25 has p < 1e-3 for n >= 12)."""
    bad, zs, flagged = exact_model_trial(chess, tmp_path, profile, PLACES, [2, 3, 4])
    assert not bad, bad
    assert len(zs) >= 12, f"only {len(zs)} of 18 marks unflagged"
    assert np.sqrt(np.mean(np.square(zs))) < 1.5, np.round(zs, 2)


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
def test_several_marks_in_one_frame_through_my_camera_model(chess, tmp_path):
    """Three marks in one frame (centre, upper left, lower right) through the exact model:
    all found and within 4 u."""
    cam = ui.camera_json(chess, tmp_path / "cam.json")
    scene = ui.Scene((ui.Groove((320, 240), -12.0, 300), ui.Groove((130, 110), 75.0, 180),
                      ui.Groove((500, 380), 40.0, 200, profile="u")), chess)
    rc, doc, _ = marks([shoot(scene, 3, tmp_path), "--camera", cam])
    assert rc == 0 and doc["ok"], doc["warnings"]
    zs = z_scores(scene, doc)
    assert max(abs(z) for z in zs) < Z_MAX, zs


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
@pytest.mark.parametrize("dist", [
    (0.35, -0.1, 0.0008, -0.0006, 0.02, 0.65, -0.05, 0.03),  # OpenCV's rational model
    pytest.param((-0.25, 0.07, 0.0015, -0.0009), marks=pytest.mark.slow),  # four coefficients
], ids=["rational8", "four"])
def test_camera_models_with_8_or_4_coefficients(chess, tmp_path, dist):
    """The docs allow dist_coeffs of 4, 5, 8, 12 or 14 values: a lens of 8 (rational) or 4
    coefficients, rendered through exactly that model and given as the camera: within 4 u."""
    lens = ui.Lens(chess.K, dist)
    cam = ui.camera_json(lens, tmp_path / "cam.json")
    bad = []
    for i, (c, a, L) in enumerate([((100, 80), 30.0, 200), ((560, 400), -60.0, 200),
                                   ((320, 30), 3.0, 450)]):
        scene = ui.Scene((ui.Groove(c, a, L),), lens)
        rc, doc, _ = marks([shoot(scene, 20 + i, tmp_path), "--force", "--camera", cam])
        assert rc == 0, doc["warnings"]
        bad += [z for z in z_scores(scene, doc) if abs(z) > Z_MAX]
    assert not bad, bad


# ------------------------------------------------------------- a lens nobody declared


def lens_trial(seed: int, folder: Path) -> tuple[list[str], list[str], list[float]]:
    """One frame of 1-3 marks through a lens drawn from the brief's ranges, no model given.
    Returns (confident wrong answers, wrong-sign k1 applied, z of the unflagged marks)."""
    rng = np.random.default_rng(100 + seed)
    lens = ui.varied_lens(rng)
    grooves = tuple(
        ui.Groove((float(rng.uniform(80, 560)), float(rng.uniform(60, 420))),
                  float(rng.uniform(-90, 90)), float(rng.uniform(120, 380)),
                  profile=str(rng.choice(["vflat", "u"])))
        for _ in range(int(rng.integers(1, 4))))
    scene = ui.Scene(grooves, lens, bits=int(rng.choice([8, 12])))
    ext = ".png" if scene.bits == 8 else ".tif"
    rc, doc, _ = marks([shoot(scene, seed, folder, ext=ext), "--force"])
    k1_true = ui.half_diagonal_k1(lens)
    wrong_sign = []
    for m in doc["marks"]:
        k1 = (m.get("lens") or {}).get("parameters", {}).get("k1", {})
        if k1.get("applied") and np.sign(k1["value"]) != np.sign(k1_true):
            wrong_sign.append(f"seed {seed}: k1 {k1['value']:+.4f} applied, truth {k1_true:+.4f}")
    zs = []
    if rc == 0 and doc["ok"]:
        zs = z_scores(scene, doc)
    return confident_wrong(scene, rc, doc), wrong_sign, zs


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
def test_undeclared_lens_never_a_confident_wrong_answer(tmp_path):
    """A frame of three marks through a lens from k1 in [-0.3, 0.1] (OpenCV's units, f 540
    px), p up to 1e-3, principal point up to 20 px off, aspect 0.995-1.005, no model: every
    mark within 4 u or flagged, and no k1 applied with the wrong sign."""
    bad, signs = [], []
    for seed in (9,):
        b, s, _ = lens_trial(seed, tmp_path)
        bad += b
        signs += s
    assert not bad, bad
    assert not signs, signs


@pytest.mark.slow
def test_undeclared_lens_over_seeds(tmp_path):
    """24 frames (~50 marks) of the trial above."""
    bad, signs, zs = [], [], []
    for seed in range(24):
        b, s, z = lens_trial(seed, tmp_path)
        bad += b
        signs += s
        zs += z
    assert not bad, bad
    assert not signs, signs
    if len(zs) >= 10:  # RMS z of n unflagged marks: chi2_n / n below 2.0 at p < 1e-3 for n >= 10
        assert np.sqrt(np.mean(np.square(zs))) < np.sqrt(2.0), zs


# ------------------------------------------------------------------------ near vertical


def test_a_near_vertical_mark_is_not_pinned_to_exactly_90_degrees(tmp_path):
    """A mark 2.2" past vertical (truth -89.9994 deg, i.e. 90.0006), distortion-free camera
    declared: the estimator is continuous, so no reading may be exactly 90.000000 deg (a
    Gaussian estimate of u 2" lands within 1e-9 deg of 90 with probability ~1e-8)."""
    lens = ui.Lens(((540.0, 0, 319.5), (0, 540.0, 239.5), (0, 0, 1)), (0, 0, 0, 0, 0))
    pinned = []
    for seed in range(3):
        scene = ui.Scene((ui.Groove((320, 240), -89.9994, 400),), lens, vignetting=0.0)
        rc, doc, _ = marks([shoot(scene, seed, tmp_path), "--force",
                            "--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0"])
        assert rc == 0, doc["warnings"]
        a = doc["marks"][0]["angle_deg"]
        if abs(abs(a) - 90.0) < 1e-9:
            pinned.append(seed)
    assert not pinned, f"seeds {pinned} read exactly 90.000000 deg"


# ------------------------------------------------------------------------------ sessions
#
# My session (tests/align/user9_inputs.py, write_session): E drawn within +-200", the triad's
# tumble (18 random attitudes x 60 samples, 100 ug noise, V), the mounted platform at 4 table
# angles and X/Y up and down, eight mark images from cameras A and B (each view reversed),
# one centred 380 px mark each. Checked: every angle of E within 4 u of my truth or the run
# flagged (exit 2, ok false); an undeclared 30" roll of camera A found within 4 u.


def run_session(folder: Path) -> tuple[int, dict, str]:
    rc, out, err = align("run", folder, "--json", "-", "--force")
    i = out.find("{")
    assert i >= 0, f"no JSON on stdout (exit {rc}): {err[-600:]}"
    return rc, json.loads(out[i:]), err


def session_z(doc: dict, triad: ui.Triad) -> np.ndarray:
    est = np.array(doc["misalignment_arcsec"], dtype=float)
    u = np.array(doc["misalignment_u_arcsec"], dtype=float)
    off = ~np.eye(3, dtype=bool)
    return (est[off] - triad.E[off] / ui.ARCSEC) / u[off]


def session_trial(tmp_path: Path, seed: int, **kw) -> tuple[int, dict, np.ndarray, ui.Triad]:
    rng = np.random.default_rng(seed)
    triad = ui.Triad(ui.random_E(rng))
    folder = ui.write_session(tmp_path / f"unit{seed}", triad, seed, **kw)
    rc, doc, _ = run_session(folder)
    return rc, doc, session_z(doc, triad), triad


def effect(doc: dict, name: str) -> dict | None:
    return next((e for e in doc["effects"] if e["name"] == name), None)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_session_finds_an_undeclared_30_arcsec_roll(tmp_path, seed):
    """Camera A rolled by +30" (every mark it shows turned +30" counter-clockwise), nobody
    told: the fusion finds the roll within 4 u and E is within 4 u of my truth, ok."""
    rc, doc, z, _ = session_trial(tmp_path, seed, rolls=(30.0, 0.0))
    assert rc == 0 and doc["ok"], doc["warnings"]
    assert np.max(np.abs(z)) < Z_MAX, np.round(z, 2)
    roll = effect(doc, "camera_roll[A]")
    assert roll is not None, [e["name"] for e in doc["effects"]]
    zr = (roll["estimate"] / ui.ARCSEC - 30.0) / (roll["u"] / ui.ARCSEC)
    assert abs(zr) < Z_MAX, (roll["estimate"] / ui.ARCSEC, roll["u"] / ui.ARCSEC)


@pytest.mark.slow
def test_session_with_an_undeclared_lens_on_camera_b(tmp_path, chess):
    """Camera B photographs through the real chessboard lens (my calibration), its
    [cameras.B] table empty (the lens's default ranges): E within 4 u of my truth, or the run
    flagged (exit 2, ok false) -- never a confident wrong E."""
    rc, doc, z, _ = session_trial(tmp_path, 2, rolls=(30.0, 0.0), lenses={"B": chess},
                                  declare={"B": []})
    flagged = rc != 0 or not doc["ok"]
    assert flagged or np.max(np.abs(z)) < Z_MAX, np.round(z, 2)
    assert np.max(np.abs(z)) < Z_MAX, ("even flagged, E's u should cover it", np.round(z, 2))


def tilted_session(tmp_path: Path) -> tuple[int, dict, np.ndarray]:
    # the table axis leans 25" about the lab's X and -15" about its Y: in the table frame the
    # up vector has components (-15", -25") -- what the platform reads at table angle 0
    rc, doc, z, _ = session_trial(tmp_path, 2, rolls=(30.0, 0.0), tilt_arcsec=(25.0, -15.0))
    return rc, doc, z


@pytest.mark.slow
def test_session_with_the_platform_out_of_level(tmp_path):
    """The table axis tilted (25", -15") and camera A rolled 30", neither declared: both
    found, E within 4 u; the tilt's components within 4 u of (-15", -25") (up in the table
    frame; declaring the values found makes the loop find nothing more: checked by hand)."""
    rc, doc, z = tilted_session(tmp_path)
    assert rc == 0 and doc["ok"], doc["warnings"]
    assert np.max(np.abs(z)) < Z_MAX, np.round(z, 2)
    tilt = effect(doc, "platform_tilt")
    assert tilt is not None, [e["name"] for e in doc["effects"]]
    comp = {c["axis"]: (c["estimate"] / ui.ARCSEC, c["u"] / ui.ARCSEC)
            for c in tilt["components"]}
    for axis, truth in (("x", -15.0), ("y", -25.0)):
        est, u = comp[axis]
        assert abs(est - truth) < Z_MAX * u, (axis, est, u)


@pytest.mark.slow
def test_session_tilt_warning_names_both_components(tmp_path):
    rc, doc, _ = tilted_session(tmp_path)
    tilt = effect(doc, "platform_tilt")
    comp = {c["axis"]: c["estimate"] / ui.ARCSEC for c in tilt["components"]}
    msg = next(w for w in doc["warnings"] if "tilt of the table axis" in w)
    for axis in ("x", "y"):
        assert f"{comp[axis]:+.1f}" in msg or f"{comp[axis]:.1f}" in msg, (axis, comp, msg)


# ------------------------------------------------------------------ inputs a user may bring


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
@pytest.mark.parametrize("fmt", ["jpeg75", pytest.param("png12in16", marks=pytest.mark.slow),
                                 "tif16"])
def test_image_formats_through_my_camera_model(chess, tmp_path, fmt):
    """The same off-centre 300 px mark as a JPEG (quality 75), 12-bit data in a 16-bit PNG
    and a 16-bit TIFF, through the exact model: within 4 u (two seeds)."""
    cam = ui.camera_json(chess, tmp_path / "cam.json")
    g = ui.Groove((250, 300), 15.0, 300)
    bits, ext, q = {"jpeg75": (8, ".jpg", 75), "png12in16": (12, ".png", None),
                    "tif16": (16, ".tif", None)}[fmt]
    zs = []
    for seed in (1, 2):
        scene = ui.Scene((g,), chess, bits=bits, full_well_e=20000.0 if bits == 8 else 60000.0)
        rc, doc, _ = marks([shoot(scene, seed, tmp_path, ext=ext, jpeg=q), "--force",
                            "--camera", cam])
        assert rc == 0 and doc["ok"], doc["warnings"]
        zs += z_scores(scene, doc)
    assert max(abs(z) for z in zs) < Z_MAX, zs


@pytest.mark.slow  # what held up: the default run keeps the defects found (lead, stop 28)
def test_odd_frame_size_and_off_centre_principal_point(tmp_path):
    """A 641 x 479 frame, principal point (+7.3, -5.1) px off the centre, k1 -0.22, given as
    the model: within 4 u."""
    w, h = 641, 479
    lens = ui.Lens(((500.0, 0, (w - 1) / 2 + 7.3), (0, 500.0, (h - 1) / 2 - 5.1), (0, 0, 1.0)),
                   (-0.22, 0.06, 0.0005, 0.0004, 0.0), (w, h))
    cam = ui.camera_json(lens, tmp_path / "cam.json")
    scene = ui.Scene((ui.Groove((192.3, 143.7), 20.0, 240), ui.Groove((450, 340), -70.0, 200)),
                     lens)
    rc, doc, _ = marks([shoot(scene, 6, tmp_path), "--camera", cam])
    assert rc == 0 and doc["ok"], doc["warnings"]
    zs = z_scores(scene, doc)
    assert max(abs(z) for z in zs) < Z_MAX, zs


def test_exif_turned_jpeg_with_a_sensor_camera_model_is_refused_not_misread(chess, tmp_path):
    """A JPEG of the sensor's pixels with EXIF Orientation 6 (shown turned 90 deg clockwise):
    the model (640 x 480) is the sensor's, the displayed image 480 x 640. Applying the model to
    the turned pixels would be wrong; the tool refuses, naming the size (exit 2). Without a
    model the displayed angle (20 - 90 = -70 deg) is read within 4 u."""
    cam = ui.camera_json(chess, tmp_path / "cam.json")
    img = ui.render(ui.Scene((ui.Groove((480, 120), 20.0, 250),), chess), 3)
    p = ui.jpeg_with_orientation(img, tmp_path / "turned.jpg", 6)
    rc, doc, _ = marks([p, "--camera", cam])
    assert rc == 2 and not doc["ok"]
    assert "640x480" in doc["warnings"][0], doc["warnings"]
    rc, doc, _ = marks([p, "--force"])
    m = doc["marks"][0]
    assert m["found"], doc["warnings"]
    z = ui.angle_error_arcsec(m["angle_deg"], -70.0) / m["angle_u_arcsec"]
    assert abs(z) < Z_MAX, (m["angle_deg"], m["angle_u_arcsec"])


def ruled_scale(lens: ui.Lens, angle_deg: float = 3.0, numerals: bool = True) -> ui.Scene:
    """A ruled scale: 21 lines 14 px apart along a direction ``angle_deg``, the lines across
    it, 110 px long and every fifth 150 px, printed numerals above the long ones."""
    a = np.deg2rad(angle_deg)
    along = np.array([np.cos(a), -np.sin(a)])
    up = -np.array([np.sin(a), np.cos(a)])
    c0 = np.array([320.0, 260.0])
    line_angle = angle_deg + 90 if angle_deg + 90 <= 90 else angle_deg - 90
    grooves = []
    for i in range(-10, 11):
        L = 150.0 if i % 5 == 0 else 110.0
        c = c0 + i * 14.0 * along + (L - 110) / 2 * up
        grooves.append(ui.Groove((float(c[0]), float(c[1])), line_angle, L, flat=1.0,
                                 wall=1.0))
    extra = (("numerals", (float(c0[0] - 144), 160.0, 70.0, 5, 14.0)),) if numerals else ()
    return ui.Scene(tuple(grooves), lens, extra=extra)


@pytest.mark.slow  # ~8 s
def test_ruled_scale_with_numerals_through_my_camera_model(chess, tmp_path):
    """A ruled scale with numerals through the real lens, the exact model given: the family's
    mean angle within 4 u of the truth, and no member beyond 4 u unflagged."""
    cam = ui.camera_json(chess, tmp_path / "cam.json")
    scene = ruled_scale(chess)
    rc, doc, _ = marks([shoot(scene, 1, tmp_path), "--camera", cam, "--max-marks", "30"])
    assert not confident_wrong(scene, rc, doc)
    fam = next((m["family"] for m in doc["marks"] if m.get("family")), None)
    assert fam is not None, doc["warnings"]
    truth = scene.grooves[0].angle_deg
    z = ui.angle_error_arcsec(fam["angle_deg"], truth) / fam["angle_u_arcsec"]
    assert abs(z) < Z_MAX, (fam["angle_deg"], fam["angle_u_arcsec"])


# ------------------------------------------------------------ align camera on my chessboards


@pytest.mark.slow
def test_align_camera_recovers_my_lens_from_rendered_chessboards(tmp_path):
    """Ten chessboard photographs rendered through a lens I chose (k1 -0.25, k2 +0.075,
    p1 +8.9e-4, principal point (+15.0, -13.2) px off, aspect 1.0011): every intrinsic
    `align camera` reports within 4 u of my truth."""
    rng = np.random.default_rng(4)
    truth = ui.varied_lens(rng, k1=-0.25)
    paths = []
    for i, (R, t) in enumerate(ui.board_views(rng, 10)):
        paths.append(ui.write_image(ui.render_board(truth, R, t, i), tmp_path / f"b{i}.png"))
    rc, out, err = align("camera", *paths, "--pattern", "9x6", "--json", "-")
    assert rc == 0, err[-400:]
    d = json.loads(out[out.find("{"):])
    k, dist, u = np.array(d["camera_matrix"]), d["dist_coeffs"], d["u"]
    tk, td = truth.k, truth.d
    got = {"fx": (k[0, 0], tk[0, 0]), "fy": (k[1, 1], tk[1, 1]), "cx": (k[0, 2], tk[0, 2]),
           "cy": (k[1, 2], tk[1, 2]), "k1": (dist[0], td[0]), "k2": (dist[1], td[1]),
           "p1": (dist[2], td[2]), "p2": (dist[3], td[3]), "k3": (dist[4], td[4])}
    z = {n: (e - t) / u[n] for n, (e, t) in got.items()}
    assert max(abs(v) for v in z.values()) < Z_MAX, {n: round(v, 2) for n, v in z.items()}


# ----------------------------------------------------- a camera model with the wrong sign


def flipped_model(lens: ui.Lens, folder: Path) -> str:
    """The real lens's model with k1 and k2 of the opposite sign (a model written by a tool
    that stores the inverse (undistortion) coefficients, or a sign slip): k1 +0.279."""
    d = list(lens.dist)
    d[0], d[1] = -d[0], -d[1]
    return ui.camera_json(ui.Lens(lens.K, tuple(d)), folder / "cam_flipped.json")


def test_three_marks_through_a_sign_flipped_model_are_flagged(chess, tmp_path):
    """Three off-centre marks through the real lens, the model's k1/k2 sign-flipped: the
    marks contradict it; every angle within 4 u or the result not ok."""
    cam = flipped_model(chess, tmp_path)
    scene = ui.Scene((ui.Groove((150, 120), 10.0, 250), ui.Groove((500, 360), 80.0, 220),
                      ui.Groove((480, 110), -35.0, 200)), chess)
    rc, doc, _ = marks([shoot(scene, 1, tmp_path), "--camera", cam])
    assert not confident_wrong(scene, rc, doc)


def test_one_mark_through_a_sign_flipped_model_is_not_a_confident_answer(chess, tmp_path):
    cam = flipped_model(chess, tmp_path)
    scene = ui.Scene((ui.Groove((150, 120), 10.0, 250),), chess)
    rc, doc, _ = marks([shoot(scene, 3, tmp_path), "--camera", cam])
    assert not confident_wrong(scene, rc, doc)


# ------------------------------------------------------------------ false JPEG diagnosis


def test_a_png_groove_on_a_block_middle_row_is_not_called_jpeg(tmp_path):
    lens = ui.Lens(((540.0, 0, 319.5), (0, 540.0, 239.5), (0, 0, 1)), (0, 0, 0, 0, 0))
    called = []
    for seed in range(2):
        scene = ui.Scene((ui.Groove((200, 100), 0.0, 250),), lens)
        rc, doc, _ = marks([shoot(scene, seed, tmp_path), "--force",
                            "--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0"])
        assert doc["marks"][0]["found"], doc["warnings"]
        called += [w for w in doc["warnings"] if "JPEG" in w]
    assert not called, called


@pytest.mark.slow
def test_session_with_my_camera_model_and_a_roll_on_that_camera(tmp_path, chess):
    """Camera B photographs through the real lens, ``[cameras.B] model = "camB.json"`` (my
    calibration, written to the camera schema) and B rolled +30" undeclared: the roll found
    within 4 u and E within 4 u, ok. (Seen by hand: z_Ar.png, a PNG, was diagnosed as 'JPEG
    compression ... quality ~8' and its u widened by 7.3" -- the false JPEG diagnosis above.)"""
    rng = np.random.default_rng(3)
    triad = ui.Triad(ui.random_E(rng))
    folder = tmp_path / "unit3"
    folder.mkdir()
    ui.camera_json(chess, folder / "camB.json")
    ui.write_session(folder, triad, 3, rolls=(0.0, 30.0), lenses={"B": chess},
                     declare={"B": ['model = "camB.json"']})
    rc, doc, _ = run_session(folder)
    assert rc == 0 and doc["ok"], doc["warnings"]
    z = session_z(doc, triad)
    assert np.max(np.abs(z)) < Z_MAX, np.round(z, 2)
    roll = effect(doc, "camera_roll[B]")
    assert roll is not None, [e["name"] for e in doc["effects"]]
    assert abs(roll["estimate"] / ui.ARCSEC - 30.0) < Z_MAX * roll["u"] / ui.ARCSEC


def test_a_min_length_beyond_the_image_is_named_as_the_flag(tmp_path):
    lens = ui.Lens(((540.0, 0, 319.5), (0, 540.0, 239.5), (0, 0, 1)), (0, 0, 0, 0, 0))
    p = shoot(ui.Scene((ui.Groove((320, 240), 20.0, 300),), lens), 1, tmp_path)
    rc, out, err = align("marks", p, "--min-length", "5000")
    assert rc == 2
    assert "min-length" in err, err[-300:]


def test_a_chessboard_photo_of_another_size_is_warned_in_the_camera_json(chess, tmp_path):
    big = tmp_path / "left01_big.png"
    g = cv2.imread(str(ui.CHESS / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(big), cv2.resize(g, (1280, 960)))
    photos = [ui.CHESS / f"left0{i}.jpg" for i in (2, 3, 4)] + [big]
    rc, out, err = align("camera", *photos, "--pattern", "9x6", "--json", "-")
    doc = json.loads(out[out.find("{"):])
    assert doc["views"] == 3
    assert any("left01_big.png" in w for w in doc.get("warnings", [])), sorted(doc)


@pytest.mark.slow
def test_a_wrongly_declared_roll_is_reported_as_the_total_or_against_the_declaration(tmp_path):
    rng = np.random.default_rng(4)
    triad = ui.Triad(ui.random_E(rng))
    declare = {"A": ["lens_k1 = 0.0", "lens_k2 = 0.0", "lens_p = 0.0", "lens_aspect = 0.0",
                     "lens_pp_px = 0.0", "roll_arcsec = -30.0"]}
    folder = ui.write_session(tmp_path / "unit4", triad, 4, rolls=(30.0, 0.0), declare=declare)
    rc, doc, _ = run_session(folder)
    assert np.max(np.abs(session_z(doc, triad))) < Z_MAX
    roll = effect(doc, "camera_roll[A]")
    total = -30.0 + roll["estimate"] / ui.ARCSEC
    msg = next(w for w in doc["warnings"] if "roll of camera A" in w)
    assert "-30" in msg or f"{total:+.1f}" in msg, msg
