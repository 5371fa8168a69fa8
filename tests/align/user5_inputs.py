"""Independent generators of user5 (seeded): images through a physical lens, chessboards,
static tumbles of a triad with effects, and session folders.

Nothing here imports the pipeline or ``synth``: the physics is written from scratch.

Camera convention (OpenCV): a scene point is a point of the *ideal* (undistorted, pinhole)
image in pixels, ``p = K · n`` with ``n`` the normalised ray.  A sensor pixel at ``s`` sees the
scene point ``undistort(s)``.  Each pixel integrates the scene over its area (n×n supersamples,
each mapped through the lens separately), then the optics blur (Gaussian PSF on the sensor),
vignetting, shot and read noise and quantisation are applied.

Angle convention of the tool (docs/commands/marks.md): from +x towards −y (counter-clockwise
as displayed), in (−90°, 90°], of the undistorted (pinhole) image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.special import erf

ARCSEC = np.pi / 180 / 3600


# ---------------------------------------------------------------------------------- images

@dataclass(frozen=True)
class Mark:
    """A straight (or bowed) groove in the ideal image.

    x0, y0: centre [px, ideal image]; angle_deg: tool convention; length, width [px];
    depth: fraction of the local level removed at the groove's bottom (>0 dark groove);
    bow_px: sagitta of a circular bend (perpendicular, at the middle) [px].
    """

    x0: float
    y0: float
    angle_deg: float
    length: float = 300.0
    width: float = 4.0
    depth: float = 0.5
    bow_px: float = 0.0


@dataclass(frozen=True)
class Lens:
    """OpenCV camera: f [px], principal point offset from the image centre [px], dist coeffs
    (k1, k2, p1, p2, k3) in OpenCV's normalised convention."""

    f: float = 600.0
    dcx: float = 0.0
    dcy: float = 0.0
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)
    fy_over_fx: float = 1.0

    def matrix(self, w: int, h: int) -> np.ndarray:
        return np.array([[self.f, 0, (w - 1) / 2 + self.dcx],
                         [0, self.f * self.fy_over_fx, (h - 1) / 2 + self.dcy],
                         [0, 0, 1]], float)


@dataclass(frozen=True)
class Scene:
    width: int = 640
    height: int = 480
    marks: tuple = ()
    lens: Lens = field(default_factory=Lens)
    level: float = 0.7            # background as a fraction of full scale
    blur_px: float = 1.0          # optics PSF sigma on the sensor [px]
    vignette: float = 0.0         # relative fall-off at the corner (cos^4-like, quadratic)
    stripes_amp: float = 0.0      # striped background (fraction of level)
    stripes_period: float = 23.0  # [px, ideal image]
    stripes_deg: float = 30.0     # direction of the stripes (tool convention)
    texture_amp: float = 0.0      # smooth random texture (fraction of level)
    read_noise: float = 1.0       # [DN of 8 bit]
    gain: float = 0.05            # shot noise: var += gain * signal[DN]
    bits: int = 8
    seed: int = 0
    supersample: int = 3


