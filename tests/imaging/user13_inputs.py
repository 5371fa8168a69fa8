"""Independent user 13's renderer: scribe marks and ruled scales seen through a real lens.

Written without reading the project's code, synth/ or tests (only README, docs/, the JSON
schemas and ``--help``), so that it does not share the pipeline's assumptions.

Physics, in the order light takes it:

1. The object: a groove (a dark band of width ``w`` and depth ``c`` on a background ``b``,
   with soft ends) or a ruled scale (many grooves at a pitch, printed numerals, dust), on an
   object plane seen fronto-parallel. Object coordinates are "ideal pixels": the pinhole image
   with square pixels at the focal length ``fx`` (the frame whose angles the tool reports).
2. The optics: a Gaussian PSF of sigma ``s`` applied analytically (a band convolved with a
   Gaussian is a difference of erfs), optionally varying along the mark (defocus gradient).
3. The lens: each sensor sample point is mapped back through the camera's distortion to the
   object (``cv2.undistortPointsIter`` with the camera matrix and distortion coefficients),
   as a real camera images: the sensor samples a distorted picture. Pixel aspect and a
   principal point off-centre live in the camera matrix.
4. The pixel: the intensity is averaged over ``ss x ss`` points inside each pixel's area.
5. Vignetting (cos^4 of the field angle), shot noise (Poisson in electrons), read noise,
   column fixed-pattern noise, quantisation to 8/12/16 bit, optionally JPEG.

Truth: the mark's angle in the object plane, measured from +x towards -y (y down), the same
convention the docs give for ``angle_deg``.
"""

from __future__ import annotations

import functools
import glob
import os

import cv2
import numpy as np
from scipy.special import erf

REAL = os.environ.get("ALIGN_REAL_DATA", "/work/shared/data/real")
CHESS = os.path.join(REAL, "opencv-chessboard")
LINES = os.path.join(REAL, "opencv-lines")


@functools.lru_cache(maxsize=2)
def real_lens(side: str = "left"):
    """Calibrate the real lens with plain OpenCV (9x6 inner corners), not with the tool.

    Returns
    -------
    K : (3, 3) camera matrix [px]; dist : (5,) k1 k2 p1 p2 k3; size : (W, H) [px]; rms [px].
    """
    files = sorted(glob.glob(os.path.join(CHESS, f"{side}0*.jpg")))
    if not files:
        raise FileNotFoundError(CHESS)
    objp = np.zeros((54, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj, img, size = [], [], None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    for f in files:
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        size = g.shape[::-1]
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (5, 5), (-1, -1), crit)
        obj.append(objp)
        img.append(c)
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    return K, dist.ravel()[:5], tuple(size), float(rms)


def scaled_lens(K, dist, size, scale: float, aspect: float = 0.0, pp_shift=(0.0, 0.0),
                tangential=None):
    """The same lens on a sensor ``scale`` times larger, with a user's extra effects.

    aspect: fy/fx - 1; pp_shift: principal point moved [px]; tangential: (p1, p2) replacing
    the lens's own.
    """
    K2 = K.copy() * scale
    K2[2, 2] = 1.0
    K2[1, 1] = K2[0, 0] * (1.0 + aspect)
    K2[0, 2] += pp_shift[0]
    K2[1, 2] += pp_shift[1]
    d2 = np.array(dist, float).copy()
    if tangential is not None:
        d2[2], d2[3] = tangential
    return K2, d2, (int(round(size[0] * scale)), int(round(size[1] * scale)))


def _exact_ideal(u, v, K, dist):
    """Ideal (square at fx) coordinates of sensor points u, v: OpenCV's inverse + Newton."""
    pts = np.stack([np.ravel(u), np.ravel(v)], -1).astype(np.float64).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
    n = cv2.undistortPoints(pts, K, dist, R=np.eye(3), P=np.eye(3), criteria=crit)
    n = _refine(n.reshape(-1, 2), pts.reshape(-1, 2), K, dist)
    return n[:, 0] * K[0, 0] + K[0, 2], n[:, 1] * K[0, 0] + K[1, 2]


def object_points(K, dist, size, ss: int = 3, step: int = 2, box=None):
    """Object-plane (ideal pixel, square at fx) coordinates of ss x ss samples per pixel.

    The inverse distortion is solved exactly on a grid every ``step`` px and interpolated
    (cubic) at the samples: the map is smooth (its interpolation error is < 1e-4 px, checked
    by ``map_error``). Returns X, Y of shape (H, W, ss*ss).
    """
    from scipy.ndimage import map_coordinates
    W, H = size
    gu = np.arange(-12 * step, W + 12 * step + 1, step, dtype=float)
    gv = np.arange(-12 * step, H + 12 * step + 1, step, dtype=float)
    U, V = np.meshgrid(gu, gv)
    gx, gy = _exact_ideal(U, V, K, dist)
    gx, gy = gx.reshape(U.shape), gy.reshape(U.shape)
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    r0, r1, c0, c1 = box if box is not None else (0, H, 0, W)
    u = np.arange(c0, c1)[None, :, None, None] + sub[None, None, None, :]
    v = np.arange(r0, r1)[:, None, None, None] + sub[None, None, :, None]
    u, v = np.broadcast_arrays(u, v)
    coords = [(v.ravel() - gv[0]) / step, (u.ravel() - gu[0]) / step]
    shape = (r1 - r0, c1 - c0, ss * ss)
    X = map_coordinates(gx, coords, order=3).reshape(shape)
    Y = map_coordinates(gy, coords, order=3).reshape(shape)
    return X, Y


def map_error(K, dist, size, n=2000, seed=0):
    """Largest error [px] of object_points's interpolated map against the exact inverse."""
    rng = np.random.default_rng(seed)
    X, Y = _points(K, dist, size, 1)
    W, H = size
    c, r = rng.integers(0, W, n), rng.integers(0, H, n)
    ex, ey = _exact_ideal(c.astype(float), r.astype(float), K, dist)
    return float(max(np.abs(X[r, c, 0] - ex).max(), np.abs(Y[r, c, 0] - ey).max()))


def distort(n, K, dist):
    """Brown-Conrady (OpenCV's model): normalised ideal points -> sensor pixels."""
    k1, k2, p1, p2, k3 = (list(dist) + [0.0] * 5)[:5]
    x, y = n[:, 0], n[:, 1]
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 ** 3
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], -1)


