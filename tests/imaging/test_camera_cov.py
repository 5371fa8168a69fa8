"""The joint covariance of a calibration's intrinsics (imaging.camera_cov) and its place in
the camera file (format 4; older files read without it)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from imaging import CameraModel, ImageInputError, fit_line_only
from imaging.camera import calibrate_corners
from imaging.camera_cov import INTRINSICS, dominating, formal_cov

K_T = np.array([[530.0, 0, 326.0], [0, 531.5, 236.0], [0, 0, 1]])
D_T = np.array([-0.28, 0.12, 8e-4, -5e-4, -0.03])


SHAPE = (480, 640)
CENTRE = np.array([319.5, 239.5])


def through_lens(xy: np.ndarray, D: np.ndarray, cam: CameraModel
                 ) -> tuple[float, np.ndarray] | None:
    """A straight mark at normalised scene points ``xy`` imaged through the true lens (K_T,
    ``D``) and measured through ``cam`` without noise: the angle's error [rad] and its
    centres in the model's undistorted frame; None when it comes within 5 px of the frame's
    edge (shared by the camera-model tests)."""
    raw, _ = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), np.zeros(3),
                               np.zeros(3), K_T, D)
    raw = raw.reshape(-1, 2)
    if not (raw.min() > 5 and raw[:, 0].max() < SHAPE[1] - 6 and raw[:, 1].max() < SHAPE[0] - 6):
        return None
    one = np.ones(len(raw))
    q, _ = cam.undistort_centred(raw - CENTRE, one, SHAPE)
    err = fit_line_only(q, one)[0] - fit_line_only(xy * K_T[0, 0], one)[0]
    return float((err + np.pi / 2) % np.pi - np.pi / 2), q


def board_views(rng: np.random.Generator, n: int, noise_px: float,
                K: np.ndarray = K_T, D: np.ndarray = D_T) -> tuple[list, list]:
    """Corners of a 9x6 board (unit squares) from ``n`` random poses spread over a 640x480
    frame through the known lens (K, D), white noise [px]: every corner inside the frame."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj[:, :2] -= obj[:, :2].mean(axis=0)
    objpts, imgpts = [], []
    while len(objpts) < n:
        rvec = rng.uniform(-1, 1, 3) * np.radians([35, 35, 20])
        z = rng.uniform(14, 22)
        tvec = np.array([rng.uniform(-0.45, 0.45) * z, rng.uniform(-0.35, 0.35) * z, z])
        p, _ = cv2.projectPoints(obj.astype(float), rvec, tvec, K, D)
        p = p.reshape(-1, 2)
        if p.min() < 8 or p[:, 0].max() > 631 or p[:, 1].max() > 471:
            continue
        objpts.append(obj.copy())
        imgpts.append((p + rng.normal(0, noise_px, p.shape)).astype(np.float32)
                      .reshape(-1, 1, 2))
    return objpts, imgpts


def test_the_formal_covariance_has_opencvs_standard_deviations():
    """s² (JᵀJ)⁻¹ from projectPoints' Jacobian: its diagonal is OpenCV's own formal u (the
    same estimate, so to 1e-6), with k3 and the aspect fixed too (a fixed k3: row 0; a fixed
    aspect: fx and fy fully correlated); and k1, k2 strongly anticorrelated (why their terms
    cannot be added as if independent)."""
    obj_pts, img_pts = board_views(np.random.default_rng(1), 7, 0.15)
    for fix_k3, fix_aspect in ((False, False), (True, True)):
        flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (
            cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect else 0)
        K0 = np.eye(3) if fix_aspect else None
        _, K, D, rv, tv, sd, _, _ = cv2.calibrateCameraExtended(
            obj_pts, img_pts, (640, 480), K0, None, flags=flags)
        C = formal_cov(obj_pts, img_pts, K, D, rv, tv, fix_k3, fix_aspect)
        sd = np.ravel(sd)[:9]
        free = sd > 0  # OpenCV states fx's as 0 with the aspect fixed (ours: fy's x fx/fy)
        assert free.sum() == 9 - fix_k3 - fix_aspect
        np.testing.assert_allclose(np.sqrt(np.diag(C))[free], sd[free], rtol=1e-6)
        r = C / np.sqrt(np.outer(np.diag(C), np.diag(C)) + 1e-300)
        if fix_aspect:
            assert r[0, 1] > 0.999999 and C[8, 8] == 0
        else:
            assert r[4, 5] < -0.8, r[4, 5]


def test_dominating_is_at_least_both_and_no_more_than_their_sum():
    """The matrix 'larger of the two': in every direction at least each covariance and at
    most their sum; equal to a when b is smaller everywhere; b's part outside a's rows is left
    out (a fixed parameter stays exact)."""
    rng = np.random.default_rng(4)
    scale = np.array([1e2, 1, 1e-2, 1e-4, 1])  # the intrinsics' spread of units
    for _ in range(20):
        A = rng.normal(size=(5, 5)) * scale[:, None]
        a = A @ A.T
        B = rng.normal(size=(5, 3)) * scale[:, None]  # rank 3, as a jackknife of few views
        b = B @ B.T
        c = dominating(a, b)
        for g in rng.normal(size=(50, 5)) / scale:
            ga, gb, gc = g @ a @ g, g @ b @ g, g @ c @ g
            assert gc >= max(ga, gb) * (1 - 1e-9) and gc <= (ga + gb) * (1 + 1e-9)
        np.testing.assert_allclose(dominating(a, 0.5 * a), a, rtol=1e-9)
    a0 = np.diag([1.0, 0.0])
    assert dominating(a0, np.eye(2))[1, 1] == 0.0


def test_the_covariance_is_saved_and_an_old_file_reads_without_it(tmp_path):
    """Format 4 saves cov, cov_formal, cov_jackknife (the intrinsics' order named); a file
    without them (format 3) still loads, with cov None (its u's then added as if
    independent); a cov that is no covariance is refused naming the key."""
    obj_pts, img_pts = board_views(np.random.default_rng(2), 5, 0.15)
    m = calibrate_corners(obj_pts, img_pts, (640, 480), [str(i) for i in range(5)])
    d = m.to_dict()
    assert d["cov_params"] == list(INTRINSICS)
    back = CameraModel.from_dict(json.loads(json.dumps(d)))
    np.testing.assert_array_equal(back.cov, m.cov)
    np.testing.assert_array_equal(back.cov_jackknife, m.cov_jackknife)
    old = {k: v for k, v in d.items() if not k.startswith("cov")}
    p = tmp_path / "old.json"
    p.write_text(json.dumps({"format": "axis-align/camera", "format_version": 3, **old}))
    assert CameraModel.load(p).cov is None
    bad = dict(d, cov=(np.array(d["cov"]) * np.r_[1, 1, 1, 1, 1, 1, 1, 1, -1]).tolist())
    p.write_text(json.dumps({"format": "axis-align/camera", "format_version": 4, **bad}))
    with pytest.raises(ImageInputError, match="'cov' is not a covariance"):
        CameraModel.load(p)
