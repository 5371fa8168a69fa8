"""Chessboard photographs rendered through a known OpenCV lens (for tests of ``align camera``
against truth): each sensor pixel integrates the board over sub x sub points mapped through
the lens (distorted -> normalised pinhole ray -> the board's plane), then blur and noise.
Nothing from the pipeline: OpenCV's own distortion model defines the lens."""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

PATTERN = (9, 6)
"""Inner corners (columns, rows) of the board, unit squares, corners at 0..8 x 0..5."""


def ray_grid(K: np.ndarray, D: np.ndarray, size: tuple[int, int], sub: int = 3) -> np.ndarray:
    """Normalised pinhole coordinates (h, w, sub², 2) of each pixel's sub-points through the
    lens (K, D) of an image of ``size`` (width, height) [px]; once per lens."""
    w, h = size
    offs = (np.arange(sub) + 0.5) / sub - 0.5
    yy, xx = np.mgrid[0:h, 0:w]
    pts = (np.stack([xx, yy], -1)[:, :, None, :]
           + np.stack(np.meshgrid(offs, offs), -1).reshape(1, 1, -1, 2)).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    n = cv2.undistortPoints(pts.astype(np.float64), K, D, None, None, criteria=crit)
    return n.reshape(h, w, sub * sub, 2)


def render_board(rays: np.ndarray, rvec: np.ndarray, tvec: np.ndarray,
                 rng: np.random.Generator, noise_dn: float = 2.0, blur_px: float = 0.7
                 ) -> np.ndarray:
    """An 8-bit photograph of the board at pose (rvec, tvec) [board units] seen along
    ``rays`` (:func:`ray_grid`): black and white squares (30, 220 DN) with a white margin
    of one square, grey (120 DN) around."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, float))
    Hi = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], tvec]))  # ray -> board plane
    x, y = rays[..., 0], rays[..., 1]
    bz = Hi[2, 0] * x + Hi[2, 1] * y + Hi[2, 2]
    X = (Hi[0, 0] * x + Hi[0, 1] * y + Hi[0, 2]) / bz
    Y = (Hi[1, 0] * x + Hi[1, 1] * y + Hi[1, 2]) / bz
    inner = (X >= -1) & (X < PATTERN[0]) & (Y >= -1) & (Y < PATTERN[1])
    board = (X >= -2) & (X < PATTERN[0] + 1) & (Y >= -2) & (Y < PATTERN[1] + 1)
    dark = inner & ((np.floor(X) + np.floor(Y)) % 2 == 0)
    v = np.where(board, np.where(dark, 30.0, 220.0), 120.0).mean(axis=-1)
    v = gaussian_filter(v, blur_px) + rng.normal(0, noise_dn, v.shape)
    return np.clip(np.round(v), 0, 255).astype(np.uint8)


def board_photos(rng: np.random.Generator, n: int, rays: np.ndarray, K: np.ndarray,
                 D: np.ndarray, size: tuple[int, int] = (640, 480), noise_dn: float = 2.0
                 ) -> dict[str, np.ndarray]:
    """``n`` photographs of the board from random poses over the frame (every corner at
    least 25 px inside it), by name; ``noise_dn``: the sensor's white noise [DN]."""
    obj = np.zeros((PATTERN[0] * PATTERN[1], 3))
    obj[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2)
    mid = np.array([(PATTERN[0] - 1) / 2, (PATTERN[1] - 1) / 2, 0.0])
    out: dict[str, np.ndarray] = {}
    while len(out) < n:
        rvec = rng.uniform(-1, 1, 3) * np.radians([35, 35, 20])
        z = rng.uniform(14, 22)
        R, _ = cv2.Rodrigues(rvec)
        tvec = np.array([rng.uniform(-0.45, 0.45) * z, rng.uniform(-0.35, 0.35) * z, z]) - R @ mid
        p, _ = cv2.projectPoints(obj, rvec, tvec, K, D)
        p = p.reshape(-1, 2)
        if p.min() < 25 or p[:, 0].max() > size[0] - 25 or p[:, 1].max() > size[1] - 25:
            continue
        out[f"board{len(out)}.png"] = render_board(rays, rvec, tvec, rng, noise_dn)
    return out
