"""Independent user 8's generators: scribe-mark photographs and accelerometer tumbles.

Imports nothing from the project. The images are rendered from physics as I understand it, not
from the tool's model: a groove of my own profile (a rounded, asymmetric V: one wall steeper
than the other, the bottom rounded) lying on a flat housing face, seen through a Brown-Conrady
lens that I calibrated myself from the real chessboard photographs (``cv2.calibrateCamera`` on
``opencv-chessboard/left*.jpg``, corners refined by ``cv2.cornerSubPix``), each pixel's area
integrated by sub-sampling, optical blur (optionally growing along the mark: defocus of a face
not square to the axis), vignetting, shot and read noise, quantisation to 8/12/16 bits, JPEG.

The truth of a mark's angle is its direction in the normalised (pinhole, square-pixel) plane:
the physical direction on a fronto-parallel face. Angles counter-clockwise as displayed (x
right, y down: direction (cos a, -sin a) in pixels).

The tumbles are static poses of a triad u = K_pos/neg (C g + non-linear terms) + b + noise with
effects of real sensors: a scale factor that differs for +g and -g (asymmetric scale), a bias
step with temperature, quantisation, vibration.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
CHESS = REAL / "opencv-chessboard"
SIZE = (640, 480)


@functools.lru_cache(maxsize=4)
def chessboard_lens(side: str = "left") -> tuple[np.ndarray, np.ndarray]:
    """(K 3x3, D 5) from cv2.calibrateCamera on the real photographs of one camera."""
    objp = np.zeros((54, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj, img = [], []
    for f in sorted(CHESS.glob(f"{side}*.jpg")):
        g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if ok:
            c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3))
            obj.append(objp)
            img.append(c)
    _, k, d, _, _ = cv2.calibrateCamera(obj, img, SIZE, None, None)
    return k, d.ravel()[:5]


def undistort(xd: np.ndarray, yd: np.ndarray, k: np.ndarray, d: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Sensor pixels -> normalised pinhole coordinates, by fixed-point iteration of OpenCV's
    forward model (written here because cv2.undistortPoints' signature moved in OpenCV 5 and
    is slow on millions of points)."""
    k1, k2, p1, p2, k3 = d
    y0 = (yd - k[1, 2]) / k[1, 1]
    x0 = (xd - k[0, 2] - k[0, 1] * y0) / k[0, 0]
    x, y = x0.copy(), y0.copy()
    for _ in range(30):
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (x0 - dx) / rad
        y = (y0 - dy) / rad
    return x, y


@functools.lru_cache(maxsize=8)
def _corner_map(kb: bytes, db: bytes, w: int, h: int, shake: tuple = (0.0, 1.0, 0.0)
                ) -> tuple[np.ndarray, np.ndarray]:
    k = np.frombuffer(kb).reshape(3, 3)
    d = np.frombuffer(db)
    yy, xx = np.mgrid[0:h + 1, 0:w + 1].astype(float) - 0.5  # pixel corners
    amp, period, phase = shake
    # rolling shutter: row y is exposed at a later time, when the camera had moved by
    # amp sin(2 pi y / period + phase) pixels along x: the scene seen at that row is shifted
    return undistort(xx + amp * np.sin(2 * np.pi * yy / period + phase), yy, k, d)


