"""Independent user 18's renders: chessboards and scribe marks through a true OpenCV lens.

Written without reading the project's code (only README, docs, schemas, --help). Every
image is rendered by ray: each sensor sub-sample is taken back through the true lens
(``cv2.undistortPoints``, iterated to 1e-12, the inverse of OpenCV's forward model) to a
ray, the ray meets the scene (a chessboard plane, possibly bowed; or the object plane of a
scribe mark), the scene's intensity there is taken, blurred (the optics' PSF) on the
sub-sample grid *before* the pixel integrates its sub-samples (area), then shot noise
(Poisson in electrons) and read noise are added and the value quantised.

Effects the tool is not told about: rolling-shutter skew, motion blur along/across the
mark, lateral colour (per-channel magnification), a lens decentred after calibration
(principal point moved), a mark's paint worn off one side of the groove along part of
its length, a board printed with an anisotropic scale error or bowed out of plane, and
few views. Imports nothing from the project.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

W, H = 800, 600
FULL_WELL = 12000.0     # electrons at intensity 1
READ_E = 6.0            # read noise [e-]


@dataclass(frozen=True)
class Lens:
    """The true camera: OpenCV intrinsics and distortion (k1 k2 p1 p2 k3)."""

    fx: float = 900.0
    fy: float = 900.0
    cx: float = (W - 1) / 2 + 6.0
    cy: float = (H - 1) / 2 - 4.0
    dist: tuple = (-0.22, 0.08, 4e-4, -3e-4, 0.0)

    def K(self):
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def moved(self, dcx=0.0, dcy=0.0):
        return Lens(self.fx, self.fy, self.cx + dcx, self.cy + dcy, self.dist)


def sensor_grid(ss):
    """Sub-sample centres of every pixel (pixel centres at integers), shape (H*ss, W*ss)."""
    o = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(W)[:, None] + o[None, :]).ravel()
    ys = (np.arange(H)[:, None] + o[None, :]).ravel()
    return np.meshgrid(xs, ys)


_RAYS = {}


def lens_rays(lens: Lens, ss: int):
    """Every sub-sample's ray through the lens (cached: it depends on the lens only)."""
    key = (lens, ss)
    if key not in _RAYS:
        X, Y = sensor_grid(ss)
        _RAYS[key] = (X, Y) + rays(lens, X, Y)
    return _RAYS[key]


def rays(lens: Lens, X, Y):
    """Normalised ray (x/z, y/z) of sensor points through the true lens."""
    pts = np.stack([X.ravel(), Y.ravel()], 1).astype(np.float64)[:, None, :]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10)
    und = cv2.undistortPoints(pts, lens.K(), np.array(lens.dist), None, None, None, crit)
    und = und.reshape(-1, 2)
    return und[:, 0].reshape(X.shape), und[:, 1].reshape(X.shape)


def expose(img_super, ss, rng, blur_px=0.7, bits=8):
    """PSF on the sub-sample grid, area integration, shot + read noise, quantisation."""
    if blur_px > 0:
        img_super = gaussian_filter(img_super, blur_px * ss, mode="nearest")
    h, w = img_super.shape[0] // ss, img_super.shape[1] // ss
    px = img_super.reshape(h, ss, w, ss).mean(axis=(1, 3))
    e = rng.poisson(np.clip(px, 0, None) * FULL_WELL) + rng.normal(0, READ_E, px.shape)
    top = 255 if bits == 8 else 65535
    dtype = np.uint8 if bits == 8 else np.uint16
    return np.clip(np.round(e / FULL_WELL * top), 0, top).astype(dtype)


# ---------------------------------------------------------------- chessboards

@dataclass(frozen=True)
class Board:
    cols: int = 9          # inner corners
    rows: int = 6
    square: float = 30.0   # mm
    scale_x: float = 1.0   # printed scale error along the board's x (the tool assumes 1)
    bow_mm: float = 0.0    # out-of-plane bow at the board's centre (0 at its edge)


def board_poses(n, rng):
    """n poses (rvec, tvec) [mm] covering the frame, tilted up to ~35 degrees."""
    poses = []
    for _ in range(n):
        ang = np.radians(rng.uniform(-30, 30, 3)) * np.array([1, 1, 0.3])
        z = rng.uniform(560, 760)
        tx = rng.uniform(-0.9, 0.9) * max(z * W / 2 / 900 - 160, 10)
        ty = rng.uniform(-0.9, 0.9) * max(z * H / 2 / 900 - 115, 10)
        poses.append((ang, np.array([tx, ty, z])))
    return poses


def _board_intensity(Xb, Yb, board: Board):
    s = board.square
    xq = Xb / board.scale_x / s
    yq = Yb / s
    par = (np.floor(xq) + np.floor(yq)) % 2
    inside = (xq > 0) & (xq < board.cols + 1) & (yq > 0) & (yq < board.rows + 1)
    margin = (xq > -0.6) & (xq < board.cols + 1.6) & (yq > -0.6) & (yq < board.rows + 1.6)
    val = np.where(par == 0, 0.08, 0.85)
    out = np.where(inside, val, np.where(margin, 0.85, 0.45))
    return out


