"""Independent input generators for tests/align/test_independent_user4.py.

Written from the documentation only (no import of align, imaging, goniometry, axisbase or
synth). Images are rendered through OpenCV's distortion model: every *distorted* sensor pixel
is mapped back to the ideal pinhole image with cv2.undistortPoints and the groove's profile is
evaluated there (3x3 sub-pixel samples per pixel).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np


def camera_matrix(w: int, h: int, f: float) -> np.ndarray:
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def _ideal_coords(w: int, h: int, K: np.ndarray, dist: np.ndarray, ss: int = 3):
    """Ideal (pinhole, same K) pixel coordinates of ss x ss sub-samples of each sensor pixel."""
    offs = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(w)[None, :, None, None] + offs[None, None, None, :])
    ys = (np.arange(h)[:, None, None, None] + offs[None, None, :, None])
    X = np.broadcast_to(xs, (h, w, ss, ss)).reshape(-1)
    Y = np.broadcast_to(ys, (h, w, ss, ss)).reshape(-1)
    pts = np.stack([X, Y], axis=1).astype(np.float64).reshape(-1, 1, 2)
    if np.any(dist != 0):
        und = cv2.undistortPoints(pts, K, dist, P=K,
                                  criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                            40, 1e-10))
        und = und.reshape(-1, 2)
    else:
        und = pts.reshape(-1, 2)
    return und[:, 0], und[:, 1]


def render_marks(w: int, h: int, marks, *, f: float | None = None, dist=(0, 0, 0, 0),
                 seed: int = 0, bg: float = 180.0, contrast: float = 90.0, width: float = 3.0,
                 blur: float = 1.0, noise: float = 2.0, bow_px: float = 0.0,
                 ss: int = 3) -> np.ndarray:
    """8-bit grey image of dark straight grooves in the *ideal* image seen through the lens.

    marks: list of (cx, cy, angle_deg, length) in ideal pixel coordinates, angle from +x
    towards -y (counter-clockwise as displayed). bow_px bends every groove by a parabola of
    that sagitta (a physically bent mark).
    """
    f = f if f is not None else 1.325 * 0.5 * math.hypot(w, h)
    K = camera_matrix(w, h, f)
    dist = np.asarray(dist, dtype=np.float64)
    U, V = _ideal_coords(w, h, K, dist, ss)
    from scipy.special import erf
    dark = np.zeros_like(U)
    for (cx, cy, ang, length) in marks:
        a = math.radians(ang)
        dx, dy = math.cos(a), -math.sin(a)
        s = (U - cx) * dx + (V - cy) * dy          # along
        d = -(U - cx) * dy + (V - cy) * dx         # across
        half = width / 2.0
        near = (np.abs(s) < length / 2 + 6 * blur) & (np.abs(d) < half + abs(bow_px) + 6 * blur)
        s, d = s[near], d[near]
        if bow_px:
            d = d - bow_px * (1.0 - np.clip(2.0 * s / length, -1, 1) ** 2)
        k = math.sqrt(2) * blur
        prof = 0.5 * (erf((d + half) / k) - erf((d - half) / k))
        along = 0.5 * (erf((s + length / 2) / k) - erf((s - length / 2) / k))
        dark[near] = np.maximum(dark[near], prof * along)
    img = bg - contrast * dark
    img = img.reshape(h, w, ss, ss).mean(axis=(2, 3))
    rng = np.random.default_rng(seed)
    img = img + rng.normal(0.0, noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def write_png(path, img) -> Path:
    path = Path(path)
    ok = cv2.imwrite(str(path), img)
    assert ok
    return path


def write_camera_json(path, w: int, h: int, f: float, dist, *, u=None) -> Path:
    K = camera_matrix(w, h, f)
    doc = {
        "format": "axis-align/camera",
        "format_version": 3,
        "camera_matrix": K.tolist(),
        "dist_coeffs": [float(x) for x in dist] + [0.0] * (5 - len(dist)),
        "image_size": [w, h],
        "rms_px": 0.2,
        "views": 10,
    }
    if u is not None:
        doc["u"] = u
    Path(path).write_text(json.dumps(doc))
    return Path(path)


def angle_diff_arcsec(a_deg: float, b_deg: float) -> float:
    d = (a_deg - b_deg + 90.0) % 180.0 - 90.0
    return d * 3600.0


def render_ruled(w: int, h: int, pitch: float, n: int, *, angle_deg: float = 90.0,
                 seed: int = 0, dust: int = 6, numerals: bool = True, x0: float | None = None):
    """A ruled scale: n short parallel grooves at a fixed pitch (long every 5th), numerals and
    dust specks. Returns (image, list of (cx, cy, angle, length))."""
    rng = np.random.default_rng(seed)
    a = math.radians(angle_deg)
    dx, dy = math.cos(a), -math.sin(a)      # along the graduation
    nx, ny = -dy, dx                        # across (the ruling direction)
    cx0 = (w - 1) / 2.0 if x0 is None else x0
    cy0 = (h - 1) / 2.0
    marks = []
    for i in range(n):
        k = i - (n - 1) / 2.0
        L = 260.0 if i % 5 == 0 else 180.0
        cx, cy = cx0 + k * pitch * nx, cy0 + k * pitch * ny
        marks.append((cx, cy, angle_deg, L))
    img = render_marks(w, h, marks, seed=seed, noise=2.0)
    if numerals:
        for i, (cx, cy, _, L) in enumerate(marks):
            if i % 5 == 0:
                org = (int(cx - 12), int(cy + L / 2 + 40))
                cv2.putText(img, str(i), org, cv2.FONT_HERSHEY_SIMPLEX, 1.0, 90, 2, cv2.LINE_AA)
    for _ in range(dust):
        px, py = rng.uniform(0, w), rng.uniform(0, h)
        cv2.circle(img, (int(px), int(py)), int(rng.integers(2, 5)), 110, -1, cv2.LINE_AA)
    return img, marks