def normalised_grid(k: np.ndarray, d: np.ndarray, ss: int, size=SIZE,
                    shake: tuple = (0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Normalised coordinates at ss x ss sub-samples of every pixel (bilinear between the
    pixel corners' exact undistortion: the lens is linear to 1e-6 px over one pixel)."""
    w, h = size
    xn, yn = _corner_map(np.ascontiguousarray(k, float).tobytes(),
                         np.ascontiguousarray(d, float).tobytes(), w, h, tuple(shake))
    f = (np.arange(ss) + 0.5) / ss
    out = []
    for g in (xn, yn):
        a, b, c, e = g[:-1, :-1], g[:-1, 1:], g[1:, :-1], g[1:, 1:]
        big = np.empty((h, ss, w, ss))
        for i, fy in enumerate(f):
            for j, fx in enumerate(f):
                big[:, i, :, j] = ((1 - fy) * ((1 - fx) * a + fx * b)
                                   + fy * ((1 - fx) * c + fx * e))
        out.append(big.reshape(h * ss, w * ss))
    return out[0], out[1]


def groove_depth(dist_px: np.ndarray, width_px: float, asym: float = 0.35,
                 power: float = 1.4) -> np.ndarray:
    """My groove: depth 1 at the bottom, walls |d/half|^power, the left wall (d < 0) narrower
    by (1 - asym) than the right (a tool ground off-centre); a rounded bottom (power > 1)."""
    half = 0.5 * width_px
    hl, hr = half * (1 - asym), half * (1 + asym)
    s = np.where(dist_px < 0, -dist_px / hl, dist_px / hr)
    return np.clip(1 - s ** power, 0, None) ** 0.8


@dataclass
class Mark:
    """A mark on the face: angle [rad] in the pinhole plane, its centre in normalised units
    relative to the optical axis (x right, y down), length and width in pixels at f."""

    angle: float
    cx: float = 0.0
    cy: float = 0.0
    length_px: float = 300.0
    width_px: float = 5.0
    contrast: float = 0.5
    asym: float = 0.35
    width_gain: float = 0.0   # relative change of the width from one end to the other


@dataclass
class Scene:
    marks: list[Mark]
    k: np.ndarray
    d: np.ndarray
    size: tuple[int, int] = SIZE
    ss: int = 3
    blur_px: float = 0.8          # optical blur sigma [px]
    defocus_px: float = 0.0       # extra blur sigma at the far end of the image in x [px]
    vignette: float = 0.25        # fall-off at the half-diagonal (cos^4-like)
    full_well: float = 20000.0    # electrons at the background level
    read_e: float = 10.0
    bits: int = 8
    level: float = 0.6            # background as a fraction of full scale
    jpeg: int = 0                 # JPEG quality (0: PNG)
    seed: int = 0
    shake: tuple = (0.0, 1.0, 0.0)  # rolling shutter: amplitude [px], period [rows], phase
    # a shadow's edge: (angle [rad], distance from the image centre [px], width [px], depth)
    shadow: tuple = (0.0, 0.0, 1.0, 0.0)


def render(sc: Scene) -> np.ndarray:
    """Integer image of the scene (uint8 or uint16)."""
    rng = np.random.default_rng(sc.seed)
    w, h = sc.size
    xn, yn = normalised_grid(sc.k, sc.d, sc.ss, sc.size, sc.shake)
    f = 0.5 * (sc.k[0, 0] + sc.k[1, 1])
    refl = np.ones_like(xn)
    for m in sc.marks:
        ca, sa = np.cos(m.angle), np.sin(m.angle)
        dx, dy = xn - m.cx, yn - m.cy
        t = (dx * ca - dy * sa) * f            # along the mark [px at f]
        dn = (dx * sa + dy * ca) * f           # across [px at f]
        ends = np.clip((0.5 * m.length_px - np.abs(t)) / 2.0 + 0.5, 0, 1)
        # a face tilted to the camera: the groove's imaged width changes along it
        wid = m.width_px * (1 + m.width_gain * np.clip(t / m.length_px, -0.5, 0.5))
        refl *= 1 - m.contrast * groove_depth(dn, wid, m.asym) * ends
    # optical blur on the sub-sampled radiance, growing across the image for defocus
    s0 = sc.blur_px * sc.ss
    img = cv2.GaussianBlur(refl, (0, 0), s0) if s0 > 0 else refl
    if sc.defocus_px > 0:
        s1 = np.hypot(sc.blur_px, sc.defocus_px) * sc.ss
        far = cv2.GaussianBlur(refl, (0, 0), s1)
        wgt = np.clip((np.arange(w * sc.ss) / (w * sc.ss)), 0, 1)[None, :]
        img = (1 - wgt) * img + wgt * far
    img = img.reshape(h, sc.ss, w, sc.ss).mean(axis=(1, 3))  # each pixel's area
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (0.25 * (w * w + h * h))
    img = img * (1 - sc.vignette * r2)
    sa, so, sw, sd = sc.shadow
    if sd:
        dist = ((xx - (w - 1) / 2) * np.sin(sa) + (yy - (h - 1) / 2) * np.cos(sa)) - so
        img = img * (1 - sd / (1 + np.exp(-dist / sw)))
    e = rng.poisson(np.clip(img * sc.full_well, 0, None)) + rng.normal(0, sc.read_e, img.shape)
    full = 2 ** sc.bits - 1
    dn_img = np.clip(np.round(e / sc.full_well * sc.level * full), 0, full)
    if sc.bits == 8:
        return dn_img.astype(np.uint8)
    return dn_img.astype(np.uint16)


def write(sc: Scene, path: Path) -> Path:
    img = render(sc)
    if sc.jpeg:
        path = path.with_suffix(".jpg")
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, sc.jpeg])
        path.write_bytes(buf.tobytes())
    else:
        cv2.imwrite(str(path), img)
    return path


def mark_at(k: np.ndarray, angle: float, px: float, py: float, **kw) -> Mark:
    """A mark whose centre images near pixel (px, py) (its pinhole position)."""
    return Mark(angle, (px - k[0, 2]) / k[0, 0], (py - k[1, 2]) / k[1, 1], **kw)


def wrap_deg(a: float) -> float:
    """A line direction difference wrapped to (-90, 90] degrees."""
    return (a + 90.0) % 180.0 - 90.0


# ---------------------------------------------------------------- tumbles of a triad


def cube26() -> np.ndarray:
    """26 attitudes (the cube's 6 faces, 12 edges, 8 corners): the up direction, unit vectors."""
    v = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                  if (i, j, k) != (0, 0, 0)], float)
    return v / np.linalg.norm(v, axis=1)[:, None]


