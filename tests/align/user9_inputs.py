"""Independent user 9's generators: scribe marks rendered from physics through a lens I
calibrate myself, written without reading the tool's source (numpy / opencv only).

The scene. A scribe mark is a straight groove in the object plane. Through a pinhole camera
with square pixels of focal length ``fx`` the groove is a straight band in the *ideal* image
plane (normalised coordinates times ``fx``). The groove's reflectance profile across it is one
of:

* ``"vflat"``: a V with a flat bottom (trapezoid): full depth for ``|d| < flat/2``, falling
  linearly to the surface over ``wall`` px on each side;
* ``"u"``: a round (U) groove, depth ``sqrt(1 - (d / half)^2)``;
* ``"double"``: two thin V's ``gap`` px apart (a double-ruled line); its centre line is the
  mark.

The lens. OpenCV's Brown-Conrady model (``K``, ``k1 k2 p1 p2 k3``) maps ideal normalised
points to sensor pixels. A sensor sample at pixel position ``(u, v)`` sees the ideal point
``cv2.undistortPointsIter(u, v)`` (iterated to 1e-12): the scene is evaluated there.

Sampling. Each pixel integrates the light over its area; the optics blur the continuous
image before it reaches the pixels. So the scene is rendered at ``n`` x ``n`` points per
pixel (n = 8 by default), blurred there with a Gaussian of ``sigma_px`` pixels (in fine
samples: ``n * sigma_px``), and then block-averaged. Only 32 x 32-pixel tiles near a mark are
rendered finely (a tile plus a margin of 4 sigma + 2 px); the rest is flat background.

Noise. Photon noise (Poisson in electrons, full well ``full_well_e`` at the surface's level)
and Gaussian read noise (``read_e``), then quantised to ``bits`` (8, 12 or 16 bit; 12-bit in
a 16-bit container like a machine-vision camera writes it).

Truth. A mark's angle is its direction in the ideal (normalised, square-pixel) plane, from +x
towards -y (counter-clockwise as displayed), in (-90, 90] degrees, as ``docs/commands/marks.md``
defines it.
"""

from __future__ import annotations

import functools
import glob
import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

CHESS = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / "opencv-chessboard"
SIZE = (640, 480)  # the chessboard camera's frame (W, H)
ARCSEC = np.pi / 180 / 3600


# ------------------------------------------------------------------------------ the lens


@dataclass(frozen=True)
class Lens:
    """A camera: OpenCV camera matrix and distortion (k1 k2 p1 p2 k3), frame (W, H)."""

    K: tuple
    dist: tuple
    size: tuple = SIZE

    @property
    def k(self) -> np.ndarray:
        return np.array(self.K, float)

    @property
    def d(self) -> np.ndarray:
        return np.array(self.dist, float)


@functools.cache
def chessboard_calibration(side: str = "left"):
    """My calibration of the real OpenCV sample camera: ``cv2.calibrateCamera`` on the 7
    chessboard photographs (9 x 6 inner corners, corners refined to 0.1 px).

    Returns (Lens, rms reprojection error [px], per-parameter formal std of fx fy cx cy k1 k2
    p1 p2 k3)."""
    files = sorted(glob.glob(str(CHESS / f"{side}0*.jpg")))
    obj = np.zeros((9 * 6, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    objs, imgs, size = [], [], None
    for f in files:
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        size = g.shape[::-1]
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 60, 1e-4))
        objs.append(obj)
        imgs.append(c)
    rms, k, d, _r, _t, std_in, _std_ex, _per = cv2.calibrateCameraExtended(
        objs, imgs, size, None, None)
    lens = Lens(tuple(tuple(float(x) for x in row) for row in k),
                tuple(float(x) for x in d.ravel()[:5]), tuple(size))
    return lens, float(rms), std_in.ravel()[:9]


