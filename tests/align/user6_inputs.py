"""user6's own generators, written from physics with numpy/scipy/opencv only.

Nothing here imports the pipeline or ``synth``: a scribe mark imaged through an OpenCV
lens (each pixel integrates the scene where the lens maps it from), and whole session
folders; the goniometer's log and the triad's tumble live in
:mod:`tests.align.user6_instruments` and are re-exported here.
Angles inside are radians; arc-seconds only where a name says so.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tests.align.user6_instruments import (  # noqa: F401  (re-exported: user6's one namespace)
    ARCSEC,
    OMEGA_EARTH,
    E_arcsec,
    Gonio,
    Triad,
    cube14,
    pose_means,
    random_dirs,
    s_from_E,
    tumble_rows,
    write_gonio,
    write_tumble,
)

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"


def wrap_deg(a: float) -> float:
    """A line direction difference wrapped to (-90, 90] degrees."""
    return (a + 90.0) % 180.0 - 90.0


# ----------------------------------------------------------------------------- optics

@dataclass
class Lens:
    """OpenCV pinhole + Brown-Conrady lens (k1, k2, p1, p2, k3)."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def D(self) -> np.ndarray:
        return np.asarray(self.dist, float)

    def ideal(self, px: np.ndarray) -> np.ndarray:
        """Distorted pixel positions (N, 2) -> the pinhole image's pixel positions (same K)."""
        pts = px.reshape(-1, 1, 2).astype(np.float64)
        if not np.any(self.D):
            return px.reshape(-1, 2).astype(np.float64)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-12)
        out = cv2.undistortPoints(pts, self.K, self.D, None, None, self.K, crit)
        return out.reshape(-1, 2)

    def distort(self, ideal_px: np.ndarray) -> np.ndarray:
        """Pinhole pixel positions -> distorted pixel positions (cv2.projectPoints)."""
        ip = ideal_px.reshape(-1, 2)
        xn = (ip[:, 0] - self.cx) / self.fx
        yn = (ip[:, 1] - self.cy) / self.fy
        obj = np.column_stack([xn, yn, np.ones_like(xn)])
        out, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), self.K, self.D)
        return out.reshape(-1, 2)


def no_lens(w: int, h: int, f: float = 700.0) -> Lens:
    return Lens(f, f, (w - 1) / 2, (h - 1) / 2)


_CHESS_LENS: Lens | None = None


def chessboard_lens() -> Lens | None:
    """The real lens of OpenCV's sample chessboards (left*.jpg, 9x6 inner corners),
    calibrated here with cv2.calibrateCamera; None when the data are absent."""
    global _CHESS_LENS
    if _CHESS_LENS is not None:
        return _CHESS_LENS
    folder = REAL / "opencv-chessboard"
    files = sorted(folder.glob("left*.jpg"))
    if not files:
        return None
    objp = np.zeros((9 * 6, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    objs, imgs, size = [], [], None
    for f in files:
        g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        size = g.shape[::-1]
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 1e-4))
        objs.append(objp)
        imgs.append(c)
    _, K, D, _, _ = cv2.calibrateCamera(objs, imgs, size, None, None)
    d = D.ravel()
    _CHESS_LENS = Lens(K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(d[:5]))
    return _CHESS_LENS


@dataclass
class Mark:
    """A straight (or bent) groove in the pinhole image: centre [px], direction angle_deg
    counter-clockwise as displayed from +x, length and width [px]; ``sag_px`` bows it (a
    circular arc whose middle lies sag_px off the chord, to the left of its direction)."""

    x: float
    y: float
    angle_deg: float
    length: float = 300.0
    width: float = 5.0
    depth: float = 0.55      # fraction of the background the groove's floor reflects less
    sag_px: float = 0.0


@dataclass
class Scene:
    width: int = 480
    height: int = 360
    marks: tuple = ()
    lens: Lens | None = None
    blur_px: float = 1.0
    full_well_e: float = 9000.0   # electrons at the background's brightest
    read_e: float = 12.0
    bits: int = 16                # 8, 12 (in 16-bit file) or 16
    vignetting: float = 0.25      # relative fall-off at the corner (cos^4-like)
    level: float = 0.8            # background as a fraction of full scale at the centre
    ss: int = 4                   # sub-pixel samples per axis
    dust: int = 0                 # dark specks of dust
    seed: int = 0
    extra: list = field(default_factory=list)  # fn(ideal_px, fat) -> depth 0..1 (other features)