@dataclass
class Triad:
    """u_i = k_i (1 + asym_i sign(a_i)) a_i + o_i [g-ish output unit], a the specific force
    along the (orthogonal) sensitive axes; a bias step `step_g` on every axis from time
    `step_t` on (a temperature step through the bias's temperature coefficient)."""

    k: tuple = (1.002, 0.997, 1.001)
    o: tuple = (0.004, -0.003, 0.002)     # output offsets [output unit]
    asym: tuple = (0.0, 0.0, 0.0)         # (k+ - k-) / (k+ + k-)
    noise: float = 3e-4                   # white noise per sample [output unit]
    lsb: float = 0.0                      # output quantum (0: none)
    step_g: tuple = (0.0, 0.0, 0.0)
    step_t: float = 1e9
    vib_g: float = 0.0                    # vibration amplitude on every axis [g]
    vib_hz: float = 0.0
    k3: tuple = (0.0, 0.0, 0.0)           # cubic non-linearity [1/g^2] (IEEE Std 1293's K3)
    creep: float = 0.0                    # fraction of the last turn's change still settling
    creep_tau: float = 0.5                # its time constant [s]
    # a room temperature step dT [K] at time temp_step_t, logged by a thermometer on the
    # housing at once; the sensing element follows it with time constant temp_lag_s, and its
    # bias with temp_coeff [g/K] of the element's temperature
    temp_step: float = 0.0
    temp_step_t: float = 1e9
    temp_lag_s: float = 60.0
    temp_coeff: tuple = (0.0, 0.0, 0.0)


def tumble_rows(tr: Triad, ups: np.ndarray, seed: int, n: int = 200, rate: float = 100.0,
                gap_s: float = 5.0, labels: list[str] | None = None) -> list[tuple]:
    """Rows (pose, ux, uy, uz, t) of a static tumble: n samples a pose at `rate`, `gap_s` of
    turning between poses (not recorded)."""
    rng = np.random.default_rng(seed)
    k, o, asym = np.array(tr.k), np.array(tr.o), np.array(tr.asym)
    rows, t0 = [], 0.0
    phase = rng.uniform(0, 2 * np.pi, 3)
    prev = ups[0]
    for p, up in enumerate(ups):
        t = t0 + np.arange(n) / rate
        a = np.tile(up, (n, 1))
        # creep: the reading still follows the turn, decaying from the last attitude
        a = a + tr.creep * np.outer(np.exp(-(t - t0) / tr.creep_tau), prev - up)
        prev = up
        if tr.vib_g:
            a = a + tr.vib_g * np.sin(2 * np.pi * tr.vib_hz * t[:, None] + phase)
        lin = a + np.array(tr.k3) * a ** 3
        u = k * (1 + asym * np.sign(a)) * lin + o + rng.normal(0, tr.noise, (n, 3))
        u = u + np.where(t[:, None] >= tr.step_t, np.array(tr.step_g) * k, 0.0)
        logged = 20.0 + tr.temp_step * (t >= tr.temp_step_t)
        since = np.clip(t - tr.temp_step_t, 0, None)
        inner = 20.0 + tr.temp_step * (t >= tr.temp_step_t) * (1 - np.exp(-since / tr.temp_lag_s))
        u = u + np.outer(inner - 20.0, np.array(tr.temp_coeff) * k)
        if tr.lsb:
            u = np.round(u / tr.lsb) * tr.lsb
        lab = labels[p] if labels else f"P{p:02d}"
        rows += [(lab, *map(float, u[i]), float(t[i]), float(logged[i])) for i in range(n)]
        t0 = t[-1] + gap_s
    return rows