def varied_lens(rng: np.random.Generator, k1: float | None = None, f: float = 540.0) -> Lens:
    """A lens drawn from the ranges a user may bring, in OpenCV's units (focal length ``f``
    px, 640 x 480): k1 in [-0.3, 0.1], k2 = 0.3 |k1| for a barrel lens (a real barrel lens
    has a positive k2 that keeps the corners in the picture: k1 = -0.3 alone folds the image
    before the corner, the real chessboard lens has k1 -0.28, k2 +0.08), |p1|, |p2| <= 1e-3,
    the principal point up to 20 px off the centre, pixel aspect fy/fx in [0.995, 1.005]."""
    w, h = SIZE
    if k1 is None:
        k1 = rng.uniform(-0.3, 0.1)
    k2 = 0.3 * max(0.0, -k1)
    p1, p2 = rng.uniform(-1e-3, 1e-3, 2)
    pp = rng.uniform(-1, 1, 2)
    pp = pp / max(1.0, float(np.hypot(*pp))) * 20.0
    aspect = rng.uniform(0.995, 1.005)
    K = ((f, 0.0, (w - 1) / 2 + float(pp[0])), (0.0, f * aspect, (h - 1) / 2 + float(pp[1])),
         (0.0, 0.0, 1.0))
    return Lens(K, (float(k1), float(k2), float(p1), float(p2), 0.0), SIZE)


def half_diagonal_k1(lens: Lens) -> float:
    """OpenCV's k1 written at the image half-diagonal (docs/camera.md: k1_cv (R/f)^2)."""
    w, h = lens.size
    R = 0.5 * np.hypot(w - 1, h - 1)
    return float(lens.d[0] * (R / lens.k[0, 0]) ** 2)


@functools.lru_cache(maxsize=8)
def ideal_map(lens: Lens):
    """Ideal normalised coordinates (xn, yn) seen by every whole pixel of the frame."""
    w, h = lens.size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2)
    n = undistort(lens, pts).reshape(h, w, 2)
    return n[..., 0], n[..., 1]


def _distort(d: np.ndarray, x: np.ndarray, y: np.ndarray):
    """OpenCV's distortion of normalised points (k1 k2 p1 p2 [k3 [k4 k5 k6]]: the rational
    model too), and its Jacobian by central differences (smooth: 1e-7 steps are exact to
    ~1e-9)."""
    def f(x, y):
        k = np.zeros(8)
        k[:min(8, len(d))] = d[:8]
        k1, k2, p1, p2, k3, k4, k5, k6 = k
        r2 = x * x + y * y
        rad = (1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3) / (1 + k4 * r2 + k5 * r2 ** 2
                                                             + k6 * r2 ** 3)
        return (x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
    h = 1e-7
    xd, yd = f(x, y)
    ax, cx_ = f(x + h, y)
    bx, dx_ = f(x - h, y)
    ay, cy_ = f(x, y + h)
    by, dy_ = f(x, y - h)
    return xd, yd, (ax - bx) / (2 * h), (ay - by) / (2 * h), (cx_ - dx_) / (2 * h), \
        (cy_ - dy_) / (2 * h)


def undistort(lens: Lens, pts: np.ndarray) -> np.ndarray:
    """Sensor pixels -> ideal normalised points: Newton's method on OpenCV's forward model
    (by hand: cv2.undistortPoints' fixed-point iteration diverges for a strong barrel lens
    near the corners), checked to re-project within 1e-6 px."""
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    k = lens.k
    yt = (pts[:, 1] - k[1, 2]) / k[1, 1]
    xt = (pts[:, 0] - k[0, 2] - k[0, 1] * yt) / k[0, 0]
    # start from OpenCV's fixed-point iteration where it converged (most lenses), else from
    # the distorted point; Newton then polishes either
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-15)
    start = cv2.undistortPoints(pts.reshape(-1, 1, 2), k, lens.d, None, None, None,
                                crit).reshape(-1, 2)
    xd0, yd0 = _distort(lens.d, start[:, 0], start[:, 1])[:2]
    good = np.isfinite(xd0) & (np.hypot(xd0 - xt, yd0 - yt) < 1e-10)
    x, y = start[:, 0].copy(), start[:, 1].copy()
    bad = ~good
    xb, yb, xtb, ytb = xt[bad], yt[bad], xt[bad], yt[bad]
    for _ in range(60):
        if not len(xb):
            break
        xd, yd, a, b, c, e = _distort(lens.d, xb, yb)
        rx, ry = xd - xtb, yd - ytb
        det = a * e - b * c
        dx = (e * rx - b * ry) / det
        dy = (a * ry - c * rx) / det
        step = np.maximum(1.0, np.hypot(dx, dy) / 0.2)  # at most 0.2 per step (no overshoot)
        xb = xb - dx / step
        yb = yb - dy / step
        if max(np.abs(dx).max(), np.abs(dy).max()) < 1e-13:
            break
    x[bad], y[bad] = xb, yb
    n = np.stack([x, y], -1)
    step = max(1, len(n) // 5000)  # a sample of the points is enough to check convergence
    back = project(lens, n[::step, 0], n[::step, 1])
    err = np.abs(back - pts[::step]).max()
    assert err < 1e-6, f"undistortion did not converge ({err:.2g} px)"
    return n


def project(lens: Lens, xn: np.ndarray, yn: np.ndarray) -> np.ndarray:
    """Ideal normalised points -> sensor pixels through the lens (OpenCV's forward model)."""
    p = np.stack([xn, yn, np.ones_like(xn)], -1).reshape(-1, 1, 3).astype(np.float64)
    s, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), lens.k, lens.d)
    return s.reshape(-1, 2)


