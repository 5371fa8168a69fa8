"""The lens model at the half-diagonal (imaging.lens) against OpenCV's own projection."""

from __future__ import annotations

import cv2
import numpy as np

from imaging.lens import distort_points, opencv_to_lens, undistort_points


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
