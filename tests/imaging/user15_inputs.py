"""Independent user 15's generator: chessboards, scribe marks and ruled scales through a lens.

Written from the docs only (README, docs/, the JSON schemas): nothing here imports the project.

Physics
-------
* A lens is OpenCV's model (K, k1 k2 p1 p2 k3) used as the *forward* map of a ray: a scene point
  at normalised coordinates (X/Z, Y/Z) lands on the sensor where ``cv2.projectPoints`` puts it.
  To render, every sub-pixel sample on the sensor is taken back to its ray with
  ``cv2.undistortPointsIter`` (iterated to 1e-10), and the scene is evaluated on that ray.
* Optical blur acts before sampling: marks are a Gaussian groove whose profile is convolved
  analytically with the Gaussian blur in the scene; chessboards are rendered at 3x the pixel
  density, blurred there, then box-averaged (the pixel's area integral).
* Each pixel is the mean of a sub-pixel grid (the area integral), then shot + read noise,
  quantised to 8 or 16 bit.
* Truth: a mark's angle is its direction in the pinhole image with square pixels, from +x
  towards -y (the tool's convention, docs/commands/marks.md), in (-90, 90] degrees.
"""

from __future__ import annotations

import json
import math
import os

import cv2
import numpy as np
from scipy.special import erf

CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-12)


# ----------------------------------------------------------------------------- lenses
def lens_cv(size, k1h=0.0, k2h=0.0, p1h=0.0, p2h=0.0, k3h=0.0, f=None, pp=(0.0, 0.0), aspect=0.0):
    """OpenCV K, dist from coefficients at the image half-diagonal (docs/camera.md's lens model).

    size (W, H) [px]; k1h ... at the half-diagonal R; f focal length [px] (default 0.83 W);
    pp principal point's offset from the image centre [px]; aspect = fy/fx - 1.
    """
    w, h = size
    f = 0.83 * w if f is None else f
    r = 0.5 * math.hypot(w - 1, h - 1)
    s = r / f
    k1 = k1h / s**2
    k2 = k2h / s**4
    k3 = k3h / s**6
    p1 = p1h / s
    p2 = p2h / s
    cx = (w - 1) / 2 + pp[0]
    cy = (h - 1) / 2 + pp[1]
    K = np.array([[f, 0, cx], [0, f * (1 + aspect), cy], [0, 0, 1.0]])
    d = np.array([k1, k2, p1, p2, k3], float)
    return K, d


def _forward(xy, K, d):
    """OpenCV's distortion (k1 k2 p1 p2 k3) of normalised coordinates, then K: sensor pixels."""
    k1, k2, p1, p2, k3 = (list(d) + [0.0] * 5)[:5]
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]])


def to_rays(px, K, d):
    """Sensor pixels (N, 2) -> normalised pinhole coordinates (N, 2): the ray each sample sees.

    OpenCV's undistortPoints as a start, then Newton steps on the forward model, so the
    rendering inverts the lens exactly (to ~1e-9 px) wherever the forward map is monotonic.
    """
    target = np.ascontiguousarray(px, dtype=np.float64).reshape(-1, 2)
    und = cv2.undistortPoints(target.reshape(-1, 1, 2), K, d).reshape(-1, 2)
    eps = 1e-7
    for _ in range(4):
        fwd = _forward(und, K, d)
        jx = (_forward(und + [eps, 0], K, d) - fwd) / eps
        jy = (_forward(und + [0, eps], K, d) - fwd) / eps
        r = target - fwd
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        und = und + np.column_stack(
            [
                (jy[:, 1] * r[:, 0] - jy[:, 0] * r[:, 1]) / det,
                (-jx[:, 1] * r[:, 0] + jx[:, 0] * r[:, 1]) / det,
            ]
        )
    return und