# ------------------------------------------------------------------------------ the scene


@dataclass(frozen=True)
class Groove:
    """One straight scribe mark, placed by where its middle appears in the image.

    ``centre_px``: the sensor pixel where the mark's middle is seen; ``angle_deg``: its
    direction in the ideal plane (the truth); ``length_px``: its length in ideal pixels
    (normalised x fx); the profile's sizes are in ideal pixels too."""

    centre_px: tuple
    angle_deg: float
    length_px: float
    profile: str = "vflat"
    flat: float = 1.5
    wall: float = 1.5
    gap: float = 4.0
    depth: float = 0.6  # fraction of the light the groove's bottom takes away


@dataclass(frozen=True)
class Scene:
    grooves: tuple
    lens: Lens
    sigma_px: float = 0.9  # optics blur (Gaussian), sensor pixels
    oversample: int = 8
    level: float = 0.55  # surface level, fraction of full scale
    full_well_e: float = 20000.0
    read_e: float = 12.0
    bits: int = 8
    container_bits: int | None = None  # 16 for 12-bit data in a 16-bit file
    vignetting: float = 0.1  # relative fall-off at the corners (cos^4-like, smooth)
    extra: tuple = field(default=())  # (name, args) extra scene items, e.g. numerals


def _profile(g: Groove, d: np.ndarray) -> np.ndarray:
    a = np.abs(d)
    if g.profile == "vflat":
        return np.clip((g.flat / 2 + g.wall - a) / g.wall, 0.0, 1.0)
    if g.profile == "u":
        half = g.flat / 2 + g.wall
        return np.sqrt(np.clip(1 - (a / half) ** 2, 0.0, 1.0))
    if g.profile == "double":
        one = lambda x: np.clip((0.9 - np.abs(x)) / 0.9, 0.0, 1.0)  # noqa: E731
        return np.maximum(one(d - g.gap / 2), one(d + g.gap / 2))
    raise ValueError(g.profile)


def _reach(g: Groove) -> float:
    if g.profile == "double":
        return g.gap / 2 + 1.0
    return g.flat / 2 + g.wall


def groove_geometry(lens: Lens, g: Groove):
    """The groove's ideal middle point (normalised) and unit direction (normalised plane)."""
    c = np.array(g.centre_px, float).reshape(1, 1, 2)
    m = undistort(lens, c).reshape(2)
    a = np.deg2rad(g.angle_deg)
    return m, np.array([np.cos(a), -np.sin(a)])


def sensor_ends(lens: Lens, g: Groove) -> np.ndarray:
    """Where the groove's two ends appear on the sensor [px] (2 x 2)."""
    m, t = groove_geometry(lens, g)
    half = g.length_px / 2 / lens.k[0, 0]
    e = np.stack([m - half * t, m + half * t])
    return project(lens, e[:, 0], e[:, 1])


def _fine_positions(lo: int, n_px: int, n: int) -> np.ndarray:
    return lo + (np.arange(n_px * n) + 0.5) / n - 0.5