def _refine(n, m, K, dist, iters=4):
    """Newton steps on distort(n) = m (OpenCV's iteration stops short far from the centre)."""
    h = 1e-6
    for _ in range(iters):
        f = distort(n, K, dist) - m
        jx = (distort(n + [h, 0], K, dist) - distort(n - [h, 0], K, dist)) / (2 * h)
        jy = (distort(n + [0, h], K, dist) - distort(n - [0, h], K, dist)) / (2 * h)
        det = jx[:, 0] * jy[:, 1] - jy[:, 0] * jx[:, 1]
        dx = (jy[:, 1] * f[:, 0] - jy[:, 0] * f[:, 1]) / det
        dy = (-jx[:, 1] * f[:, 0] + jx[:, 0] * f[:, 1]) / det
        n = n - np.stack([dx, dy], -1)
    return n


def _band(d, w, s):
    """A band of width w [px] centred on d = 0, blurred by a Gaussian of sigma s [px]."""
    r = np.sqrt(2.0) * s
    return 0.5 * (erf((d + w / 2) / r) - erf((d - w / 2) / r))


def groove(X, Y, centre, angle_rad, length, width=3.0, sigma=1.0, sigma_end=None,
           sagitta=0.0):
    """Depth [0..1] of a straight (or bowed) groove at object points X, Y.

    centre: (x, y) ideal px; angle from +x towards -y; sagitta: bow [px] at the middle,
    towards +normal (0 at both ends; the chord is the truth); sigma_end: the blur at the
    mark's +t end (a defocus gradient along the mark, linear from the -t end's sigma).
    """
    c, s_ = np.cos(angle_rad), np.sin(angle_rad)
    dx, dy = X - centre[0], Y - centre[1]
    t = dx * c - dy * s_                # along the mark
    d = dx * s_ + dy * c                # across (normal (sin a, cos a))
    if sagitta:
        d = d - sagitta * (1.0 - (2.0 * t / length) ** 2)
    sig = sigma if sigma_end is None else sigma + (sigma_end - sigma) * np.clip(
        (t / length) + 0.5, 0.0, 1.0)
    across = _band(d, width, sig)
    along = _band(t, length, sig)
    return across * along


def expose(signal, rng, full_well=20000.0, read_e=8.0, bits=8, fpn=0.0, contrast=1.0,
           jpeg_quality=None, vignette=None):
    """Signal [0..1 of full scale] -> DN with shot, read and column fixed-pattern noise.

    fpn: column offsets' sigma as a fraction of ``contrast`` (both in signal units).
    vignette: (K, strength): cos^4 falloff of the field angle, mixed by strength.
    """
    H, W = signal.shape
    if vignette is not None:
        K, strength = vignette
        yy, xx = np.mgrid[0:H, 0:W]
        r2 = ((xx - K[0, 2]) ** 2 + (yy - K[1, 2]) ** 2) / K[0, 0] ** 2
        signal = signal * ((1 - strength) + strength / (1 + r2) ** 2)
    if fpn:
        signal = signal + rng.normal(0, fpn * contrast, W)[None, :]
    e = rng.poisson(np.clip(signal, 0, None) * full_well).astype(float)
    e += rng.normal(0, read_e, e.shape)
    full = 2 ** bits - 1
    dn = np.clip(np.round(e / full_well * full), 0, full)
    out = dn.astype(np.uint8 if bits == 8 else np.uint16)
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return out