def to_sensor(xy, K, d):
    """Normalised coordinates (N, 2) -> sensor pixels (N, 2), the lens's forward map."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    obj = np.column_stack([xy, np.ones(len(xy))])
    p, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, np.asarray(d, float))
    return p.reshape(-1, 2)


def _noise_quantise(img, rng, noise, bits, full=None):
    full = (2**bits - 1) if full is None else full
    sig = img * full
    # shot noise ~ sqrt(signal) scaled so that mid-grey has `noise` (fraction of full scale) rms
    sd = noise * full * np.sqrt(np.clip(img, 0.02, None) / 0.5)
    out = sig + rng.normal(size=img.shape) * sd
    out = np.clip(np.round(out), 0, 2**bits - 1)
    return out.astype(np.uint16 if bits > 8 else np.uint8)


# ----------------------------------------------------------------------------- chessboards
def board_poses(n, seed, size, K, pattern=(9, 6), square=1.0):
    """n board poses that keep the board inside the frame, tilted up to ~40 deg."""
    rng = np.random.default_rng(seed)
    w, h = size
    cols, rows = pattern
    poses = []
    tries = 0
    while len(poses) < n and tries < 5000:
        tries += 1
        ax = rng.uniform(-0.7, 0.7)
        ay = rng.uniform(-0.7, 0.7)
        az = rng.uniform(-0.4, 0.4)
        rvec = np.array([ax, ay, az])
        Rm, _ = cv2.Rodrigues(rvec)
        # board width covers 45-75 % of the frame
        z = K[0, 0] * (cols + 1) * square / (w * rng.uniform(0.45, 0.75))
        cen = np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0])
        tx = rng.uniform(-0.35, 0.35) * w / K[0, 0] * z
        ty = rng.uniform(-0.35, 0.35) * h / K[1, 1] * z
        tvec = np.array([tx, ty, z]) - Rm @ cen
        corners = (
            np.array([[-1, -1, 0], [cols, -1, 0], [-1, rows, 0], [cols, rows, 0]], float) * square
        )
        cam = (Rm @ corners.T).T + tvec
        if np.any(cam[:, 2] <= 0.3 * z):
            continue
        p, _ = cv2.projectPoints(corners, rvec, tvec, K, np.zeros(5))
        p = p.reshape(-1, 2)
        if (
            p[:, 0].min() < 15
            or p[:, 1].min() < 15
            or p[:, 0].max() > w - 16
            or p[:, 1].max() > h - 16
        ):
            continue
        poses.append((rvec, tvec))
    return poses


def board_points(pattern=(9, 6), square=1.0):
    cols, rows = pattern
    g = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2).astype(float) * square
    return np.column_stack([g, np.zeros(len(g))])


def render_board(
    size,
    K,
    d,
    rvec,
    tvec,
    pattern=(9, 6),
    square=1.0,
    blur_px=0.7,
    noise=0.01,
    bits=8,
    seed=0,
    ss=2,
):
    """A chessboard photograph through the lens (K, d): rays from every sub-pixel, blur, area."""
    rng = np.random.default_rng(seed)
    w, h = size
    cols, rows = pattern
    xs = (np.arange(w * ss) + 0.5) / ss - 0.5
    ys = (np.arange(h * ss) + 0.5) / ss - 0.5
    X, Y = np.meshgrid(xs, ys)
    rays = to_rays(np.column_stack([X.ravel(), Y.ravel()]), K, d)
    Rm, _ = cv2.Rodrigues(np.asarray(rvec, float))
    t = np.asarray(tvec, float)
    # ray r = (x, y, 1) s; board plane: n . (p - t) = 0 with n = R e3; board coords = R^T (p - t)
    n = Rm[:, 2]
    rr = np.column_stack([rays, np.ones(len(rays))])
    s = (n @ t) / (rr @ n)
    p = rr * s[:, None] - t
    b = p @ Rm  # board coordinates (u, v, 0)
    u = b[:, 0] / square + 1.0
    v = b[:, 1] / square + 1.0
    inside = (u >= 0) & (u < cols + 1) & (v >= 0) & (v < rows + 1) & (s > 0)
    chk = (np.floor(u) + np.floor(v)) % 2 == 0
    val = np.where(inside, np.where(chk, 0.1, 0.9), 0.75)
    # a white margin of one square around the board
    margin = (u >= -1) & (u < cols + 2) & (v >= -1) & (v < rows + 2) & ~inside
    val = np.where(margin, 0.9, val).reshape(h * ss, w * ss)
    if blur_px > 0:
        val = cv2.GaussianBlur(val, (0, 0), blur_px * ss)
    img = val.reshape(h, ss, w, ss).mean(axis=(1, 3))
    return _noise_quantise(img, rng, noise, bits)


def write_boards(folder, n, seed, size, K, d, pattern=(9, 6), noise=0.01, bits=8, blur_px=0.7):
    os.makedirs(folder, exist_ok=True)
    files = []
    for i, (rvec, tvec) in enumerate(board_poses(n, seed, size, K, pattern)):
        img = render_board(
            size,
            K,
            d,
            rvec,
            tvec,
            pattern,
            noise=noise,
            bits=bits,
            seed=seed * 1000 + i,
            blur_px=blur_px,
        )
        f = os.path.join(folder, f"board{i:02d}.png")
        cv2.imwrite(f, img)
        files.append(f)
    return files


# ----------------------------------------------------------------------------- marks
def groove(n_px, a_px, half_len_px, width_px, blur_px, depth):
    """Intensity drop of a Gaussian groove (sigma width_px) of finite length, blurred (Gaussian)."""
    sig = math.hypot(width_px, blur_px)
    across = depth * (width_px / sig) * np.exp(-0.5 * (n_px / sig) ** 2)
    # ends: a step in depth along the mark, blurred
    along = 0.5 * (
        erf((a_px + half_len_px) / (math.sqrt(2) * blur_px))
        - erf((a_px - half_len_px) / (math.sqrt(2) * blur_px))
    )
    return across * along


def render_marks(
    size,
    K,
    d,
    marks,
    noise=0.004,
    bits=16,
    seed=0,
    ss=4,
    background=0.6,
    blur_px=1.0,
    width_px=1.6,
    depth=0.35,
):
    """An image of straight scribe marks through the lens.

    marks: list of (cx_px, cy_px, angle_deg, length_px) in the *pinhole* image (square pixels of
    size 1/fx in the normalised plane, measured from the principal point), angle from +x
    towards -y. Returns (image, truths) with the truth angle of each mark in degrees.
    """
    rng = np.random.default_rng(seed)
    w, h = size
    f = K[0, 0]
    img = np.full((h, w), background, float)
    truths = []
    for mx, my, ang, length in marks:
        th = math.radians(ang)
        dirv = np.array([math.cos(th), -math.sin(th)])  # y down
        nrm = np.array([dirv[1], -dirv[0]])
        c = np.array([mx, my]) / f  # normalised
        # the band on the sensor: the mark's points forward-projected
        ts = np.linspace(-length / 2 - 8, length / 2 + 8, 400) / f
        poly = to_sensor(c[None, :] + ts[:, None] * dirv[None, :], K, d)
        mask = np.zeros((h, w), np.uint8)
        cv2.polylines(
            mask,
            [np.round(poly * 4).astype(np.int32)],
            False,
            1,
            thickness=int(4 * (2 * (6 * math.hypot(width_px, blur_px) + 3))),
            shift=2,
        )
        iy, ix = np.nonzero(mask)
        if len(ix) == 0:
            truths.append(None)
            continue
        off = (np.arange(ss) + 0.5) / ss - 0.5
        ox, oy = np.meshgrid(off, off)
        sx = (ix[:, None] + ox.ravel()[None, :]).ravel()
        sy = (iy[:, None] + oy.ravel()[None, :]).ravel()
        rays = to_rays(np.column_stack([sx, sy]), K, d)
        rel = (rays - c) * f  # in pinhole pixels
        n_px = rel @ nrm
        a_px = rel @ dirv
        val = (
            groove(n_px, a_px, length / 2, width_px, blur_px, depth)
            .reshape(-1, ss * ss)
            .mean(axis=1)
        )
        img[iy, ix] -= val * background
        a = ang
        while a <= -90:
            a += 180
        while a > 90:
            a -= 180
        truths.append(a)
    return _noise_quantise(img, rng, noise, bits), truths


def render_scale(
    size,
    K,
    d,
    n_lines=20,
    pitch_px=22.0,
    angle_deg=3.0,
    length_px=160,
    centre=(0.0, 0.0),
    seed=0,
    noise=0.004,
    bits=16,
    dust=12,
    numerals=True,
):
    """A ruled scale: n_lines parallel lines at a fixed pitch (pinhole px), numerals, dust.

    Returns (image, truth angle [deg]).
    """
    th = math.radians(angle_deg)
    nrm = np.array([math.sin(th), math.cos(th)])
    marks = []
    for i in range(n_lines):
        o = (i - (n_lines - 1) / 2) * pitch_px
        ln = length_px * (1.4 if i % 5 == 0 else 1.0)
        marks.append((centre[0] + o * nrm[0], centre[1] + o * nrm[1], angle_deg, ln))
    img, truths = render_marks(size, K, d, marks, noise=noise, bits=bits, seed=seed)
    rng = np.random.default_rng(seed + 77)
    full = 2**bits - 1
    w, h = size
    cxp, cyp = K[0, 2], K[1, 2]
    imgf = img.astype(float)
    if numerals:
        # numerals beside every fifth line, beyond the lines' ends (in pinhole px, drawn on the
        # sensor near their projected position: text is not what is measured)
        dirv = np.array([math.cos(th), -math.sin(th)])
        for i in range(0, n_lines, 5):
            o = (i - (n_lines - 1) / 2) * pitch_px
            p = np.array([centre[0], centre[1]]) + o * nrm + dirv * (length_px * 0.7 + 25)
            q = to_sensor((p / K[0, 0])[None, :], K, d)[0]
            ink = np.zeros((h, w), np.uint8)
            cv2.putText(
                ink,
                str(i // 5),
                (int(q[0]) - 6, int(q[1]) + 6),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.5,
                255,
                1,
                cv2.LINE_AA,
            )
            imgf -= ink / 255.0 * 0.25 * full
    for _ in range(dust):
        x, y = rng.uniform(0, w), rng.uniform(0, h)
        r = rng.uniform(0.8, 2.5)
        spot = np.zeros((h, w), np.uint8)
        cv2.circle(spot, (int(x * 4), int(y * 4)), int(r * 4), 255, -1, cv2.LINE_AA, shift=2)
        imgf -= spot / 255.0 * 0.2 * full
    _ = (cxp, cyp)
    img = np.clip(np.round(imgf), 0, full).astype(img.dtype)
    return img, truths[0]


def write_png(path, img):
    cv2.imwrite(path, img)
    return path


def camera_json_from_cv(K, d, size, path, cov=None, u=None):
    """A minimal camera file (format 6) holding a model, e.g. a deliberately changed one."""
    doc = {
        "format": "axis-align/camera",
        "format_version": 6,
        "ok": True,
        "warnings": [],
        "camera_matrix": np.asarray(K).tolist(),
        "dist_coeffs": list(map(float, d)),
        "image_size": [int(size[0]), int(size[1])],
    }
    if cov is not None:
        doc["cov_params"] = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"]
        doc["cov"] = np.asarray(cov).tolist()
    if u is not None:
        doc["u"] = u
    with open(path, "w") as fh:
        json.dump(doc, fh)
    return path


def angle_diff_arcsec(a_deg, b_deg):
    d = (a_deg - b_deg + 90.0) % 180.0 - 90.0
    return d * 3600.0