def render(scene: Scene, seed: int) -> np.ndarray:
    """The scene as a camera records it: uint8 or uint16 array (H, W)."""
    lens = scene.lens
    w, h = lens.size
    n = scene.oversample
    xn, yn = ideal_map(lens)
    f = lens.k[0, 0]
    take = np.zeros((h, w))  # the fraction of light the grooves take away (pixel-integrated)
    margin = int(np.ceil(4 * scene.sigma_px)) + 2
    tile = 32
    for g in scene.grooves:
        m, t = groove_geometry(lens, g)
        nrm = np.array([-t[1], t[0]])
        # signed across / along distances of each whole pixel's ideal point [ideal px]
        dx, dy = (xn - m[0]) * f, (yn - m[1]) * f
        d_all = dx * nrm[0] + dy * nrm[1]
        s_all = dx * t[0] + dy * t[1]
        near = (np.abs(d_all) < _reach(g) + 4 * scene.sigma_px + 3) & (
            np.abs(s_all) < g.length_px / 2 + 4 * scene.sigma_px + 3)
        for ty in range(0, h, tile):
            for tx in range(0, w, tile):
                if not near[ty:ty + tile, tx:tx + tile].any():
                    continue
                y0, y1 = max(0, ty - margin), min(h, ty + tile + margin)
                x0, x1 = max(0, tx - margin), min(w, tx + tile + margin)
                # sensor sample positions; the ideal point of each by bilinear interpolation
                # of the whole pixels' map (smooth: its error is ~1e-5 px here), exact at
                # the pixels; samples beyond the frame's last pixel centre use the map's
                # edge extrapolated by remap's replicate border (they only feed the blur's
                # margin)
                fx_ = _fine_positions(x0, x1 - x0, n).astype(np.float32)
                fy_ = _fine_positions(y0, y1 - y0, n).astype(np.float32)
                mx, my = np.meshgrid(fx_, fy_)
                d = cv2.remap(d_all.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT101)
                s = cv2.remap(s_all.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT101)
                # d in float32 loses ~1e-5 px at 600 px: below what any test resolves
                along = np.clip(g.length_px / 2 + 0.5 - np.abs(s), 0.0, 1.0)
                fine = g.depth * _profile(g, d.astype(np.float64)) * along
                fine = cv2.GaussianBlur(fine, (0, 0), scene.sigma_px * n,
                                        borderType=cv2.BORDER_REFLECT101)
                blk = fine.reshape(y1 - y0, n, x1 - x0, n).mean(axis=(1, 3))
                iy0, ix0 = ty - y0, tx - x0
                iy1 = iy0 + min(tile, h - ty)
                ix1 = ix0 + min(tile, w - tx)
                cur = take[ty:ty + tile, tx:tx + tile]
                take[ty:ty + tile, tx:tx + tile] = 1 - (1 - cur) * (1 - blk[iy0:iy1, ix0:ix1])
    for name, args in scene.extra:
        take = np.maximum(take, _EXTRA[name](lens, scene, *args))
    return expose(scene, 1.0 - take, seed)


def expose(scene: Scene, reflect: np.ndarray, seed: int) -> np.ndarray:
    """Light, photon and read noise, quantisation."""
    rng = np.random.default_rng(seed)
    h, w = reflect.shape
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (
        0.25 * ((w - 1) ** 2 + (h - 1) ** 2))
    light = scene.level * (1 - scene.vignetting * r2)
    e = rng.poisson(light * reflect * scene.full_well_e).astype(float)
    e += rng.normal(0, scene.read_e, e.shape)
    full = 2 ** scene.bits - 1
    dn = np.clip(np.round(e / scene.full_well_e * full), 0, full)
    return dn.astype(np.uint8 if (scene.container_bits or scene.bits) <= 8 else np.uint16)


def pixel_noise_dn(scene: Scene) -> float:
    """The surface's pixel noise [DN] (photon + read + quantisation) at the frame's centre."""
    full = 2 ** scene.bits - 1
    e = scene.level * scene.full_well_e
    return float(np.sqrt(e + scene.read_e ** 2) / scene.full_well_e * full)


# ------------------------------------------------------------------------ extra scene items