def _groove_depth(px: np.ndarray, m: Mark) -> np.ndarray:
    """Groove depth (0..1) at ideal pixel positions px (N, 2): a rounded V (a ground
    scribe's cross-section, parabolic floor), ends rounded over half a width."""
    a = np.deg2rad(m.angle_deg)
    u = np.array([np.cos(a), -np.sin(a)])   # along (y down)
    n = np.array([np.sin(a), np.cos(a)])    # normal
    d = px - np.array([m.x, m.y])
    s = d @ u
    t = d @ n
    if m.sag_px:
        half = m.length / 2
        r = (half ** 2 + m.sag_px ** 2) / (2 * m.sag_px)
        # arc bulging towards -n by sag at s = 0 (left of the direction, as displayed)
        t = t + (m.sag_px - (r - np.sqrt(np.maximum(r ** 2 - s ** 2, 0.0))))
    hw = m.width / 2
    prof = np.clip(1 - (t / hw) ** 2, 0, None) ** 0.75
    end = np.clip((m.length / 2 - np.abs(s)) / hw + 0.5, 0, 1)
    return m.depth * prof * end


_MAPS: dict = {}
MARGIN = 16.0


def ideal_map(lens: Lens, width: int, height: int, step: float = 2.0):
    """The lens's exact inverse (cv2.undistortPoints, 60 iterations) on a grid every ``step``
    px from MARGIN px before to MARGIN px past the frame (spline edge effects stay outside);
    returns a function of distorted positions (N, 2) that interpolates it (cubic spline;
    checked against cv2.projectPoints to 1e-3 px in the test file)."""
    from scipy.ndimage import map_coordinates

    key = (lens.fx, lens.fy, lens.cx, lens.cy, tuple(lens.D), width, height, step)
    if key not in _MAPS:
        gx = np.arange(-MARGIN, width + MARGIN + step, step)
        gy = np.arange(-MARGIN, height + MARGIN + step, step)
        X, Y = np.meshgrid(gx, gy)
        ide = lens.ideal(np.column_stack([X.ravel(), Y.ravel()])).reshape(*X.shape, 2)
        _MAPS[key] = (ide, step)
    ide, st = _MAPS[key]

    def f(px):
        c = np.stack([(px[:, 1] + MARGIN) / st, (px[:, 0] + MARGIN) / st])
        return np.column_stack([map_coordinates(ide[..., 0], c, order=3, mode="nearest"),
                                map_coordinates(ide[..., 1], c, order=3, mode="nearest")])
    return f


def reflectance(sc: Scene) -> np.ndarray:
    """Each pixel's mean reflectance over ss x ss sub-pixel samples, each taken where the
    lens maps it from in the pinhole image (only near the marks: elsewhere 1)."""
    lens = sc.lens or no_lens(sc.width, sc.height)
    to_ideal = ideal_map(lens, sc.width, sc.height)
    yy, xx = np.mgrid[0:sc.height, 0:sc.width]
    centres = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    ic = to_ideal(centres)
    near = np.zeros(len(centres), bool)
    for m in sc.marks:
        fat = Mark(m.x, m.y, m.angle_deg, m.length + 8, m.width + 8, 1.0, m.sag_px)
        near |= _groove_depth(ic, fat) > 0
    for fn in sc.extra:
        near |= fn(ic, True) > 0
    idx = np.flatnonzero(near)
    ss = sc.ss
    off = (np.arange(ss) + 0.5) / ss - 0.5
    ox, oy = np.meshgrid(off, off)
    grid = np.column_stack([ox.ravel(), oy.ravel()])
    sub = (centres[idx][:, None, :] + grid[None]).reshape(-1, 2)
    isub = to_ideal(sub)
    refl = np.ones(len(sub))
    for m in sc.marks:
        refl *= 1 - _groove_depth(isub, m)
    for fn in sc.extra:
        refl *= 1 - fn(isub, False)
    out = np.ones(len(centres))
    out[idx] = refl.reshape(len(idx), ss * ss).mean(axis=1)
    return out.reshape(sc.height, sc.width)


def render(sc: Scene) -> np.ndarray:
    """The image (uint16 or uint8): pixel-integrated reflectance (``reflectance``), blurred
    by a Gaussian PSF, vignetting, dust; photon (Poisson) and read noise; quantised to the
    bit depth (12-bit data in a 16-bit file when bits = 12)."""
    return expose(sc, blurred_after(sc))


