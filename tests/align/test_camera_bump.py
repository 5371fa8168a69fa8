"""A camera bumped after its calibration (align/lens_bump.py, docs/camera.md): the principal
point moved, the lens otherwise as calibrated.

Marks are straight lines seen through the true (moved) camera, noise added, and undistorted by
the calibration's model (which the move left behind); the truth of each angle is the same
mark's noise-free angle through the unmoved camera. Tolerances from the noise: z = error / u.
"""

from __future__ import annotations

import math
import pathlib
import tempfile

import cv2
import numpy as np
import pytest

from align.camera_lens import camera_lens_cov
from align.lens import LensRanges, LineGeometry
from align.lens_bump import bonferroni, pp_move, stability_coupling
from align.lens_fallback import model_lever
from align.lens_terms import check_camera
from align.mark_stage import half_diagonal
from imaging import CameraModel, fit_line

SHAPE = (480, 640)  # rows, columns
F = 531.2
# user 15's lens: k1 -0.15 at the half-diagonal (OpenCV -0.265), k2 +0.02
DIST = np.array([-0.2654659, 0.06264191, 0.0, 0.0, 0.0])
SIGMA = 0.02  # px, a centre's noise
# marks: (x, y) of the middle from the image centre [px], direction [deg], length [px]
MARKS = [(-150, -100, 25.0, 170), (120, -80, 80.0, 130), (-50, 110, -40.0, 140),
         (170, 90, 10.0, 150), (-180, 40, 70.0, 120), (40, -150, -15.0, 160)]


def _camera(dx=0.0, dy=0.0):
    K = np.array([[F, 0, 319.5 + dx], [0, F, 239.5 + dy], [0, 0, 1.0]])
    cov = np.diag([0.1, 0.1, 0.1, 0.1, 3e-4, 1e-3, 2e-5, 2e-5, 1e-6]) ** 2
    return CameraModel.from_dict({
        "camera_matrix": K.tolist(), "dist_coeffs": DIST.tolist(), "image_size": [640, 480],
        "cov_params": ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"],
        "cov": cov.tolist()})


def _raw(true, x, y, deg, length, n=30):
    """A straight mark's pinhole points (about the calibrated camera's centre) through the
    ``true`` camera: raw pixels."""
    t = np.linspace(-length / 2, length / 2, n)
    a = math.radians(deg)
    pin = np.column_stack([x + t * math.cos(a), y - t * math.sin(a)])
    obj = np.column_stack([pin / F, np.ones(n)]).reshape(-1, 1, 3)
    raw, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), true.camera_matrix, DIST)
    return raw.reshape(-1, 2)


def _lines(model, true, rng, marks=MARKS):
    c = np.array([319.5, 239.5])
    out = []
    for m in marks:
        raw = _raw(true, *m) + rng.normal(0, SIGMA, (30, 2))
        q, s = model.undistort_centred(raw - c, np.full(30, SIGMA), SHAPE)
        out.append(LineGeometry(q, s, None))
    return out


def _move(lines, model, stability):
    cov = camera_lens_cov(model, SHAPE)
    _, _, designs = check_camera(lines, np.zeros(7), cov, half_diagonal(SHAPE), LensRanges())
    return pp_move(model_lever(designs, lines, model, SHAPE), cov, stability)


def test_a_bump_the_bows_show_is_found_where_it_is():
    """A 12 px move under six marks: found (p far below alpha/2), the shift within 3 u."""
    model, true = _camera(), _camera(9.0, -8.0)
    for seed in range(3):
        m = _move(_lines(model, true, np.random.default_rng(seed)), model, 0.5)
        assert m.p < 5e-4, m
        z = (np.array(m.shift_px) - [9.0, -8.0]) / np.array(m.u_px)
        assert np.all(np.abs(z) < 3), (m, z)


def test_no_bump_no_false_alarm_and_the_statistic_is_chi2():
    """The unmoved camera: the move's p is uniform (its mean 1/2, sd of the mean 0.04 over
    50 seeds), and none below alpha = 1e-3 (expected 0.05)."""
    model = _camera()
    ps = [_move(_lines(model, model, np.random.default_rng(100 + s)), model, 0.5).p
          for s in range(50)]
    assert abs(np.mean(ps) - 0.5) < 4 * math.sqrt(1 / 12 / 50), np.mean(ps)
    assert min(ps) > 1e-3, min(ps)