def _numerals(lens: Lens, scene: Scene, x0: float, y0: float, pitch: float, count: int,
              height: float) -> np.ndarray:
    """Printed numerals beside a ruled scale (drawn by cv2.putText at 4x, area-averaged and
    blurred; they are print, not grooves, so no lens is applied to them)."""
    w, h = lens.size
    n = 4
    big = np.zeros((h * n, w * n), np.uint8)
    for i in range(count):
        org = (int((x0 + i * pitch) * n), int(y0 * n))
        cv2.putText(big, str(i % 10), org, cv2.FONT_HERSHEY_SIMPLEX, height * n / 22.0,
                    255, thickness=max(1, int(0.12 * height * n / 4)), lineType=cv2.LINE_AA)
    big = cv2.GaussianBlur(big.astype(np.float32) * (0.5 / 255), (0, 0), scene.sigma_px * n)
    return big.reshape(h, n, w, n).mean(axis=(1, 3)).astype(float)


_EXTRA = {"numerals": _numerals}


# ------------------------------------------------------------------------------ files


def camera_json(lens: Lens, path: Path, u: dict | None = None) -> Path:
    """A camera model file as ``align/schemas/camera.schema.json`` defines it."""
    if u is None:
        u = {"fx": 0.05, "fy": 0.05, "cx": 0.05, "cy": 0.05, "k1": 1e-5, "k2": 1e-5,
             "p1": 1e-6, "p2": 1e-6, "k3": 1e-5}
    cam = {"format": "axis-align/camera", "format_version": 3, "tool": "user9",
           "tool_version": "0", "camera_matrix": lens.k.tolist(),
           "dist_coeffs": [float(x) for x in lens.d], "image_size": list(lens.size),
           "rms_px": 0.1, "u": u}
    path.write_text(json.dumps(cam))
    return path


def write_image(img: np.ndarray, path: Path, jpeg_quality: int | None = None) -> Path:
    if jpeg_quality is not None:
        cv2.imwrite(str(path), img, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    else:
        cv2.imwrite(str(path), img)
    return path


def angle_error_arcsec(measured_deg: float, truth_deg: float) -> float:
    d = (measured_deg - truth_deg + 90.0) % 180.0 - 90.0
    return d * 3600.0


def jpeg_with_orientation(img: np.ndarray, path: Path, orientation: int,
                          quality: int = 95) -> Path:
    """A JPEG of the *sensor's* pixels with an EXIF Orientation tag (as a phone or a camera
    held on its side writes it): an APP1 segment with one IFD entry, written by hand
    (struct), inserted after the SOI marker."""
    import struct

    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    data = buf.tobytes()
    tiff = b"MM" + struct.pack(">HI", 42, 8)  # big-endian TIFF header, IFD0 at offset 8
    tiff += struct.pack(">H", 1)  # one entry
    tiff += struct.pack(">HHIHH", 0x0112, 3, 1, orientation, 0)  # Orientation, SHORT, 1
    tiff += struct.pack(">I", 0)  # no next IFD
    app1 = b"Exif\x00\x00" + tiff
    seg = b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1
    path.write_bytes(data[:2] + seg + data[2:])
    return path


# ------------------------------------------------------------------------------ a session

AXES = {"+X": (1, 0, 0), "-X": (-1, 0, 0), "+Y": (0, 1, 0), "-Y": (0, -1, 0),
        "+Z": (0, 0, 1), "-Z": (0, 0, -1)}
VIEWS = {"A": ("A", "+X", "+Z"), "Ar": ("A", "-X", "+Z"),
         "B": ("B", "+Y", "+Z"), "Br": ("B", "-Y", "+Z")}
# which housings each view shows: (housing, nominal)
VIEW_MARKS = {"A": (("x", "horizontal"), ("z", "vertical")),
              "Ar": (("x", "horizontal"), ("z", "vertical")),
              "B": (("y", "horizontal"), ("z", "vertical")),
              "Br": (("y", "horizontal"), ("z", "vertical"))}


@dataclass(frozen=True)
class Triad:
    """The truth: E [rad] (row i accelerometer, column j platform axis, zero diagonal), scale
    factors k [V/g], biases b [V], white noise per sample [V]."""

    E: np.ndarray
    k: tuple = (2.51, 2.47, 2.53)
    b: tuple = (0.012, -0.008, 0.02)
    noise_v: float = 2.5e-4  # 100 ug at 2.5 V/g

    @property
    def S(self) -> np.ndarray:
        """Unit sensitive axes (rows) in the platform frame: row i along (I + E)_i."""
        m = np.eye(3) + self.E
        return m / np.linalg.norm(m, axis=1, keepdims=True)

    def read(self, f_p: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
        """n samples [V] of the triad under specific force f_p [g] (platform frame)."""
        clean = np.array(self.k) * (self.S @ f_p) + np.array(self.b)
        return clean + rng.normal(0, self.noise_v, (n, 3))


def mark_angle_deg(triad: Triad, view: str, housing: str, roll_arcsec: float) -> float:
    """A housing's mark as the view's camera displays it (docs/concepts.md: atan2(s.u, s.r)
    + the camera's roll), in (-90, 90]."""
    _cam, right, up = VIEWS[view]
    s = triad.S["xyz".index(housing)]
    a = np.degrees(np.arctan2(s @ np.array(AXES[up], float), s @ np.array(AXES[right], float)))
    a += roll_arcsec / 3600.0
    return float((a + 90.0) % 180.0 - 90.0) if (a + 90.0) % 180.0 != 0 else 90.0


def tilt_up(table_deg: float, tilt_rad: tuple) -> np.ndarray:
    """Specific force [g] in the platform frame on a table at ``table_deg`` whose axis leans
    by ``tilt_rad`` = (about X, about Y) of the lab: the lab's up is the table axis rotated
    back by the tilt, seen in the platform frame turned by the table angle."""
    tx, ty = tilt_rad
    up_table = np.array([ty, -tx, 1.0])
    up_table /= np.linalg.norm(up_table)
    c, s = np.cos(np.radians(table_deg)), np.sin(np.radians(table_deg))
    rz_inv = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])  # lab/table -> platform
    return rz_inv @ up_table