def blurred_after(sc: Scene) -> np.ndarray:
    """``render``'s noise-free relative exposure: the pixels' reflectance, then the PSF
    applied on the pixel grid (after the pixels, as a digital filter would)."""
    lo = reflectance(sc)
    return cv2.GaussianBlur(lo, (0, 0), sc.blur_px) if sc.blur_px > 0 else lo


def render_optics_first(sc: Scene) -> np.ndarray:
    """The same scene with the blur *before* the pixels, as a lens blurs
    (``blurred_before``); vignetting, dust and noise as ``render``."""
    return expose(sc, blurred_before(sc))


def blurred_before(sc: Scene, fine: int = 8) -> np.ndarray:
    """Noise-free relative exposure with the PSF before the pixels: the reflectance
    point-sampled on a grid ``fine`` x ``fine`` per pixel about the marks (through the lens
    map, past the frame's edge where the scene goes on), blurred there by the PSF, then
    averaged over each pixel."""
    if sc.extra:
        raise ValueError("render_optics_first draws marks only (no extra features)")
    lens = sc.lens or no_lens(sc.width, sc.height)
    to_ideal = ideal_map(lens, sc.width, sc.height)
    yy, xx = np.mgrid[0:sc.height, 0:sc.width]
    ic = to_ideal(np.column_stack([xx.ravel(), yy.ravel()]).astype(float))
    near = np.zeros(len(ic), bool)
    for m in sc.marks:
        near |= _groove_depth(ic, Mark(m.x, m.y, m.angle_deg, m.length + 8, m.width + 8, 1.0,
                                       m.sag_px)) > 0
    rows, cols = np.divmod(np.flatnonzero(near), sc.width)
    pad = int(np.ceil(4 * sc.blur_px)) + 2     # the scene goes on past the frame's edge
    r0, r1, c0, c1 = rows.min() - pad, rows.max() + pad + 1, cols.min() - pad, cols.max() + pad + 1
    off = (np.arange(fine) + 0.5) / fine - 0.5
    ys = (np.arange(r0, r1)[:, None] + off).ravel()
    xs = (np.arange(c0, c1)[:, None] + off).ravel()
    X, Y = np.meshgrid(xs, ys)
    isub = to_ideal(np.column_stack([X.ravel(), Y.ravel()]))
    refl = np.ones(len(isub))
    for m in sc.marks:
        refl *= 1 - _groove_depth(isub, m)
    refl = refl.reshape(X.shape)
    if sc.blur_px > 0:
        refl = cv2.GaussianBlur(refl, (0, 0), sc.blur_px * fine, borderType=cv2.BORDER_REPLICATE)
    pix = refl.reshape(r1 - r0, fine, c1 - c0, fine).mean(axis=(1, 3))
    lo = np.ones((sc.height, sc.width))
    a0, a1, b0, b1 = max(r0, 0), min(r1, sc.height), max(c0, 0), min(c1, sc.width)
    lo[a0:a1, b0:b1] = pix[a0 - r0:a1 - r0, b0 - c0:b1 - c0]
    return lo


def vignette(sc: Scene) -> np.ndarray:
    """Relative illumination of each pixel: 1 at the centre, 1 - vignetting at the corners."""
    yy, xx = np.mgrid[0:sc.height, 0:sc.width]
    r2 = ((xx - (sc.width - 1) / 2) ** 2 + (yy - (sc.height - 1) / 2) ** 2) / (
        ((sc.width - 1) / 2) ** 2 + ((sc.height - 1) / 2) ** 2)
    return 1 - sc.vignetting * r2


def expose(sc: Scene, lo: np.ndarray) -> np.ndarray:
    """Relative exposure ``lo`` (1 on the bare surface) -> the image: vignetting, dust;
    photon (Poisson) and read noise; quantised to the bit depth."""
    rng = np.random.default_rng(sc.seed)
    yy, xx = np.mgrid[0:sc.height, 0:sc.width]
    vig = vignette(sc)
    for _ in range(sc.dust):
        cx, cy = rng.uniform(0, sc.width), rng.uniform(0, sc.height)
        rad = rng.uniform(1.0, 3.0)
        lo = lo * (1 - 0.5 * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * rad ** 2)))
    electrons = rng.poisson(np.clip(sc.full_well_e * sc.level * vig * lo, 0, None)).astype(float)
    electrons += rng.normal(0, sc.read_e, electrons.shape)
    full = {8: 255, 12: 4095, 16: 65535}[sc.bits]
    dn = np.clip(np.round(electrons / sc.full_well_e * full), 0, full)
    return dn.astype(np.uint8 if sc.bits == 8 else np.uint16)


