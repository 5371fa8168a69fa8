"""Independent user 18: the camera side of an alignment station, against rendered truth.

A metrology engineer who has read only README, docs/, the schemas and --help. The images are
user18_inputs.py's: chessboards and scribe marks rendered by ray through a true OpenCV lens
(800x600, f 900 px, k1 -0.22, k2 0.08, p ~4e-4, principal point (+6, -4) px off centre),
PSF before the pixels, area integration, shot (12000 e- full well) + read (6 e-) noise.

The rule every test asserts: a result is either not ok (exit status 2, JSON ok false) or
its error is within 3 u. Defects are strict xfails whose reason holds the figures seen.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import user18_inputs as u18  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, PYTHONPATH=str(ROOT), PYTHONDONTWRITEBYTECODE="1")

# marks in the pinhole image [px from the principal point], 260 px long
MARKS = {
    "centre": u18.Mark(0.0, 0.0, 20.0),
    "upper_right": u18.Mark(150.0, -80.0, 70.0),
    "lower_right": u18.Mark(180.0, 150.0, 5.0),
}


def _align(*args):
    return subprocess.run([sys.executable, "-m", "align", *args], capture_output=True,
                          text=True, env=ENV, timeout=600)


def calibrate(folder: Path, n_views: int, seed: int, board=None, lens=None):
    """Render n_views boards, run `align camera`; (exit status, camera JSON, path)."""
    board = board or u18.Board()
    lens = lens or u18.Lens()
    folder.mkdir(parents=True, exist_ok=True)
    paths = u18.write_boards(str(folder), lens, n_views, seed, board)
    out = folder / "cam.json"
    r = _align("camera", *paths, "--pattern", f"{board.cols}x{board.rows}",
               "--square", str(board.square), "--json", str(out), "-q")
    assert out.exists(), r.stderr
    return r.returncode, json.loads(out.read_text()), out


def measure(img, path: Path, camera: Path | None):
    """`align marks --one` on one rendered image: (exit status, the document)."""
    import cv2

    cv2.imwrite(str(path), img)
    out = path.with_suffix(".json")
    args = ["marks", str(path), "--one", "--json", str(out), "-q"]
    if camera is not None:
        args += ["--camera", str(camera)]
    r = _align(*args)
    assert out.exists(), r.stderr
    return r.returncode, json.loads(out.read_text())


def judge(mark: u18.Mark, rc: int, doc: dict):
    """(ok, error ["], u ["]) of a one-mark document against the rendered truth."""
    m = doc["marks"][0]
    ok = bool(doc["ok"]) and rc == 0
    if not m.get("found") or m.get("angle_deg") is None:
        return False, None, None
    err = (m["angle_deg"] - u18.true_angle_deg(mark)) * 3600.0
    err = (err + 648000.0) % 1296000.0 - 648000.0
    u = m["angle_u_deg"] * 3600.0 if m.get("angle_u_deg") else None
    return ok, err, u


def assert_honest(rows):
    """Every ok mark within 3 u; the JSON ok agrees with the exit status."""
    bad = [r for r in rows if r[1] and (r[3] is None or abs(r[2]) > 3 * r[3])]
    assert not bad, f"ok beyond 3 u: {bad}"


# ---------------------------------------------------------------- default run

def test_user18_renderer_inverts_the_true_lens():
    """The renderer's rays: through OpenCV's forward model they land on their pixels."""
    import cv2

    lens = u18.Lens()
    X, Y = np.meshgrid(np.linspace(0, u18.W - 1, 9), np.linspace(0, u18.H - 1, 7))
    xn, yn = u18.rays(lens, X, Y)
    P, _ = cv2.projectPoints(np.stack([xn.ravel(), yn.ravel(), np.ones(xn.size)], 1),
                             np.zeros(3), np.zeros(3), lens.K(), np.array(lens.dist))
    assert np.abs(P.reshape(-1, 2) - np.stack([X.ravel(), Y.ravel()], 1)).max() < 1e-6


# ---------------------------------------------------------------- slow: camera + marks

@pytest.fixture(scope="module")
def camera12(tmp_path_factory):
    """12 clean views of a 9x6 board through the true lens, calibrated by `align camera`."""
    rc, cam, path = calibrate(tmp_path_factory.mktemp("u18cam"), 12, 0)
    return rc, cam, path


@pytest.mark.slow
def test_user18_calibration_within_its_u(camera12):
    """The calibration's own parameters against the true lens: each within 3 u, ok, exit 0.

    Seen (seed 0): fx 900.84 ± 0.98 (true 900), cx 405.17 ± 1.30 (405.5), cy 295.04 ± 0.84
    (295.5), k1 -0.2232 ± 0.0077 (-0.22), k2 0.098 ± 0.10 (0.08), p1 4.1e-4 ± 1.5e-4 (4e-4),
    p2 -3.3e-4 ± 2.0e-4 (-3e-4): all within 0.9 u.
    """
    rc, cam, _ = camera12
    assert rc == 0 and cam["ok"]
    lens = u18.Lens()
    K = np.array(cam["camera_matrix"])
    d = cam["dist_coeffs"]
    got = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2], "k1": d[0], "k2": d[1],
           "p1": d[2], "p2": d[3]}
    true = {"fx": lens.fx, "fy": lens.fy, "cx": lens.cx, "cy": lens.cy, "k1": lens.dist[0],
            "k2": lens.dist[1], "p1": lens.dist[2], "p2": lens.dist[3]}
    z = {k: (got[k] - true[k]) / cam["u"][k] for k in got}
    assert all(abs(v) <= 3 for v in z.values()), z


def _marks_through(camera_path, tmp, effect=None, strength=0.0, names=tuple(MARKS), seed=0):
    lens = u18.Lens()
    rows = []
    for name in names:
        mark = MARKS[name]
        kw = {}
        lens_m = lens
        if effect == "skew":
            kw["skew"] = strength
        elif effect == "motion_along":
            kw.update(motion=(strength, 0.0), nsub=max(3, int(2 * strength)))
        elif effect == "motion_across":
            kw.update(motion=(0.0, strength), nsub=max(3, int(2 * strength)))
        elif effect == "chroma":
            kw["chroma"] = strength
        elif effect == "decentre":
            lens_m = lens.moved(strength, 0.0)
        elif effect == "wear":
            mark = u18.Mark(mark.x0, mark.y0, mark.angle_deg, wear_frac=0.4, wear_side=strength)
        img = u18.render_mark(lens_m, mark, np.random.default_rng(seed), **kw)
        rc, doc = measure(img, Path(tmp) / f"{name}.png", camera_path)
        ok, err, u = judge(mark, rc, doc)
        rows.append((name, ok, err, u))
    return rows


@pytest.mark.slow
def test_user18_clean_marks_through_the_calibration(camera12, tmp_path):
    """Marks rendered through the true lens, measured with the calibrated model.

    Seen (seed 0/1): centre err -8.3/-2.8″ at u 12.3″; upper right -18.0/-13.5″ at 39.4″;
    lower right -10.1/-20.4″ at 51.8″: all ok, |z| <= 0.67. (A mark at (-200, +110) px is
    lens-limited at 65″ by the model's own u: not ok, err -10″.)
    """
    _, _, cam = camera12
    rows = _marks_through(cam, tmp_path)
    assert_honest(rows)
    ok = [r for r in rows if r[1]]
    assert len(ok) >= 2 and all(r[3] < 60 for r in ok), rows


# Effects the tool is not told about, from negligible to gross (marks of MARKS, seed 0,
# through the 12-view calibration). Figures in each xfail's reason; the table in the report.
def _xf(reason):
    return pytest.mark.xfail(strict=True, reason=reason)


SKEW_GROSS = ("rolling-shutter skew 2e-3 px/row (the scene's x shift per row, 1.2 px over the "
              "frame): upper_right (70°) ok, err +346.8″ at u 39.4″ (z 8.80); centre (20°) ok, "
              "+40.2″ at 12.2″ (z 3.30); no effect named, exit 0. A uniform skew keeps a line "
              "straight: one image cannot show it, and the docs name no such limit")

DECENTRE_8 = ("the lens's principal point moved 8 px in x after calibration (the default "
              "pp_stability_px 0.5, not declared): upper_right ok, err -160.1″ at u 40.3″ "
              "(z -3.97, a bent_mark named, still ok); lower_right ok, -182.7″ at 52.3″ "
              "(z -3.49); exit 0. At 2 px: z -1.32, -1.09")

MARK_EFFECTS = [
    ("skew", 2e-5), ("skew", 2e-4), pytest.param("skew", 2e-3, marks=_xf(SKEW_GROSS)),
    ("motion_along", 0.5), ("motion_along", 3.0), ("motion_along", 10.0),
    ("motion_across", 0.5), ("motion_across", 2.0), ("motion_across", 6.0),
    ("chroma", 2e-4), ("chroma", 1e-3), ("chroma", 4e-3),
    ("decentre", 0.3), ("decentre", 2.0), pytest.param("decentre", 8.0, marks=_xf(DECENTRE_8)),
    # wear 0.03 / 0.05 (centre: +56″ at 12.2″, +100″ at 30.8″ before imaging.asymmetry): now
    # groove_asymmetry carried; seeds 0-4, 3 marks: 14/15 and 15/15 not ok or within 3 u
    ("wear", 0.03), ("wear", 0.05), ("wear", 0.1), ("wear", 0.4), ("wear", 0.9),
]


@pytest.mark.slow
@pytest.mark.parametrize("effect,strength", MARK_EFFECTS)
def test_user18_mark_effect(camera12, tmp_path, effect, strength):
    """Not ok, or within 3 u, under an effect the tool is not told about.

    skew: px of x shift per sensor row; motion_*: px moved during the exposure along/across
    the mark; chroma: R/B magnification -/+ that about the principal point (a colour PNG);
    decentre: the lens's principal point moved by that [px] after calibration; wear: the
    paint gone from that fraction of the groove's +normal half over 40 % of its length.
    """
    rows = _marks_through(camera12[2], tmp_path, effect, strength)
    assert_honest(rows)


BOARD_EFFECTS = [
    ("scale_x", 1.005), ("scale_x", 1.02),
    ("bow_mm", 0.3), ("bow_mm", 1.0), ("bow_mm", 3.0),
    ("views", 3), ("views", 4),
]


@pytest.mark.slow
@pytest.mark.parametrize("effect,value", BOARD_EFFECTS)
def test_user18_board_effect(tmp_path, effect, value):
    """A board printed with an anisotropic scale error, bowed out of plane, or few views:
    the camera is not ok, or the marks measured through it are not ok or within 3 u."""
    board = u18.Board()
    n = 12
    if effect == "scale_x":
        board = u18.Board(scale_x=value)
    elif effect == "bow_mm":
        board = u18.Board(bow_mm=value)
    else:
        n = int(value)
    rc, cam, path = calibrate(tmp_path / "cam", n, 0, board)
    assert (rc == 0) == bool(cam.get("ok", True))
    if rc != 0:
        return
    rows = _marks_through(path, tmp_path)
    assert_honest(rows)