def _ideal_coords(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Ideal-image coordinates seen by every supersample of every sensor pixel, shape
    (h, w, n, n) (rows: y-subsample, last: x-subsample).

    With a lens: the exact (iterated to 1e-12) undistortion at every pixel corner, bilinear
    inside each pixel — the map's curvature over one pixel is ~1e-4 px
    (``exact_map_error_px`` checks it)."""
    n = scene.supersample
    w, h = scene.width, scene.height
    sub = (np.arange(n) + 0.5) / n - 0.5
    K = scene.lens.matrix(w, h)
    dist = np.asarray(scene.lens.dist, float)
    if not np.any(dist != 0):
        X = np.arange(w)[None, :, None, None] + sub[None, None, None, :]
        Y = np.arange(h)[:, None, None, None] + sub[None, None, :, None]
        return (np.broadcast_to(X, (h, w, n, n)).astype(float),
                np.broadcast_to(Y, (h, w, n, n)).astype(float))
    gx = np.arange(w + 1) - 0.5
    gy = np.arange(h + 1) - 0.5
    GX, GY = np.meshgrid(gx, gy)
    g = _undistort_exact(np.stack([GX.ravel(), GY.ravel()], 1), K, dist)
    outs = []
    for m in (g[:, 0].reshape(GX.shape), g[:, 1].reshape(GX.shape)):
        a00, a01, a10, a11 = m[:-1, :-1], m[:-1, 1:], m[1:, :-1], m[1:, 1:]
        res = np.empty((h, w, n, n))
        for iy, sy in enumerate(sub):
            ty = sy + 0.5
            for ix, sx in enumerate(sub):
                tx = sx + 0.5
                res[:, :, iy, ix] = ((a00 * (1 - tx) + a01 * tx) * (1 - ty)
                                     + (a10 * (1 - tx) + a11 * tx) * ty)
        outs.append(res)
    return outs[0], outs[1]


def _undistort_exact(pts: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    return cv2.undistortPoints(pts.reshape(-1, 1, 2), K, dist, None, None, K,
                               crit).reshape(-1, 2)


def exact_map_error_px(lens: Lens, w: int, h: int, n: int = 3, samples: int = 2000,
                       seed: int = 0) -> float:
    """Largest difference between the renderer's per-supersample map and the exact
    undistortion at random supersamples [px]: the renderer's own accuracy."""
    rng = np.random.default_rng(seed)
    X, Y = _ideal_coords(Scene(width=w, height=h, lens=lens, supersample=n))
    idx = rng.integers(0, [h, w, n, n], size=(samples, 4))
    sub = (np.arange(n) + 0.5) / n - 0.5
    pts = np.stack([idx[:, 1] + sub[idx[:, 3]], idx[:, 0] + sub[idx[:, 2]]], 1)
    ex = _undistort_exact(pts, lens.matrix(w, h), np.asarray(lens.dist, float))
    got = np.stack([X[idx[:, 0], idx[:, 1], idx[:, 2], idx[:, 3]],
                    Y[idx[:, 0], idx[:, 1], idx[:, 2], idx[:, 3]]], 1)
    return float(np.abs(got - ex).max())


def _groove(u: np.ndarray, width: float, soft: float = 0.35) -> np.ndarray:
    """Depth profile of a flat-bottomed groove of full width ``width`` with soft walls."""
    a = (u + width / 2) / (np.sqrt(2) * soft)
    b = (u - width / 2) / (np.sqrt(2) * soft)
    return 0.5 * (erf(a) - erf(b))


def mark_direction(angle_deg: float) -> np.ndarray:
    a = np.deg2rad(angle_deg)
    return np.array([np.cos(a), -np.sin(a)])


def render(scene: Scene) -> np.ndarray:
    """The image as the sensor records it (uint8 or uint16)."""
    rng = np.random.default_rng(scene.seed)
    X, Y = _ideal_coords(scene)
    w, h = scene.width, scene.height
    refl = np.ones_like(X)
    if scene.stripes_amp:
        d = mark_direction(scene.stripes_deg)
        nrm = np.array([-d[1], d[0]])
        refl *= 1 + scene.stripes_amp * np.sin(2 * np.pi * (X * nrm[0] + Y * nrm[1])
                                               / scene.stripes_period)
    if scene.texture_amp:
        tex = gaussian_filter(rng.normal(size=(h // 4 + 2, w // 4 + 2)), 2.0)
        tex /= tex.std()
        tx = cv2.resize(tex.astype(np.float32), (w * 1, h * 1), interpolation=cv2.INTER_CUBIC)
        refl *= (1 + scene.texture_amp * tx)[:, :, None, None]
    for m in scene.marks:
        d = mark_direction(m.angle_deg)
        nrm = np.array([-d[1], d[0]])
        rx, ry = X - m.x0, Y - m.y0
        t = rx * d[0] + ry * d[1]
        u = rx * nrm[0] + ry * nrm[1]
        if m.bow_px:
            # circular arc of sagitta bow at the middle, chord = length
            half = m.length / 2
            rad = (half ** 2 + m.bow_px ** 2) / (2 * m.bow_px)
            u = u - (m.bow_px - (rad - np.sqrt(np.maximum(rad ** 2 - t ** 2, 0.0))))
        # Beyond width/2 + 8 sqrt(2) 0.35 px across the groove both erf of its walls are
        # exactly +-1 (|argument| >= 8): the factor there is exactly 1, so only the
        # sub-samples nearer are multiplied (the same image bit for bit; NaN stays in).
        near = ~(np.abs(u) > m.width / 2 + 8 * np.sqrt(2) * 0.35)
        t, u = t[near], u[near]
        along = 0.5 * (erf((t + m.length / 2) / 1.0) - erf((t - m.length / 2) / 1.0))
        refl[near] *= 1 - m.depth * _groove(u, m.width) * along
    img = refl.mean(axis=(2, 3))  # pixel integration
    if scene.blur_px:
        img = gaussian_filter(img, scene.blur_px, mode="nearest")
    if scene.vignette:
        yy, xx = np.mgrid[0:h, 0:w]
        r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2
                                                                   + ((h - 1) / 2) ** 2)
        img = img * (1 - scene.vignette * r2)
    full = 2 ** scene.bits - 1
    scale = full / 255.0
    sig = img * scene.level * 255.0  # in 8-bit DN
    var = scene.read_noise ** 2 + scene.gain * sig
    sig = sig + rng.normal(size=sig.shape) * np.sqrt(var)
    out = np.clip(np.round(sig * scale), 0, full)
    return out.astype(np.uint8 if scene.bits == 8 else np.uint16)


def write_image(path: Path, img: np.ndarray, jpeg_quality: int | None = None) -> Path:
    path = Path(path)
    if jpeg_quality is not None:
        cv2.imwrite(str(path), img, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    else:
        cv2.imwrite(str(path), img)
    return path


def wrap_deg(a: float) -> float:
    """Direction difference wrapped to (-90, 90]."""
    return (a + 90.0) % 180.0 - 90.0


# ---------------------------------------------------------------------------- chessboards

def render_chessboard(lens: Lens, w: int, h: int, rvec, tvec, cols: int = 9, rows: int = 6,
                      square: float = 1.0, seed: int = 0, blur_px: float = 0.7,
                      noise: float = 1.5, n: int = 3) -> np.ndarray:
    """A (cols+1)×(rows+1)-square board (``cols×rows`` inner corners) in the plane z = 0 of the
    board frame, posed by (rvec, tvec), seen through ``lens``; 8-bit."""
    rng = np.random.default_rng(seed)
    sc = Scene(width=w, height=h, lens=lens, supersample=n)
    X, Y = _ideal_coords(sc)
    K = lens.matrix(w, h)
    xn = (X - K[0, 2]) / K[0, 0]
    yn = (Y - K[1, 2]) / K[1, 1]
    Rm, _ = cv2.Rodrigues(np.asarray(rvec, float))
    t = np.asarray(tvec, float).ravel()
    # ray r = (xn, yn, 1) s ; board point B: Rm B + t = r s, B_z = 0
    Rt = Rm.T
    # B = Rt (r s - t); B_z = 0 -> s = (Rt t)_z / (Rt r)_z
    rtt = Rt @ t
    rz = Rt[2, 0] * xn + Rt[2, 1] * yn + Rt[2, 2]
    s = rtt[2] / rz
    bx = Rt[0, 0] * xn * s + Rt[0, 1] * yn * s + Rt[0, 2] * s - rtt[0]
    by = Rt[1, 0] * xn * s + Rt[1, 1] * yn * s + Rt[1, 2] * s - rtt[1]
    # inner corners at integer multiples of square, 0..cols-1; board squares from -1..cols
    i = np.floor(bx / square)
    j = np.floor(by / square)
    inside = (i >= -1) & (i <= cols - 1) & (j >= -1) & (j <= rows - 1) & (s > 0)
    white = ((i + j) % 2 == 0)
    val = np.where(inside, np.where(white, 0.9, 0.1), 0.55)
    img = val.mean(axis=(2, 3))
    img = gaussian_filter(img, blur_px)
    img = img * 255 + rng.normal(size=img.shape) * noise
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def chessboard_views(lens: Lens, w: int, h: int, count: int = 12, seed: int = 0,
                     cols: int = 9, rows: int = 6):
    """Seeded board poses that fill the frame at various tilts; yields images."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        tilt = rng.uniform(-0.4, 0.4, size=2)
        rvec = np.array([tilt[0], tilt[1], rng.uniform(-0.2, 0.2)])
        dist = rng.uniform(13.0, 16.0)
        cxb, cyb = (cols - 1) / 2, (rows - 1) / 2
        Rm, _ = cv2.Rodrigues(rvec)
        corner = k % 5  # the centre, then each quadrant in turn: the lens is seen to the corners
        sx, sy = [(0, 0), (1, 1), (-1, 1), (1, -1), (-1, -1)][corner]
        off = np.array([sx * 3.2 + rng.uniform(-0.5, 0.5), sy * 2.3 + rng.uniform(-0.4, 0.4),
                        dist])
        tvec = off - Rm @ np.array([cxb, cyb, 0.0])
        out.append(render_chessboard(lens, w, h, rvec, tvec, cols, rows, seed=seed * 100 + k))
    return out


# ----------------------------------------------------------------------------- tumbles

CUBE14 = ([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
          + [(sx, sy, sz) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)])


@dataclass(frozen=True)
class Triad:
    """u_i = k_i (s_i · a + b_i) + cross + ... [V]; s_i unit sensing axes in the fixture frame.

    k: scale factors [V/g]; axes: 3×3 rows s_i; bias [g]; k2 [1/g] (u_i gets k_i K2_i x_i²);
    cross: dict ((i, j, l) -> K [1/g]) adds k_i K x_j x_l; drift_bias [g/s];
    scale_drift [1/s]; hyst [g] (± by sign of the last change of axis i's input);
    temp_bias [g/K] with temperature ramp.
    """

    k: tuple = (2.41, 2.38, 2.45)
    axes: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    bias: tuple = (8e-4, -5e-4, 3e-4)
    k2: tuple = (0.0, 0.0, 0.0)
    cross: tuple = ()
    drift_bias: tuple = (0.0, 0.0, 0.0)
    scale_drift: float = 0.0
    hyst: tuple = (0.0, 0.0, 0.0)

    def S(self) -> np.ndarray:
        a = np.asarray(self.axes, float)
        return a / np.linalg.norm(a, axis=1, keepdims=True)


def small_axes(beta_urad: tuple = (1700.0, -900.0, 1200.0), seed: int = 0) -> tuple:
    """Non-orthogonal sensing axes: x exact, y tilted towards x, z tilted towards x and y."""
    bx, by, bz = (np.asarray(beta_urad) * 1e-6)
    sx = np.array([1.0, 0, 0])
    sy = np.array([bx, 1.0, 0])
    sz = np.array([by, bz, 1.0])
    return tuple(tuple(v / np.linalg.norm(v)) for v in (sx, sy, sz))


def tumble(triad: Triad, poses=None, samples: int = 200, noise_g: float = 1e-5,
           seed: int = 0, dt_pose: float = 10.0, rate: float = 100.0, tilt_err_deg: float = 0.3,
           bursts: int = 0, labels: bool = False, rw_g: float = 0.0,
           sine_bias=(0.0, 600.0), order=None):
    """Rows (pose, ux, uy, uz, t) and the true up-vectors, in V.  Poses are attitudes of the
    fixture; each is placed with a random error (tilt_err_deg) since it is never exact.

    rw_g: random-walk bias per sample [g] (all axes, independent); sine_bias = (amplitude [g],
    period [s]): a thermal cycle of the bias no column records; order: a permutation of the
    poses (the order they are visited in)."""
    rng = np.random.default_rng(seed)
    poses = CUBE14 if poses is None else poses
    if order is not None:
        poses = [poses[i] for i in order]
    walk = np.zeros(3)
    S = triad.S()
    k = np.asarray(triad.k)
    rows, ups = [], []
    last_a = np.zeros(3)
    side = np.zeros(3)
    t0 = 0.0
    names = ["+x", "-x", "+y", "-y", "+z", "-z"]
    for p, d in enumerate(poses):
        a = np.asarray(d, float)
        a = a / np.linalg.norm(a)
        e = rng.normal(size=3) * np.deg2rad(tilt_err_deg)
        Rm, _ = cv2.Rodrigues(e)
        a = Rm @ a
        ups.append(a)
        x = S @ a  # inputs along the sensing axes [g]
        ch = x - (S @ last_a)
        side = np.where(np.abs(ch) > 0.1, np.sign(ch), side)
        last_a = a
        t = t0 + np.arange(samples) / rate
        tm = t.mean()
        xi = x + np.asarray(triad.bias) + np.asarray(triad.drift_bias) * tm
        xi = xi + np.asarray(triad.hyst) * side
        xi = xi + np.asarray(triad.k2) * x ** 2
        for (i, j, m), kk in triad.cross:
            xi[i] += kk * x[j] * x[m]
        ks = k * (1 + triad.scale_drift * tm)
        extra = np.zeros((samples, 3))
        if rw_g:
            steps = np.cumsum(rng.normal(size=(samples, 3)) * rw_g, axis=0)
            extra += walk + steps
            walk = walk + steps[-1]
        if sine_bias[0]:
            extra += sine_bias[0] * np.sin(2 * np.pi * t / sine_bias[1])[:, None]
        u = ks[None, :] * (xi[None, :] + extra + rng.normal(size=(samples, 3)) * noise_g)
        if bursts:
            for _ in range(bursts):
                s0 = rng.integers(0, samples - 10)
                u[s0:s0 + 10] += rng.normal(size=(10, 3)) * noise_g * 30 * k
        lab = names[p] if (labels and p < 6) else f"P{p:02d}"
        for s in range(samples):
            rows.append((lab, *u[s], t[s]))
        t0 = t[-1] + dt_pose
    return rows, np.array(ups)


def write_tumble(path: Path, rows, with_t: bool = True) -> Path:
    with open(path, "w") as fh:
        fh.write("pose,ux,uy,uz,t\n" if with_t else "pose,ux,uy,uz\n")
        for r in rows:
            if with_t:
                fh.write(f"{r[0]},{r[1]:.9f},{r[2]:.9f},{r[3]:.9f},{r[4]:.4f}\n")
            else:
                fh.write(f"{r[0]},{r[1]:.9f},{r[2]:.9f},{r[3]:.9f}\n")
    return Path(path)


def lens_residual_px(lens: Lens, w: int, h: int) -> float:
    """Largest round-trip error of the renderer's undistortion (distort(undistort(s)) - s) [px]
    on a grid: the renderer's own accuracy."""
    xs, ys = np.meshgrid(np.linspace(0, w - 1, 33), np.linspace(0, h - 1, 25))
    pts = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64)
    K = lens.matrix(w, h)
    dist = np.asarray(lens.dist, float)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    und = cv2.undistortPoints(pts.reshape(-1, 1, 2), K, dist, None, None, None, crit)
    obj = np.concatenate([und.reshape(-1, 2), np.ones((len(pts), 1))], 1)
    back, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, dist)
    return float(np.abs(back.reshape(-1, 2) - pts).max())


# ----------------------------------------------------------------------------- sessions

E_NAMES = {(0, 1): "E_xY", (0, 2): "E_xZ", (1, 0): "E_yX", (1, 2): "E_yZ", (2, 0): "E_zX",
           (2, 1): "E_zY"}


def axes_from_E(E_arcsec: dict) -> np.ndarray:
    """Unit sensing axes s_i (rows, platform frame) whose E_ij = s_ij / s_ii are given [″]."""
    M = np.eye(3)
    for (i, j), name in E_NAMES.items():
        M[i, j] = E_arcsec.get(name, 0.0) * ARCSEC
    return M / np.linalg.norm(M, axis=1, keepdims=True)


PLATFORM_POSES = {"L000": ((0, 0, 1), 0.0), "L090": ((0, 0, 1), 90.0),
                  "L180": ((0, 0, 1), 180.0), "L270": ((0, 0, 1), 270.0),
                  "Xup": ((1, 0, 0), None), "Xdn": ((-1, 0, 0), None),
                  "Yup": ((0, 1, 0), None), "Ydn": ((0, -1, 0), None)}


def write_plain_session(folder: Path, E_arcsec: dict, seed: int = 0, noise_g: float = 1e-5,
                        tolerance: str | None = None, k=(2.41, 2.38, 2.45),
                        bias=(8e-4, -5e-4, 3e-4), samples: int = 200,
                        platform_noise_g: float | None = None,
                        platform_bias_shift=(0.0, 0.0, 0.0), tumble_kw=None) -> dict:
    """A session of a tumble and platform static readings (no images, no goniometer), from
    one physical triad whose axes give ``E_arcsec``; returns the truth."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    S = axes_from_E(E_arcsec)
    tr = Triad(k=k, axes=tuple(map(tuple, S)), bias=bias)
    rows, _ = tumble(tr, seed=seed, noise_g=noise_g, samples=samples, **(tumble_kw or {}))
    write_tumble(folder / "tumble.csv", rows)
    rng = np.random.default_rng(seed + 7919)
    pn = noise_g if platform_noise_g is None else platform_noise_g
    kk = np.asarray(k)
    with open(folder / "platform.csv", "w") as fh:
        fh.write("pose,ux,uy,uz\n")
        for lab, (up, _table) in PLATFORM_POSES.items():
            a = np.asarray(up, float)
            x = S @ a + np.asarray(bias) + np.asarray(platform_bias_shift)
            u = kk * (x[None, :] + rng.normal(size=(samples, 3)) * pn)
            for r in u:
                fh.write(f"{lab},{r[0]:.9f},{r[1]:.9f},{r[2]:.9f}\n")
    poses = "\n".join(
        f'{lab} = {{ up = "{"+-"[up[[0, 1, 2].index(int(np.argmax(np.abs(up))))] < 0]}'
        f'{"XYZ"[int(np.argmax(np.abs(up)))]}"'
        + (f", table_deg = {t}" if t is not None else "") + " }"
        for lab, (up, t) in PLATFORM_POSES.items())
    text = (f'name = "u5-{seed}"\n\n[calibration]\nstatic = "tumble.csv"\n\n'
            f'[platform]\nstatic = "platform.csv"\n[platform.poses]\n{poses}\n')
    if tolerance:
        text += f"\n[tolerance]\n{tolerance}\n"
    (folder / "session.toml").write_text(text)
    return {name: E_arcsec.get(name, 0.0) for name in E_NAMES.values()}


def write_pose_means(path: Path, rows) -> Path:
    """The tumble as one row per pose (its mean), no time column: the plainest format."""
    labels = list(dict.fromkeys(r[0] for r in rows))
    arr = np.array([r[1:4] for r in rows], float)
    lab = np.array([r[0] for r in rows])
    with open(path, "w") as fh:
        fh.write("pose,ux,uy,uz\n")
        for name in labels:
            m = arr[lab == name].mean(axis=0)
            fh.write(f"{name},{m[0]:.9f},{m[1]:.9f},{m[2]:.9f}\n")
    return Path(path)


VIEWS = {"A": ("+X", "+Z"), "Ar": ("-X", "+Z"), "B": ("+Y", "+Z"), "Br": ("-Y", "+Z")}
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _vec(name: str) -> np.ndarray:
    v = np.zeros(3)
    v[_AXIS[name[1]]] = 1.0 if name[0] == "+" else -1.0
    return v


def add_images(folder: Path, E_arcsec: dict, seed: int = 0, scene_kw=None,
               width: int = 480, height: int = 360) -> None:
    """Eight mark images (x, z in views A/Ar along Y; y, z in B/Br along X), one mark each, the
    mark's direction in the image that of the housing's axis (right, up) — my own projection;
    cameras declared distortion-free."""
    folder = Path(folder)
    S = axes_from_E(E_arcsec)
    rng = np.random.default_rng(seed + 104729)
    entries = []
    plan = [("x", "A"), ("z", "A"), ("x", "Ar"), ("z", "Ar"),
            ("y", "B"), ("z", "B"), ("y", "Br"), ("z", "Br")]
    for k, (housing, view) in enumerate(plan):
        r, u = (_vec(v) for v in VIEWS[view])
        s = S["xyz".index(housing)]
        ang = float(np.degrees(np.arctan2(s @ u, s @ r)))
        nominal = "vertical" if housing == "z" else "horizontal"
        sc = Scene(width=width, height=height,
                   marks=(Mark(width / 2 + rng.uniform(-15, 15), height / 2 + rng.uniform(-15, 15),
                               ang, 0.6 * min(width, height)),),
                   seed=seed * 100 + k, **(scene_kw or {}))
        name = f"{housing}_{view}.png"
        write_image(folder / name, render(sc))
        entries.append(f'[[images]]\nfile = "{name}"\nhousing = "{housing}"\nview = "{view}"\n'
                       f'nominal = "{nominal}"\n')
    zero = "".join(f"lens_{k} = 0.0\n" for k in ("k1", "k2", "p", "aspect", "pp_px"))
    text = (folder / "session.toml").read_text()
    text += f"\n[cameras.A]\n{zero}[cameras.B]\n{zero}"
    for v, (r, u) in VIEWS.items():
        text += f'[views.{v}]\ncamera = "{v[0]}"\nright = "{r}"\nup = "{u}"\n'
    text += "\n" + "\n".join(entries)
    (folder / "session.toml").write_text(text)