def write_image(path: Path, img: np.ndarray) -> Path:
    ok = cv2.imwrite(str(path), img)
    assert ok, path
    return path


def camera_json(path: Path, lens: Lens, size: tuple, u_rel: float = 1e-3) -> Path:
    """A camera model file as the docs describe it (camera_matrix, dist_coeffs,
    image_size); used only when a test wants to hand the tool a model I wrote."""
    path.write_text(json.dumps({
        "camera_matrix": lens.K.tolist(), "dist_coeffs": list(map(float, lens.D)),
        "image_size": list(size)}))
    return path


# ----------------------------------------------------------------------------- scenes

def text_feature(texts, width: int, height: int, depth: float = 0.6, ss: int = 4):
    """Printed numerals (cv2.putText, anti-aliased) as dark ink in the pinhole image:
    ``texts`` is a list of (string, (x, y) bottom-left [px], font scale). Returns a feature
    function for ``Scene.extra``."""
    from scipy.ndimage import map_coordinates

    canvas = np.zeros((height * ss, width * ss), np.uint8)
    for s, (x, y), scale in texts:
        cv2.putText(canvas, s, (int(x * ss), int(y * ss)), cv2.FONT_HERSHEY_SIMPLEX,
                    scale * ss, 255, max(1, int(2 * ss * scale)), cv2.LINE_AA)
    ink = canvas.astype(float) / 255.0
    fat = cv2.dilate(ink, np.ones((9 * ss, 9 * ss), np.uint8))

    def fn(px, want_fat):
        img = fat if want_fat else ink
        c = np.stack([px[:, 1] * ss + (ss - 1) / 2, px[:, 0] * ss + (ss - 1) / 2])
        return depth * map_coordinates(img, c, order=1, mode="constant")
    return fn


def micrometer(angle_deg: float, width: int = 640, height: int = 480, pitch: float = 40.0,
               n: int = 11, seed: int = 0, numerals: bool = True, lens: Lens | None = None,
               dust: int = 25) -> Scene:
    """A stage micrometer: n parallel graduations at ``pitch`` px across, every 5th longer,
    every 5th numbered, the lines' direction ``angle_deg`` (near 90: vertical rulings)."""
    a = np.deg2rad(angle_deg)
    normal = np.array([np.sin(a), np.cos(a)])   # across the lines (image x for vertical ones)
    along = np.array([np.cos(a), -np.sin(a)])
    c0 = np.array([(width - 1) / 2, (height - 1) / 2 + 20])
    marks, texts = [], []
    for i in range(n):
        k = i - (n - 1) // 2
        long_ = i % 5 == 0
        ln = 220.0 if long_ else 150.0
        # graduations share their bottom end (the scale's base line side)
        base = c0 + k * pitch * normal
        centre = base + along * (ln / 2 - 110.0)
        marks.append(Mark(float(centre[0]), float(centre[1]), angle_deg, ln, 3.5, 0.6))
        if long_ and numerals:
            top = base + along * (ln - 110.0 + 14)
            texts.append((str(i), (top[0] - 8, top[1]), 0.6))
    extra = [text_feature(texts, width, height)] if texts else []
    return Scene(width, height, tuple(marks), lens=lens, blur_px=1.0, seed=seed, bits=12,
                 dust=dust, extra=extra)


def dial(width: int = 640, height: int = 480, n: int = 12, r_in: float = 90.0,
         r_out: float = 210.0, seed: int = 0, turn_deg: float = 0.0) -> tuple:
    """Radial graduations every 360/n deg between radii r_in and r_out about the frame's
    centre (nudged), turned by ``turn_deg``; returns (scene, their direction angles)."""
    cx, cy = (width - 1) / 2 + 3.3, (height - 1) / 2 - 2.1
    marks, truth = [], []
    for i in range(n):
        th = np.deg2rad(turn_deg + 360.0 * i / n)
        rm = (r_in + r_out) / 2
        x, y = cx + rm * np.cos(th), cy - rm * np.sin(th)
        if not (r_out < min(width, height) / 2 or (0 < x < width and 0 < y < height)):
            continue
        marks.append(Mark(x, y, float(np.rad2deg(th)), r_out - r_in, 4.0, 0.6))
        truth.append(wrap_deg(float(np.rad2deg(th))))
    return Scene(width, height, tuple(marks), seed=seed, bits=12), truth


