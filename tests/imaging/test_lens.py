"""The lens model at the half-diagonal (imaging.lens) against OpenCV's own projection."""

from __future__ import annotations

import cv2
import numpy as np

from imaging.lens import distort_points, opencv_to_lens, undistort_points, undistortion_jacobian


def _opencv_project(ideal_px: np.ndarray, K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Ideal pixels (square, at fx, from the principal point) through OpenCV's model."""
    obj = np.column_stack([ideal_px / K[0, 0], np.ones(len(ideal_px))])
    img, _ = cv2.projectPoints(obj.astype(np.float64), np.zeros(3), np.zeros(3), K, D)
    return img.reshape(-1, 2)


def test_distortion_matches_opencv_and_inverts():
    rng = np.random.default_rng(3)
    w, h = 640, 480
    for _ in range(5):
        fx = rng.uniform(400, 1200)
        K = np.array([[fx, 0, 319.5 + rng.uniform(-20, 20)],
                      [0, fx * rng.uniform(0.995, 1.005), 239.5 + rng.uniform(-20, 20)],
                      [0, 0, 1]])
        D = np.array([rng.uniform(-0.3, 0.1), rng.uniform(-0.05, 0.1),
                      *rng.uniform(-1e-3, 1e-3, 2), 0.0])
        lam = opencv_to_lens(K, D, (w, h))
        q = rng.uniform(-300, 300, (200, 2)) * [1, 0.75]
        sensor = distort_points(q, lam, np.hypot(w - 1, h - 1) / 2)
        cv = _opencv_project(q, K, D) - [(w - 1) / 2, (h - 1) / 2]
        assert np.max(np.abs(sensor - cv)) < 1e-9
        back = undistort_points(sensor, lam, np.hypot(w - 1, h - 1) / 2)
        assert np.max(np.abs(back - q)) < 1e-9


def test_a_folding_lens_gives_no_points():
    q = np.array([[390.0, 0.0], [10.0, 0.0]])
    out = undistort_points(q, [-2.0, 0, 0, 0, 0, 0, 0], 399.5)
    assert np.isnan(out[0]).all() and np.all(np.isfinite(out[1]))


def test_undistortion_jacobian_matches_finite_differences():
    """The analytic Jacobian (implicit-function theorem) against central differences through
    the undistortion itself, over lenses across the plausible ranges (k1 +-0.3, k2 +-0.05, p
    +-1e-3, aspect +-0.005, principal point +-20 px). Step h = 1e-5 of each range: the
    differences' truncation error (~h^2, 4e-6 of a column at 1e-4, 4e-8 here) and rounding
    (Newton's 1e-14 / h, ~2e-8) stay below 1e-7 of a column's size, so 1e-6 is the
    tolerance; ``only`` zeroes the other columns."""
    rng = np.random.default_rng(11)
    scale = np.hypot(639, 479) / 2
    rng_vec = np.array([0.3, 0.05, 1e-3, 1e-3, 0.005, 20.0, 20.0])
    for _ in range(8):
        lam = rng.uniform(-1, 1, 7) * rng_vec
        # Within 0.8 of the half-diagonal: clear of where a strong barrel lens folds (there
        # the map is singular and differences are no reference).
        q = rng.uniform(-250, 250, (60, 2)) * [1, 0.75]
        base, jac = undistortion_jacobian(q, lam, scale)
        assert np.array_equal(base, undistort_points(q, lam, scale), equal_nan=True)
        ok = np.all(np.isfinite(base), axis=1)
        assert ok.all() and np.all(np.isfinite(jac))
        for j, h in enumerate(1e-5 * rng_vec):
            e = np.zeros(7)
            e[j] = h
            fd = (undistort_points(q, lam + e, scale)
                  - undistort_points(q, lam - e, scale)) / (2 * h)
            assert np.max(np.abs(jac[ok, :, j] - fd[ok])) < 1e-6 * np.max(np.abs(fd[ok]))
        _, part = undistortion_jacobian(q, lam, scale, (0, 1))
        assert np.array_equal(part[ok, :, :2], jac[ok, :, :2]) and not np.any(part[ok, :, 2:])
