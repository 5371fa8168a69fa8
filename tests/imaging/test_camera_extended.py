"""align camera: per-parameter uncertainties and per-view RMS (OpenCV extended calibration)."""

from __future__ import annotations

import json

import numpy as np

from align.cli import main
from imaging import CameraModel, calibrate_chessboard, read_image
from tests.conftest import real_folder


def test_extended_calibration_on_real_chessboards(tmp_path):
    files = sorted(real_folder("opencv-chessboard").glob("left*.jpg"))
    imgs = {str(f): read_image(f).astype(np.uint8) for f in files}
    model, failed = calibrate_chessboard(imgs, (9, 6))
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
