"""Real photographs (../shared/data/real/opencv-chessboard): the closed loop on a real lens.

Straight rows/columns of chessboard corners are bowed by the lens; the loop's plumb-line
effect (k1 from the lines alone, principal point at the image centre) must straighten them
and agree with cv2.calibrateCamera's k1, which uses the board's known geometry instead.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from imaging import (
    chessboard_lines,
    find_chessboard,
    fit_line,
    plumb_line,
    read_image,
    undistort,
)
from tests.conftest import real_folder

PATTERN = (9, 6)


def _views(side: str):
    folder = real_folder("opencv-chessboard")
    out = {}
    for p in sorted(folder.glob(f"{side}0*.jpg")):
        img = read_image(p).astype(np.uint8)
        c = find_chessboard(img, PATTERN)
        assert c is not None, f"{p}: chessboard not found"
        out[p.name] = (img, c)
    return out


@pytest.mark.parametrize("side", ["left", "right"])
def test_plumb_line_k1_matches_calibrate_camera(side):
    views = _views(side)
    h, w = next(iter(views.values()))[0].shape
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    lines = [ln for _, c in views.values() for ln in chessboard_lines(c - centre, PATTERN)]
    R = float(np.hypot(w - 1, h - 1) / 2)
    pl = plumb_line(lines, R, n_coeffs=1)
    # The bow is real and the lens model removes most of it.
    assert pl.rms_before_px > 0.5
    assert pl.rms_after_px < 0.3 * pl.rms_before_px
    obj = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2)
    imgpts = [c.astype(np.float32).reshape(-1, 1, 2) for _, c in views.values()]
    flags = cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    _, K, D, _, _ = cv2.calibrateCamera([obj] * len(imgpts), imgpts, (w, h), None, None,
                                        flags=flags)
    k1_cv = pl.opencv(float(np.sqrt(K[0, 0] * K[1, 1])))[0]
    # Measured: left -0.241 vs -0.259, right -0.255 vs -0.247: two independent routes
    # (straightness alone vs the board's geometry) agree to < 10 %.
    assert k1_cv == pytest.approx(float(D.ravel()[0]), rel=0.10)
    # Angles of the lines change by up to a degree once the bow is removed.
    before = [fit_line(q, np.ones(len(q)), reject_sigma=None).angle_rad for q in lines]
    after = [fit_line(undistort(q, pl.k, R), np.ones(len(q)), reject_sigma=None).angle_rad
             for q in lines]
    assert np.max(np.abs(np.subtract(before, after))) > np.deg2rad(0.2)


def test_plumb_line_refuses_too_little():
    with pytest.raises(ValueError):
        plumb_line([np.zeros((5, 2))], 100.0)


@pytest.mark.xfail(strict=True, reason="measured: plumb-line k1 -0.2414 +- 0.0017 vs "
                   "calibrateCamera -0.2588 +- 0.0011 (left, 8.5 combined u), -0.2554 +- 0.0013 "
                   "vs -0.2471 +- 0.0015 (right, 4.1 u): the plumb line fixes the principal "
                   "point at the image centre, calibrateCamera fits it; both u are formal")
@pytest.mark.parametrize("side", ["left", "right"])
def test_plumb_line_k1_agrees_within_combined_uncertainty(side):
    """Issue 9 item 5: the joint distortion from straight lines agrees with the camera
    calibration's within their combined standard uncertainty (3 u)."""
    views = _views(side)
    h, w = next(iter(views.values()))[0].shape
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    lines = [ln for _, c in views.values() for ln in chessboard_lines(c - centre, PATTERN)]
    R = float(np.hypot(w - 1, h - 1) / 2)
    pl = plumb_line(lines, R, n_coeffs=1)
    obj = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2)
    imgpts = [c.astype(np.float32).reshape(-1, 1, 2) for _, c in views.values()]
    flags = cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    out = cv2.calibrateCameraExtended([obj] * len(imgpts), imgpts, (w, h), None, None,
                                      flags=flags)
    K, D, sd = out[1], out[2], out[5]
    f = float(np.sqrt(K[0, 0] * K[1, 1]))
    k1_pl, u_pl = pl.opencv(f)[0], pl.k_u[0] * (f / R) ** 2
    k1_cal, u_cal = float(D.ravel()[0]), float(sd.ravel()[4])
    assert abs(k1_pl - k1_cal) < 3 * np.hypot(u_pl, u_cal)