# ----------------------------------------------------------------------------- sessions

VIEWS = {  # view: (camera, image right, image up) as platform unit vectors
    "A": ("A", np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
    "Ar": ("A", np.array([-1.0, 0, 0]), np.array([0, 0, 1.0])),
    "B": ("B", np.array([0, 1.0, 0]), np.array([0, 0, 1.0])),
    "Br": ("B", np.array([0, -1.0, 0]), np.array([0, 0, 1.0])),
}
VIEW_KEYS = {"A": ("+X", "+Z"), "Ar": ("-X", "+Z"), "B": ("+Y", "+Z"), "Br": ("-Y", "+Z")}
IMAGES = [("x", "A", "horizontal"), ("z", "A", "vertical"), ("x", "Ar", "horizontal"),
          ("z", "Ar", "vertical"), ("y", "B", "horizontal"), ("z", "B", "vertical"),
          ("y", "Br", "horizontal"), ("z", "Br", "vertical")]
PLATFORM_POSES = {  # label: (up in the platform frame before levelling error, table deg)
    "L000": ("+Z", 0.0), "L090": ("+Z", 90.0), "L180": ("+Z", 180.0), "L270": ("+Z", 270.0),
    "Xup": ("+X", 0.0), "Xdn": ("-X", 0.0), "Yup": ("+Y", 0.0), "Ydn": ("-Y", 0.0)}


def rot(axis: str, ang: float) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def mark_angle_deg(s: np.ndarray, view: str) -> float:
    """The displayed direction of a housing's mark along the sensitive axis s (platform
    frame) in a view: atan2(s . up, s . right), as a line direction in (-90, 90]."""
    _, r, u = VIEWS[view]
    return wrap_deg(float(np.rad2deg(np.arctan2(s @ u, s @ r))))


@dataclass
class SessionSpec:
    E_arcsec: tuple = (40.0, -25.0, 15.0, 35.0, -20.0, 30.0)   # xY xZ yX yZ zX zY
    seed: int = 0
    level_arcsec: tuple = (0.0, 0.0)   # the levelled poses' up tilted towards +X, +Y
    creep_y_arcsec: float = 0.0        # the triad turned about Y after the images
    lens_A: Lens | None = None         # the real optics of camera A
    lens_A_keys: str = "zero"          # "zero": lens_* = 0 declared; "none": keys absent
    off_centre_A: float = 0.0          # camera A's marks this far off the centre [px]
    width: int = 480
    height: int = 360
    samples: int = 200
    images: bool = True                # False: tumble and platform only
    model_A: str = ""                  # a camera model file for [cameras.A] model


def write_session(folder: Path, sp: SessionSpec) -> dict:
    """A session folder (session.toml, tumble.csv, platform.csv, eight mark images) whose
    truth is E (E_ij = s_ij / s_ii); returns the truth."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(sp.seed)
    E = E_arcsec(*sp.E_arcsec)
    S_img = s_from_E(E)                                # the triad when imaged
    S_static = S_img @ rot("y", sp.creep_y_arcsec * ARCSEC).T   # after creep
    tri = Triad(S_static)
    write_tumble(folder / "tumble.csv", tumble_rows(tri, cube14(), rng, n=sp.samples))
    lines = ["pose,ux,uy,uz,t"]
    t0 = 0.0
    lx, ly = (np.asarray(sp.level_arcsec) * ARCSEC)
    for lab, (up, _) in PLATFORM_POSES.items():
        sign = 1.0 if up[0] == "+" else -1.0
        f = sign * np.eye(3)["XYZ".index(up[1])]
        if up[1] == "Z":
            f = np.array([lx, ly, 1.0])
            f /= np.linalg.norm(f)
        u = tri.read(np.tile(f, (sp.samples, 1)), rng)
        for i, ui in enumerate(u):
            lines.append(f"{lab},{ui[0]:.9e},{ui[1]:.9e},{ui[2]:.9e},{t0 + 0.05 * i:.3f}")
        t0 += 0.05 * sp.samples + 10
    (folder / "platform.csv").write_text("\n".join(lines) + "\n")
    toml = ['name = "user6"', "", "[calibration]", 'static = "tumble.csv"', ""]
    for cam in ("A", "B") if sp.images else ():
        toml.append(f"[cameras.{cam}]")
        if cam == "A" and sp.model_A:
            toml.append(f'model = "{sp.model_A}"')
        elif cam == "B" or sp.lens_A_keys == "zero":
            toml += [f"lens_{k} = 0.0" for k in ("k1", "k2", "p", "aspect", "pp_px")]
        toml.append("")
    for v, (cam, _, _) in VIEWS.items() if sp.images else ():
        r, u = VIEW_KEYS[v]
        toml += [f"[views.{v}]", f'camera = "{cam}"', f'right = "{r}"', f'up = "{u}"', ""]
    truth_marks = {}
    for i, (housing, view, nominal) in enumerate(IMAGES if sp.images else ()):
        s = S_img["xyz".index(housing)]
        a = mark_angle_deg(s, view)
        cam = VIEWS[view][0]
        off = sp.off_centre_A if cam == "A" else 0.0
        cx, cy = (sp.width - 1) / 2 + rng.uniform(-6, 6), (sp.height - 1) / 2
        if nominal == "horizontal":
            cy -= off           # a horizontal mark in the top of the frame
        else:
            cx -= off           # a vertical one at its left
        wh = (640, 480) if cam == "A" and sp.model_A else (sp.width, sp.height)
        cx, cy = cx + (wh[0] - sp.width) / 2, cy + (wh[1] - sp.height) / 2
        sc = Scene(*wh, (Mark(cx, cy, a, 250.0, 4.5, 0.6),),
                   lens=sp.lens_A if cam == "A" else None, seed=sp.seed * 100 + i, bits=12)
        name = f"{housing}_{view}.png"
        write_image(folder / name, render(sc))
        truth_marks[name] = a
        toml += ["[[images]]", f'file = "{name}"', f'housing = "{housing}"',
                 f'view = "{view}"', f'nominal = "{nominal}"', ""]
    toml += ["[platform]", 'static = "platform.csv"', "", "[platform.poses]"]
    for lab, (up, tab) in PLATFORM_POSES.items():
        toml.append(f'{lab} = {{ up = "{up}", table_deg = {tab} }}')
    (folder / "session.toml").write_text("\n".join(toml) + "\n")
    return {"E": E, "marks": truth_marks}


def recording(triad: Triad, dirs: np.ndarray, rng, rate: float = 50.0, static_s: float = 8.0,
              move_s: float = 3.0, shake_g: float = 0.02) -> np.ndarray:
    """A continuous tumble recording (t, ux, uy, uz): static poses joined by turns (the
    direction swept along a great circle, via a waypoint when the next pose is opposite),
    with a hand's shake of ``shake_g`` while moving."""
    def sweep(d0, d1, n):
        if d0 @ d1 < -0.9:
            w = np.cross(d0, rng.normal(size=3))
            w /= np.linalg.norm(w)
            return np.vstack([sweep(d0, w, n // 2), sweep(w, d1, n - n // 2)])
        ang = np.arccos(np.clip(d0 @ d1, -1, 1))
        s = 0.5 - 0.5 * np.cos(np.linspace(0, np.pi, n))
        if ang < 1e-9:
            return np.tile(d0, (n, 1))
        out = (np.sin((1 - s) * ang)[:, None] * d0 + np.sin(s * ang)[:, None] * d1) / np.sin(ang)
        return out
    ns, nm = int(static_s * rate), int(move_s * rate)
    f = []
    for i, d in enumerate(dirs):
        f.append(np.tile(d, (ns, 1)))
        if i + 1 < len(dirs):
            mv = sweep(d, dirs[i + 1], nm)
            mv = mv + rng.normal(0, shake_g, mv.shape)
            f.append(mv)
    f = np.vstack(f)
    t = np.arange(len(f)) / rate
    return np.column_stack([t, triad.read(f, rng)])


def write_recording(path: Path, rec: np.ndarray, with_t: bool = True) -> Path:
    h = "t,ux,uy,uz" if with_t else "ux,uy,uz"
    body = rec if with_t else rec[:, 1:]
    np.savetxt(path, body, delimiter=",", header=h, comments="", fmt="%.9e")
    return path