def mark_image(lens, rng, centre, angle_rad, length=300.0, width=3.0, sigma=1.0,
               sigma_end=None, sagitta=0.0, background=0.55, depth=0.3, ss=3, **noise):
    """One dark groove imaged through ``lens`` = (K, dist, size). Returns a DN image."""
    K, dist, size = lens
    X1, Y1 = _points(K, dist, size, 1)
    sl = _near(X1, Y1, centre, angle_rad, length, 6 * max(sigma, sigma_end or 0) + width
               + abs(sagitta) + 2)
    X, Y = object_points(np.asarray(K), np.asarray(dist), size, ss,
                         box=(sl[0].start, sl[0].stop, sl[1].start, sl[1].stop))
    g = np.zeros(X1.shape[:2])
    g[sl] = groove(X, Y, centre, angle_rad, length, width, sigma, sigma_end,
                   sagitta).mean(-1)
    signal = background * (1.0 - depth * g)
    return expose(signal, rng, contrast=background * depth, **noise)


def _near(X, Y, centre, angle_rad, length, reach):
    """The rows and columns (slices) whose pixels lie within reach of the mark's rectangle."""
    c, s_ = np.cos(angle_rad), np.sin(angle_rad)
    dx, dy = X[..., 0] - centre[0], Y[..., 0] - centre[1]
    m = (np.abs(dx * c - dy * s_) < length / 2 + reach) & (np.abs(dx * s_ + dy * c) < reach)
    rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
    if rows.size == 0:
        return (slice(0, 0), slice(0, 0))
    return (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))


@functools.lru_cache(maxsize=4)
def _points_cached(key):
    K, dist, size, ss = key
    return object_points(np.array(K).reshape(3, 3), np.array(dist), size, ss)


def _points(K, dist, size, ss):
    key = (tuple(np.asarray(K, float).ravel()), tuple(np.asarray(dist, float).ravel()),
           tuple(size), ss)
    return _points_cached(key)


def scale_image(lens, rng, angle_rad, centre, n_lines=9, pitch=60.0, long_len=240.0,
                short_len=160.0, width=2.5, sigma=1.0, background=0.6, depth=0.35,
                numerals=True, dust=6, ss=3, **noise):
    """A ruled scale: n_lines grooves at ``pitch`` (every 5th long), numerals, dust.

    Returns the image and the truth: the lines' centres (ideal px) and the angle.
    """
    K, dist, size = lens
    X, Y = _points(K, dist, size, ss)
    c, s_ = np.cos(angle_rad), np.sin(angle_rad)
    normal = np.array([s_, c])
    along = np.array([c, -s_])
    depth_map = np.zeros(X.shape)
    centres = []
    for i in range(n_lines):
        k = i - (n_lines - 1) / 2
        L = long_len if i % 5 == 0 else short_len
        # the lines share one end (a scale's baseline) on the -t side
        cc = np.array(centre) + k * pitch * normal + (L - long_len) / 2 * along
        centres.append(cc)
        depth_map = np.maximum(depth_map, groove(X, Y, cc, angle_rad, L, width, sigma))
    signal = background * (1.0 - depth * depth_map.mean(-1))
    H, W = signal.shape
    if numerals:
        txt = np.zeros((H, W), np.uint8)
        for i in range(0, n_lines, 5):
            k = i - (n_lines - 1) / 2
            p = np.array(centre) + k * pitch * normal - (long_len / 2 + 25) * along
            cv2.putText(txt, str(i), (int(p[0]) - 8, int(p[1]) + 8), cv2.FONT_HERSHEY_SIMPLEX,
                        0.8, 255, 2, cv2.LINE_AA)
        txt = cv2.GaussianBlur(txt.astype(float) / 255, (0, 0), sigma)
        signal = signal * (1.0 - depth * txt)
    for _ in range(dust):
        x, y, r = rng.uniform(0, W), rng.uniform(0, H), rng.uniform(1.5, 4)
        yy, xx = np.ogrid[0:H, 0:W]
        signal = signal * (1.0 - 0.5 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * r * r)))
    img = expose(signal, rng, contrast=background * depth, **noise)
    return img, {"angle_rad": angle_rad, "centres": np.array(centres), "pitch": pitch}


def camera_json(K, dist, size, path):
    """A camera model in the layout docs/formats.md gives (camera_matrix, dist_coeffs, size).

    Used only for lenses the tool's own 'align camera' cannot see (a scaled sensor); the
    model is exact, so no u beyond 0 is claimed in it.
    """
    import json
    doc = {"format": "axis-align/camera", "camera_matrix": np.asarray(K).tolist(),
           "dist_coeffs": np.asarray(dist).tolist(), "image_size": list(size)}
    with open(path, "w") as f:
        json.dump(doc, f)
    return path