def write_session(folder: Path, triad: Triad, seed: int, *, rolls=(0.0, 0.0),
                  lenses: dict | None = None, declare: dict | None = None,
                  tilt_arcsec=(0.0, 0.0), tumble_poses: int = 18) -> Path:
    """A session folder: 8 mark images (cameras A, B, each view reversed), a tumble of the
    triad, the mounted platform at 8 attitudes; ``session.toml`` as docs/formats.md shows.

    rolls: (A, B) roll of each camera [arc-seconds], undeclared; lenses: camera -> Lens the
    images are rendered through (default distortion-free 540 px); declare: camera -> the
    [cameras.X] lines (default: declared distortion-free)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    ideal = Lens(((540.0, 0, 319.5), (0, 540.0, 239.5), (0, 0, 1.0)), (0, 0, 0, 0, 0))
    lenses = lenses or {}
    declare = declare or {}
    toml = [f'name = "{folder.name}"', "", "[calibration]", 'static = "tumble.csv"',
            'units = "V"', ""]
    for cam in ("A", "B"):
        toml += [f"[cameras.{cam}]"]
        toml += declare.get(cam, ["lens_k1 = 0.0", "lens_k2 = 0.0", "lens_p = 0.0",
                                  "lens_aspect = 0.0", "lens_pp_px = 0.0"])
        toml += [""]
    for v, (cam, right, up) in VIEWS.items():
        toml += [f"[views.{v}]", f'camera = "{cam}"', f'right = "{right}"', f'up = "{up}"', ""]
    for v, hs in VIEW_MARKS.items():
        cam = VIEWS[v][0]
        lens = lenses.get(cam, ideal)
        roll = rolls["AB".index(cam)]
        for h, nominal in hs:
            a = mark_angle_deg(triad, v, h, roll)
            off = rng.uniform(-40, 40, 2)
            g = Groove((319.5 + off[0], 239.5 + off[1]), a, 380.0)
            img = render(Scene((g,), lens), int(rng.integers(1 << 30)))
            name = f"{h}_{v}.png"
            write_image(img, folder / name)
            toml += ["[[images]]", f'file = "{name}"', f'housing = "{h}"', f'view = "{v}"',
                     f'nominal = "{nominal}"', ""]
    # the tumble: random attitudes, 60 samples each
    rows = ["pose,ux,uy,uz"]
    for p in range(tumble_poses):
        f = rng.normal(size=3)
        f /= np.linalg.norm(f)
        for r in triad.read(f, rng, 60):
            rows.append(f"T{p:02d},{r[0]:.7f},{r[1]:.7f},{r[2]:.7f}")
    (folder / "tumble.csv").write_text("\n".join(rows) + "\n")
    # the platform
    tilt = tuple(np.array(tilt_arcsec) * ARCSEC)
    poses = {f"L{t:03d}": (tilt_up(t, tilt), f'{{ up = "+Z", table_deg = {t:.1f} }}')
             for t in (0, 90, 180, 270)}
    for ax in ("X", "Y"):
        for sgn, nm in ((1, "up"), (-1, "dn")):
            v = np.zeros(3)
            v["XYZ".index(ax)] = sgn
            poses[f"{ax}{nm}"] = (v, f'{{ up = "{"+" if sgn > 0 else "-"}{ax}" }}')
    rows = ["pose,ux,uy,uz"]
    for name, (f, _) in poses.items():
        for r in triad.read(f, rng, 60):
            rows.append(f"{name},{r[0]:.7f},{r[1]:.7f},{r[2]:.7f}")
    (folder / "platform.csv").write_text("\n".join(rows) + "\n")
    toml += ["[platform]", 'static = "platform.csv"', "[platform.poses]"]
    toml += [f"{name} = {decl}" for name, (_, decl) in poses.items()]
    (folder / "session.toml").write_text("\n".join(toml) + "\n")
    return folder


def random_E(rng: np.random.Generator, scale_arcsec: float = 200.0) -> np.ndarray:
    e = rng.uniform(-scale_arcsec, scale_arcsec, (3, 3)) * ARCSEC
    np.fill_diagonal(e, 0.0)
    return e


# ------------------------------------------------------------------------ chessboard photos


def rodrigues(v) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(v, np.float64))[0]


def board_views(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """n poses (R, t) of a 10 x 7-square board (unit squares, origin at its centre) that fill
    much of a 540 px camera's frame, tilted up to ~35 deg about random axes."""
    poses = []
    for _ in range(n):
        ax = rng.normal(size=3)
        ax[2] *= 0.3
        ax /= np.linalg.norm(ax)
        R = rodrigues(ax * np.radians(rng.uniform(10, 35)))
        t = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-1.0, 1.0), rng.uniform(11, 14)])
        poses.append((R, t))
    return poses


