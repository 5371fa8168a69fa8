"""The board's x/y scale fitted with the intrinsics (imaging/camera_board.py): a board printed
longer along its x is named and corrected when the views' in-plane rotations separate it from
the pixels' aspect, its range (the print tolerance) carried in fy/fx's u when they do not.

Default: corners projected through a known lens (white noise: the formal u is exact).
Slow: the false-alarm count on square boards (binomial), and user 18's rendered boards
(tests/align/user18_inputs.py: by ray through a true OpenCV lens) over five seeds.
"""

from __future__ import annotations

import glob
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy import special

from imaging import find_chessboard
from imaging.camera import calibrate_corners
from imaging.camera_board import BOARD_ALPHA, board_choice, board_fit, significant

K_T = np.array([[900.0, 0, 405.5], [0, 900.0, 295.5], [0, 0, 1]])
D_T = np.array([-0.22, 0.08, 4e-4, -3e-4, 0.0])
SIZE = (800, 600)


def views(rng, n, s, roll_deg, noise_px=0.05):
    """n views of a 9x6 board (30 mm squares) printed with x/y scale 1 + s, random tilts
    (±30°) and in-plane rotations uniform in ±roll_deg; the nominal object points and the
    corners seen (white noise [px])."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = (np.mgrid[0:9, 0:6].T.reshape(-1, 2) - [4, 2.5]) * 30.0
    true = obj.astype(float) * [1 + s, 1, 1]
    objpts, imgpts = [], []
    while len(objpts) < n:
        ax = np.radians(rng.uniform(-30, 30, 2))
        R = (cv2.Rodrigues(np.array([ax[0], ax[1], 0.0]))[0]
             @ cv2.Rodrigues(np.array([0, 0, np.radians(rng.uniform(-roll_deg, roll_deg))]))[0])
        z = rng.uniform(560, 760)
        t = np.array([rng.uniform(-0.2, 0.2) * z, rng.uniform(-0.15, 0.15) * z, z])
        p = cv2.projectPoints(true, cv2.Rodrigues(R)[0], t, K_T, D_T)[0].reshape(-1, 2)
        if p.min() < 5 or p[:, 0].max() > SIZE[0] - 6 or p[:, 1].max() > SIZE[1] - 6:
            continue
        p = p + rng.normal(0, noise_px, p.shape)
        objpts.append(obj)
        imgpts.append(p.astype(np.float32).reshape(-1, 1, 2))
    return objpts, imgpts


def fit(objpts, imgpts):
    _, K, D, _, _ = cv2.calibrateCamera(objpts, imgpts, SIZE, None, None,
                                        flags=cv2.CALIB_FIX_K3)
    return board_fit(objpts, imgpts, K, D, True, False)


def test_rotated_views_separate_the_board_from_the_aspect():
    """Views rotated ±90° about the board's normal: a 0.5 % print error within 3 u of its
    fitted s and significant; the same board always the same way up (±2°): s's u far above
    the 0.1 % tolerance, so not separable and the tolerance carried; a square board with
    rotated views: not significant, its range carried. A fit blind to the board's frame (s
    absorbed by the aspect) fails the first; one ignoring degeneracy fails the second."""
    rng = np.random.default_rng(3)
    f = fit(*views(rng, 8, 0.005, 90))
    assert significant(f) and abs(f["s"] - 0.005) < 3 * f["u"] < 0.001, f
    c = board_choice(f, f["s"], True)
    assert c["board"] == "corrected" and "+0.5" in c["why"] and c["carried_s"] == f["u"]
    f = fit(*views(rng, 8, 0.005, 2))
    c = board_choice(f, f["s"], significant(f))
    assert f["u"] > 0.001 and c["board"] == "not separable", c
    assert c["carried_s"] == 0.001 and "rotate the board" in c["why"]
    assert abs(c["carried_direction"][1] / 900 - c["carried_direction"][0] / 900) > 0.5
    f = fit(*views(rng, 8, 0.0, 90))
    c = board_choice(f, f["s"], significant(f))
    assert c["board"] == "nominal" and c["carried_s"] == pytest.approx(np.hypot(f["s"], f["u"]))


@pytest.mark.slow
def test_false_alarms_on_square_boards_at_alpha():
    """300 square boards, 8 views rotated ±45°: s called significant in a binomial count at
    BOARD_ALPHA (1 %: expected 3; refused beyond the 99.9 % point, 10). Seen: 0 of 300
    (the u is the larger of formal and jackknife: conservative)."""
    rng = np.random.default_rng(11)
    n = 300
    hits = sum(significant(fit(*views(rng, 8, 0.0, 45))) for _ in range(n))
    limit = next(k for k in range(n) if special.bdtr(k, n, BOARD_ALPHA) >= 0.999)
    assert hits <= limit, (hits, limit)


# ------------------------------------------------------------ user 18's rendered boards

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "align"))


def rendered(tmp: Path, scale_x: float, seed: int, n: int = 12):
    import user18_inputs as u18

    tmp.mkdir(parents=True, exist_ok=True)
    u18.write_boards(str(tmp), u18.Lens(), n, seed, u18.Board(scale_x=scale_x))
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 30.0
    imgpts = [find_chessboard(cv2.imread(p, cv2.IMREAD_GRAYSCALE), (9, 6))
              for p in sorted(glob.glob(f"{tmp}/*.png"))]
    imgpts = [c.astype(np.float32).reshape(-1, 1, 2) for c in imgpts if c is not None]
    return calibrate_corners([obj] * len(imgpts), imgpts, SIZE, [str(i) for i in
                                                                 range(len(imgpts))])


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_user18_boards_printed_long_are_corrected(tmp_path, seed):
    """user 18's renders (12 views, tilts ±30°, in-plane rotations ±9°) of a board 0.5 %
    longer along x: corrected, s within 3 u of 0.005, the corrected fy/fx within 3 of its u
    of 1; the same seed's square board not corrected. Seen (seeds 0-4): s +0.464, +0.476,
    +0.506, +0.444, +0.433 % at u 0.06-0.10 % (z −1.14..+0.09); square: 3 nominal, 2 not
    separable."""
    cam = rendered(tmp_path / "long", 1.005, seed)
    b = cam.board_scale
    K = cam.camera_matrix
    assert b["board"] == "corrected" and abs(b["s"] - 0.005) <= 3 * b["u_s"], b
    assert abs(K[1, 1] / K[0, 0] - 1) <= 3 * cam.u["aspect"], (K, cam.u["aspect"])
    cam = rendered(tmp_path / "square", 1.0, seed)
    b = cam.board_scale
    assert b["board"] != "corrected" and abs(b["s"]) <= 3 * b["u_s"], b
    K = cam.camera_matrix
    assert abs(K[1, 1] / K[0, 0] - 1) <= 3 * cam.u["aspect"], (K, cam.u["aspect"])