def render_board(lens: Lens, board: Board, rvec, tvec, rng, ss=3, blur_px=0.7):
    """A chessboard photograph (8 bit): board coords X right, Y down, origin at the corner
    before the first inner corner, so inner corner (i, j) is at ((i+1) s, (j+1) s)."""
    X, Y, xn, yn = lens_rays(lens, ss)
    R, _ = cv2.Rodrigues(np.asarray(rvec, float))
    t = np.asarray(tvec, float)
    # centre the board on its pose: shift board coords so the pose's origin is its centre
    c0 = np.array([(board.cols + 1) * board.square * board.scale_x / 2,
                   (board.rows + 1) * board.square / 2])
    half = np.hypot(*c0)
    Z = np.zeros_like(xn)
    for _ in range(4 if board.bow_mm else 1):
        # s*(xn, yn, 1) = R0 X + R1 Y + R2 Z + t  -> 3x3 system per sample (Cramer)
        rhs = -(t[:, None] + R[:, 2:3] * Z.ravel()[None, :])
        d = np.stack([xn.ravel(), yn.ravel(), np.ones(xn.size)])
        A0, A1 = R[:, 0][:, None], R[:, 1][:, None]
        A2 = -d
        det = _det3(A0, A1, A2)
        Xb = _det3(rhs, A1, A2) / det
        Yb = _det3(A0, rhs, A2) / det
        if board.bow_mm:
            rr = (Xb ** 2 + Yb ** 2) / half ** 2
            Z = (board.bow_mm * np.clip(1 - rr, -1, 1)).reshape(xn.shape)
    img = _board_intensity(Xb.reshape(xn.shape) + c0[0], Yb.reshape(xn.shape) + c0[1], board)
    return expose(img, ss, rng, blur_px, bits=8)


def _det3(a, b, c):
    a = np.broadcast_to(a, c.shape)
    b = np.broadcast_to(b, c.shape)
    return (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))


def write_boards(folder, lens: Lens, n, seed, board: Board = Board()):
    """n board photographs in folder; returns the file paths of those OpenCV finds a board in."""
    rng = np.random.default_rng(seed)
    paths = []
    tries = 0
    while len(paths) < n and tries < 4 * n:
        tries += 1
        rv, tv = board_poses(1, rng)[0]
        img = render_board(lens, board, rv, tv, rng, ss=2)
        ok, _ = cv2.findChessboardCorners(img, (board.cols, board.rows))
        if not ok:
            continue
        p = f"{folder}/board{len(paths):02d}.png"
        cv2.imwrite(p, img)
        paths.append(p)
    return paths


# ---------------------------------------------------------------- scribe marks

@dataclass(frozen=True)
class Mark:
    """A straight groove in the pinhole image (px in fx units about the principal point)."""

    x0: float = 0.0             # centre [pinhole px from the principal point]
    y0: float = 0.0
    angle_deg: float = 20.0     # from +x towards -y (counter-clockwise as displayed)
    length: float = 260.0
    width: float = 3.0          # groove Gaussian sigma [px]
    depth: float = 0.45         # fraction of the background removed at the groove's centre
    wear_frac: float = 0.0      # fraction of the length (from one end) whose paint is worn
    wear_side: float = 0.0      # 0..1: how much of the groove's +normal half is gone there
    extra: dict = field(default_factory=dict)


def mark_intensity(xp, yp, mark: Mark):
    a = np.radians(mark.angle_deg)
    d = np.array([np.cos(a), -np.sin(a)])        # image y down
    n = np.array([np.sin(a), np.cos(a)])
    rx, ry = xp - mark.x0, yp - mark.y0
    s = rx * d[0] + ry * d[1]
    q = rx * n[0] + ry * n[1]
    half = mark.length / 2
    end = 0.5 * (1 + np.tanh((half - np.abs(s)) / 1.5))   # soft ends
    prof = np.exp(-0.5 * (q / mark.width) ** 2)
    if mark.wear_frac > 0:
        worn = s > half - 2 * half * mark.wear_frac
        prof = np.where(worn & (q > 0), prof * (1 - mark.wear_side), prof)
    tex = 0.0
    return 0.72 * (1 - mark.depth * prof * end) + tex


def render_mark(lens: Lens, mark: Mark, rng, ss=3, blur_px=0.8, bits=16,
                skew=0.0, motion=(0.0, 0.0), nsub=1, chroma=0.0):
    """A mark photograph through the true lens.

    skew: rolling shutter, the scene's x shift per sensor row [px/row] (about the middle row).
    motion: total shift (along, across) the mark during the exposure [px]; nsub sub-exposures.
    chroma: lateral colour, channel magnification 1 -/+ chroma for R/B about the principal
    point (G is the lens as given); a 3-channel image when non-zero.
    """
    X, Y = sensor_grid(ss)
    chans = [0.0] if chroma == 0 else [+chroma, 0.0, -chroma]   # BGR order for cv2
    a = np.radians(mark.angle_deg)
    dvec = np.array([np.cos(a), -np.sin(a)])
    nvec = np.array([np.sin(a), np.cos(a)])
    out = []
    for c in chans:
        Xc = lens.cx + (X - lens.cx) / (1 + c)
        Yc = lens.cy + (Y - lens.cy) / (1 + c)
        xn, yn = rays(lens, Xc, Yc)
        xp, yp = xn * lens.fx, yn * lens.fx
        if skew:
            xp = xp - skew * (Y - (H - 1) / 2)
        acc = np.zeros_like(xp)
        k = max(nsub, 1)
        for i in range(k):
            f = (i + 0.5) / k - 0.5 if k > 1 else 0.0
            sh = f * (motion[0] * dvec + motion[1] * nvec)
            acc += mark_intensity(xp - sh[0], yp - sh[1], mark)
        out.append(expose(acc / k, ss, rng, blur_px, bits))
    if len(out) == 1:
        return out[0]
    return np.stack(out, -1)


def true_angle_deg(mark: Mark) -> float:
    """The tool's convention: the undistorted (pinhole) image's direction, (-90, 90]."""
    a = mark.angle_deg % 180.0
    return a - 180.0 if a > 90.0 else a