def write_tumble(rows: list[tuple], path: Path, temp: bool = False) -> Path:
    """The tumble as CSV; with temp, the logged temperature [°C] as a last column."""
    with open(path, "w") as fh:
        fh.write("pose,ux [g],uy [g],uz [g],t [s]" + (",temp\n" if temp else "\n"))
        for r in rows:
            tail = f",{r[5]:.3f}" if temp else ""
            fh.write(f"{r[0]},{r[1]:.9f},{r[2]:.9f},{r[3]:.9f},{r[4]:.4f}{tail}\n")
    return path


FACES = ["+x", "-x", "+y", "-y", "+z", "-z"]


def tilted_faces(tilt_deg: float, seed: int, repeats: int = 1) -> np.ndarray:
    """The six faces' up directions, each tilted by `tilt_deg` about a random horizontal axis
    (a fixture whose faces are not square, or a unit set down on a burr)."""
    rng = np.random.default_rng(seed + 9999)
    base = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    out = []
    for v in np.repeat(base, repeats, axis=0):
        w = np.cross(v, rng.normal(size=3))
        w /= np.linalg.norm(w)
        a = np.deg2rad(tilt_deg)
        out.append(np.cos(a) * v + np.sin(a) * w)
    return np.array(out)


# ---------------------------------------------------------------- chessboards through my lens


@functools.lru_cache(maxsize=2)
def chessboard_poses(side: str = "left") -> tuple:
    """(rvec, tvec) of each real photograph's board (square = 1), from my calibration."""
    objp = np.zeros((54, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    k, d = chessboard_lens(side)
    poses = []
    for f in sorted(CHESS.glob(f"{side}*.jpg")):
        g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if ok:
            c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3))
            _, rv, tv = cv2.solvePnP(objp, c, k, d)
            poses.append((rv.ravel(), tv.ravel()))
    return tuple(poses)


def render_board(k: np.ndarray, d: np.ndarray, rvec, tvec, seed: int, ss: int = 3,
                 blur_px: float = 0.7, size=SIZE) -> np.ndarray:
    """An 8-bit photograph of a 10 x 7-square board (9 x 6 inner corners, square 1) at pose
    (rvec, tvec) through my lens: each sub-sample's ray meets the board's plane; white 0.85,
    black 0.1; blur, shot and read noise."""
    rng = np.random.default_rng(seed)
    xn, yn = normalised_grid(k, d, ss, size)
    r, _ = cv2.Rodrigues(np.asarray(rvec, float))
    n = r[:, 2]                                   # board normal in the camera frame
    t = np.asarray(tvec, float)
    s = (n @ t) / (n[0] * xn + n[1] * yn + n[2])  # ray length to the plane
    pts = np.stack([xn * s - t[0], yn * s - t[1], s - t[2]], axis=-1) @ r  # board coords
    bx, by = pts[..., 0] + 1.0, pts[..., 1] + 1.0  # inner corner (0, 0) at square (1, 1)
    inside = (bx >= 0) & (bx < 10) & (by >= 0) & (by < 7)
    chk = (np.floor(bx).astype(int) + np.floor(by).astype(int)) % 2 == 0
    refl = np.where(inside, np.where(chk, 0.1, 0.85), 0.6)
    w, h = size
    img = cv2.GaussianBlur(refl, (0, 0), blur_px * ss)
    img = img.reshape(h, ss, w, ss).mean(axis=(1, 3))
    e = rng.poisson(img * 20000.0) + rng.normal(0, 10, img.shape)
    return np.clip(np.round(e / 20000.0 * 255), 0, 255).astype(np.uint8)