def render_board(lens: Lens, R: np.ndarray, t: np.ndarray, seed: int, n: int = 4,
                 sigma_px: float = 0.8) -> np.ndarray:
    """A chessboard photograph: every fine sample's ideal ray meets the board plane (exact
    homography), black/white squares (10 x 7, a white border of one square), blurred at the
    fine grid, area-averaged, photon + read noise, 8 bit."""
    w, h = lens.size
    xn, yn = ideal_map(lens)
    mx, my = np.meshgrid(_fine_positions(0, w, n).astype(np.float32),
                         _fine_positions(0, h, n).astype(np.float32))
    fx = cv2.remap(xn.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                   borderMode=cv2.BORDER_REFLECT101).astype(np.float64)
    fy = cv2.remap(yn.astype(np.float32), mx, my, cv2.INTER_LINEAR,
                   borderMode=cv2.BORDER_REFLECT101).astype(np.float64)
    hom = np.column_stack([R[:, 0], R[:, 1], t])  # board (X, Y, 1) -> ray
    inv = np.linalg.inv(hom)
    q = inv @ np.stack([fx.ravel(), fy.ravel(), np.ones(fx.size)])
    X = (q[0] / q[2]).reshape(fx.shape) + 5.0  # board coords, squares from the corner
    Y = (q[1] / q[2]).reshape(fx.shape) + 3.5
    inside = (X >= 0) & (X < 10) & (Y >= 0) & (Y < 7)
    border = (X >= -1) & (X < 11) & (Y >= -1) & (Y < 8)
    black = inside & ((np.floor(X) + np.floor(Y)) % 2 == 0)
    refl = np.where(border, 0.85, 0.35)
    refl = np.where(black, 0.06, refl).astype(np.float32)
    refl = cv2.GaussianBlur(refl, (0, 0), sigma_px * n)
    refl = refl.reshape(h, n, w, n).mean(axis=(1, 3)).astype(float)
    scene = Scene((), lens, level=0.9, full_well_e=15000.0, read_e=10.0, vignetting=0.15)
    return expose(scene, refl, seed)
