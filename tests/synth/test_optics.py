"""synth's camera (Brown-Conrady with tangential terms, principal-point offset, non-square
pixels) against OpenCV's projection: the truth side renders OpenCV's lens."""

from __future__ import annotations

import cv2
import numpy as np

from synth import CameraGeometry


def test_synth_lens_is_opencvs_and_inverts():
    rng = np.random.default_rng(8)
    for _ in range(5):
        f = rng.uniform(400, 1500)
        cam = CameraGeometry(focal_px=f, k1=rng.uniform(-0.3, 0.1), k2=rng.uniform(-0.05, 0.1),
                             p1=rng.uniform(-1e-3, 1e-3), p2=rng.uniform(-1e-3, 1e-3),
                             aspect=rng.uniform(0.995, 1.005),
                             pp_offset_px=tuple(rng.uniform(-20, 20, 2)))
        x, y = rng.uniform(-300, 300, (2, 100))
        sx, sy = cam.distort(x, y)
        K = np.array([[f, 0, cam.pp_offset_px[0]], [0, f * cam.aspect, cam.pp_offset_px[1]],
                      [0, 0, 1]])
        D = np.array([cam.k1, cam.k2, cam.p1, cam.p2, 0.0])
        obj = np.column_stack([x / f, y / f, np.ones_like(x)])
        img, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, D)
        assert np.max(np.abs(img.reshape(-1, 2) - np.column_stack([sx, sy]))) < 1e-9
        bx, by = cam.undistort(sx, sy)
        assert max(np.max(np.abs(bx - x)), np.max(np.abs(by - y))) < 1e-9