def test_stability_term_covers_a_move_within_it():
    """Moves drawn uniform within +- 0.5 px: no bow shows them (p above alpha), and each
    angle's error is covered by its noise u with the declared stability's term (z rms ~1,
    within the chi2 spread of 24 angles); without the term they are not (rms z 1.7)."""
    model = _camera()
    rng = np.random.default_rng(7)
    z_with, z_without = [], []
    for _ in range(4):
        true = _camera(*rng.uniform(-0.5, 0.5, 2))
        lines = _lines(model, true, rng)
        for ln, m in zip(lines, MARKS, strict=True):
            truth = fit_line(model.undistort_centred(_raw(model, *m) - [319.5, 239.5],
                                                     np.full(30, SIGMA), SHAPE)[0],
                             np.full(30, SIGMA), reject_sigma=None).angle_rad
            fit = fit_line(ln.points, ln.sigma, reject_sigma=None)
            e = (fit.angle_rad - truth + np.pi / 2) % np.pi - np.pi / 2
            u0 = math.sqrt(fit.cov[0, 0])
            term = math.hypot(*stability_coupling(model, ln, SHAPE, 0.5).values())
            z_with.append(e / math.hypot(u0, term))
            z_without.append(e / u0)
    rms = math.sqrt(np.mean(np.square(z_with)))
    print("rms z with the term", round(rms, 2))
    assert 0.5 < rms < 1.3, (rms, np.round(z_with, 2))
    assert max(np.abs(z_with)) < 3.5, np.round(z_with, 2)
    # without it they are not: rms z of N(0, 1) over 24 angles is 1 +- 0.15
    assert math.sqrt(np.mean(np.square(z_without))) > 1.3, np.round(z_without, 2)


def test_bonferroni():
    assert bonferroni(0.01, 4e-4) == (0.02, 8e-4)
    assert bonferroni(0.7, 0.6) == (1.0, 1.0)


def _frames(kind, n, lo, hi, extra=()):
    """User 15's frame (tests/imaging/test_independent_user15.py) through its exact model, the
    camera moved lo..hi px in random directions: (exit 0, named, ok beyond 3 u, u's, z's)."""
    from tests.imaging import user15_inputs as gen
    from tests.imaging.test_independent_user15 import FRAME, LENS, _errors, _exact_model, _marks

    size = (640, 480)
    K, d = gen.lens_cv(size, **LENS)
    with tempfile.TemporaryDirectory() as tmp:
        cam = _exact_model(pathlib.Path(tmp), size, K, d)
        rng = np.random.default_rng(15)
        exit0 = named = bad = 0
        us, zs = [], []
        for seed in range(100, 100 + n):
            mag, ang = rng.uniform(lo, hi), rng.uniform(0, 2 * math.pi)
            K2 = K.copy()
            K2[0, 2] += mag * math.cos(ang)
            K2[1, 2] += mag * math.sin(ang)
            img, truths = gen.render_marks(size, K2, d, FRAME, seed=seed)
            rc, doc, err = _marks([gen.write_png(f"{tmp}/{seed}.png", img)], "--camera", cam,
                                  *extra)
            exit0 += rc == 0
            named += "principal point differs" in err or "lens differs" in err
            for e, u, ok in _errors(doc, truths):
                bad += ok and abs(e) > 3 * u
                us.append(u)
                zs.append(e / u)
    print(f"{kind} {lo}-{hi} px, {n} frames: exit 0 in {exit0}, named {named}, "
          f"ok beyond 3 u {bad}, median u {np.median(us):.0f}″, rms z "
          f"{math.sqrt(np.mean(np.square(zs))):.2f}")
    return exit0, named, bad, us, zs


@pytest.mark.slow
def test_unbumped_frames_untouched():
    """User 15's frame unbumped: no false alarm (alpha 1e-3 over 8 frames: expected 0.008),
    all exit 0, every angle within 3.5 u (with the default stability's term)."""
    exit0, named, bad, us, zs = _frames("unbumped", 8, 0, 0)
    assert named == 0 and exit0 == 8 and bad == 0
    assert max(np.abs(zs)) < 3.5, np.round(zs, 2)


@pytest.mark.slow
def test_bumped_frames_named():
    """User 15's frame: a move the bows show at > 99 % (18-25 px) is named, none ok beyond
    3 u."""
    _, named, bad, _, _ = _frames("bumped", 6, 18, 25)
    assert named == 6 and bad == 0
