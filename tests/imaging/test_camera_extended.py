"""align camera: per-parameter uncertainties and per-view RMS (OpenCV extended calibration)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from align.cli import main
from imaging import CameraModel, calibrate_chessboard, read_image
from imaging.camera import jackknife_u
from imaging.camera_board import board_term
from imaging.camera_cov import INTRINSICS
from tests.conftest import real_folder


def test_extended_calibration_on_real_chessboards(tmp_path):
    files = sorted(real_folder("opencv-chessboard").glob("left*.jpg"))
    imgs = {str(f): read_image(f).astype(np.uint8) for f in files}
    model, failed = calibrate_chessboard(imgs, (9, 6), k3="free")  # OpenCV's default
    assert not failed
    assert set(model.per_view_rms_px) == set(imgs)
    assert all(0 < v < 1 for v in model.per_view_rms_px.values())
    # Every free parameter has a positive uncertainty, far below its value for f and k1.
    assert all(model.u[k] > 0 for k in ("fx", "fy", "cx", "cy", "k1", "k2", "k3"))
    assert model.u["fx"] < 0.01 * model.camera_matrix[0, 0]
    assert model.u["k1"] < 0.1 * abs(model.dist_coeffs[0])
    fixed, _ = calibrate_chessboard(imgs, (9, 6), fix_k3=True, fix_aspect=True)
    assert fixed.dist_coeffs[4] == 0 and fixed.u["k3"] == 0
    assert fixed.camera_matrix[0, 0] == fixed.camera_matrix[1, 1]
    out = tmp_path / "cam.json"
    assert main(["camera", *map(str, files), "--fix-k3", "--json", str(out)]) == 0
    back = CameraModel.load(out)
    assert back.u == fixed_u(out) and back.per_view_rms_px is not None


def fixed_u(path):
    return {k: float(v) for k, v in json.loads(path.read_text())["u"].items()}


def test_u_is_the_larger_of_formal_and_jackknife_on_real_views():
    """The 7 real views disagree more than OpenCV's formal u says (cx by 3.3x): the model's
    u is the larger of the two per parameter, and both are kept in the file."""
    files = sorted(real_folder("opencv-chessboard").glob("left*.jpg"))
    imgs = {str(f): read_image(f).astype(np.uint8) for f in files}
    model, _ = calibrate_chessboard(imgs, (9, 6), k3="free")  # the figures: OpenCV's model
    # (with the board's x/y-scale term in quadrature: imaging.camera_board)
    w, c = board_term(model.board_scale)
    for k, v in model.u_formal.items():
        assert np.isclose(model.u[k], np.hypot(max(v, model.u_jackknife[k]),
                                               c * w[INTRINSICS.index(k)]), rtol=1e-12), k
    # the aspect fy / fx: far better known than fx and fy together (they move together)
    fx, fy = model.camera_matrix[0, 0], model.camera_matrix[1, 1]
    assert model.u["aspect"] < 0.5 * np.hypot(model.u["fx"] / fx, model.u["fy"] / fy)
    assert model.u_jackknife["cx"] > 2 * model.u_formal["cx"]
    back = CameraModel.from_dict(model.to_dict())
    assert back.u_jackknife == model.u_jackknife and back.u_formal == model.u_formal


def _board_views(rng, n_views, K, D, noise_px):
    """Corners of a 9x6 board (30 mm squares) seen from n random poses through (K, D), with
    white noise [px]: the case OpenCV's formal u is exact for."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 30.0
    obj -= obj.mean(axis=0)
    objpts, imgpts = [], []
    for _ in range(n_views):
        rvec = rng.uniform(-0.5, 0.5, 3)
        tvec = np.array([rng.uniform(-60, 60), rng.uniform(-40, 40), rng.uniform(450, 650)])
        p, _ = cv2.projectPoints(obj.astype(float), rvec, tvec, K, D)
        p = p.reshape(-1, 2) + rng.normal(0, noise_px, (54, 2))
        objpts.append(obj)
        imgpts.append(p.astype(np.float32).reshape(-1, 1, 2))
    return objpts, imgpts


@pytest.mark.slow  # a jackknife over the views (~1.5 s CPU)
def test_jackknife_agrees_with_the_formal_u_when_the_model_is_exact():
    """White corner noise through OpenCV's own model, 10 views, 12 seeds: the jackknife's u is
    the formal u within its sampling spread (median ratio 0.6-1.7 per parameter), so taking
    the larger does not inflate an honest calibration by much; the errors against truth are
    covered (|err| / u < 4 for every parameter and seed)."""
    K = np.array([[530.0, 0, 320], [0, 530, 240], [0, 0, 1]])
    D = np.array([-0.27, 0.1, 1e-4, -2e-4, 0.0])
    truth = np.r_[530, 530, 320, 240, D[:4]]
    ratios, zs, aspect_z = [], [], []
    for seed in range(12):
        objpts, imgpts = _board_views(np.random.default_rng(seed), 10, K, D, 0.1)
        flags = cv2.CALIB_FIX_K3
        _, K1, D1, _, _, sd, _, _ = cv2.calibrateCameraExtended(
            objpts, imgpts, (640, 480), None, None, flags=flags)
        formal = np.ravel(sd)[:8]
        jk = jackknife_u(objpts, imgpts, (640, 480), None, flags)  # once: 10 calibrations
        jack = jk[:8]  # [-1]: the aspect
        ratios.append(jack / formal)
        est = np.r_[K1[0, 0], K1[1, 1], K1[0, 2], K1[1, 2], np.ravel(D1)[:4]]
        zs.append((est - truth) / np.maximum(formal, jack))
        aspect_z.append((K1[1, 1] / K1[0, 0] - 1.0) / jk[-1])
    med = np.median(ratios, axis=0)
    print("median jackknife/formal", np.round(med, 2), "max |z|", np.abs(zs).max())
    assert np.all((med > 0.6) & (med < 1.7)), med
    assert np.abs(zs).max() < 4, np.abs(zs).max(axis=0)
    # the aspect fy / fx (its u far below fx's and fy's together): covered too
    assert np.abs(aspect_z).max() < 4, np.round(aspect_z, 2)
