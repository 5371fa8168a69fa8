"""Independent user 16's generator: three different cameras, scribe marks and chessboards.

Written from the documentation only (README, docs/, the schemas, ``--help``); it imports
nothing from the project. Physics, in this order, for every pixel:

1. the lens maps rays forward (OpenCV's model, k1 k2 p1 p2 [k3], principal point off the
   image centre): each sub-sample of a pixel is taken back to the pinhole (undistorted) image
   by iterating OpenCV's own model (``cv2.undistortPointsIter``) on a coarse grid, interpolated
   bicubically (the map is smooth to far below 1e-3 px over 4 px);
2. the scene there: a groove of width ``w`` blurred by a Gaussian ``s`` (the optics, applied
   *before* sampling; ``s`` may vary along the mark: a defocus gradient), its ends blurred
   likewise, the groove's centre bowed by a sagitta (a bent printed mark), on a background
   lit unevenly (linear gradient and vignetting); a chessboard is ray-traced onto its plane;
3. integrated over the pixel's area (n x n sub-samples), then column fixed-pattern noise,
   Poisson shot noise in electrons, Gaussian read noise, quantised to 8/12/16 bits; the
   webcam's frame is JPEG-compressed.

Truth: the angle of the mark's chord in the pinhole image (``angle_deg`` convention of
``align marks``: from +x towards -y, in (-90, 90]); offset from the image centre
((W-1)/2, (H-1)/2) along the normal (sin a, cos a).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage
from scipy.special import erf


@dataclasses.dataclass(frozen=True)
class Camera:
    name: str
    width: int
    height: int
    f: float
    cx: float
    cy: float
    dist: tuple  # k1, k2, p1, p2, k3
    bits: int
    full_well: float  # electrons at full scale
    read_e: float  # read noise [e-]
    fpn: float  # column fixed-pattern noise, fraction of the level
    jpeg: int = 0  # JPEG quality (0: lossless)
    ss: int = 4  # sub-samples per pixel side

    @property
    def K(self):
        return np.array([[self.f, 0, self.cx], [0, self.f, self.cy], [0, 0, 1.0]])

    @property
    def D(self):
        return np.array(self.dist, float)


WEBCAM = Camera("webcam", 640, 480, 520.0, 331.0, 229.0, (-0.32, 0.11, 0.0, 0.0, 0.0),
                8, 6000.0, 6.0, 0.004, jpeg=92, ss=4)
MACHINE = Camera("machine", 2448, 2048, 5200.0, 1240.0, 1009.0,
                 (0.015, 0.0, 9e-4, -7e-4, 0.0), 12, 12000.0, 3.0, 0.002, ss=3)
MICRO = Camera("micro", 1280, 1024, 20000.0, 646.0, 507.0, (0.0, 0.0, 0.0, 0.0, 0.0),
               16, 30000.0, 4.0, 0.001, ss=3)
CAMERAS = {c.name: c for c in (WEBCAM, MACHINE, MICRO)}


def distort(cam: Camera, xn, yn):
    """OpenCV's forward model on normalised pinhole coordinates."""
    k1, k2, p1, p2, k3 = cam.dist
    r2 = xn * xn + yn * yn
    rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = xn * rad + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * rad + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


def _undistort(cam: Camera, u, v):
    """Invert the forward model (fixed point, checked to 1e-6 px)."""
    xd, yd = (u - cam.cx) / cam.f, (v - cam.cy) / cam.f
    x, y = xd.copy(), yd.copy()
    for _ in range(200):
        fx, fy = distort(cam, x, y)
        x, y = x + (xd - fx), y + (yd - fy)
    fx, fy = distort(cam, x, y)
    err = np.max(np.hypot(fx - xd, fy - yd)) * cam.f
    assert err < 1e-6, err
    return x * cam.f + cam.cx, y * cam.f + cam.cy


def pinhole_coords(cam: Camera, x0, y0, w, h, ss):
    """Pinhole (undistorted) coordinates of the ss x ss sub-samples of the pixels of a box.

    Returns arrays of shape (h*ss, w*ss); pixel centres at integer coordinates.
    """
    step, pad = 4, 8
    gx = np.arange(x0 - pad * step, x0 + w + pad * step + 1, step, dtype=float)
    gy = np.arange(y0 - pad * step, y0 + h + pad * step + 1, step, dtype=float)
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    xs = (np.arange(x0, x0 + w)[:, None] + sub[None, :]).ravel()
    ys = (np.arange(y0, y0 + h)[:, None] + sub[None, :]).ravel()
    XS, YS = np.meshgrid(xs, ys)
    if not np.any(cam.D):
        return XS, YS
    GX, GY = np.meshgrid(gx, gy)
    UX, UY = _undistort(cam, GX, GY)
    # interpolate the lens's displacement (smooth, small), not the coordinates: a spline's
    # boundary condition does not reproduce a ramp, and the pad keeps its ringing far away
    ci = (XS - gx[0]) / step
    ri = (YS - gy[0]) / step
    ux = XS + ndimage.map_coordinates(UX - GX, [ri, ci], order=3, mode="nearest")
    uy = YS + ndimage.map_coordinates(UY - GY, [ri, ci], order=3, mode="nearest")
    return ux, uy


def _bin(a, ss):
    h, w = a.shape[0] // ss, a.shape[1] // ss
    return a.reshape(h, ss, w, ss).mean(axis=(1, 3))


def _box(t, half, s):
    """A box of half-width ``half`` blurred by a Gaussian of sigma ``s``."""
    r = np.sqrt(2.0) * s
    return 0.5 * (erf((t + half) / r) - erf((t - half) / r))


@dataclasses.dataclass(frozen=True)
class Mark:
    """A straight (or bowed) groove in the pinhole image: centre, chord angle, length."""
    xc: float
    yc: float
    angle_deg: float
    length: float
    width: float = 3.0
    depth: float = 0.55  # fraction of the background absorbed
    blur0: float = 1.0  # Gaussian sigma at the start [px]
    blur1: float = 1.0  # ... at the end: a defocus gradient
    sagitta: float = 0.0  # bow of the printed mark [px] (+: towards the normal)


def truth(cam: Camera, m: Mark):
    """The chord's angle [deg] and offset [px] in the tool's conventions."""
    a = math.radians(m.angle_deg)
    while m.angle_deg > 90:
        m = dataclasses.replace(m, angle_deg=m.angle_deg - 180)
    while m.angle_deg <= -90:
        m = dataclasses.replace(m, angle_deg=m.angle_deg + 180)
    a = math.radians(m.angle_deg)
    n = (math.sin(a), math.cos(a))
    xc0, yc0 = (cam.width - 1) / 2, (cam.height - 1) / 2
    return m.angle_deg, (m.xc - xc0) * n[0] + (m.yc - yc0) * n[1]


def illumination(cam: Camera, X, Y, rng):
    gx, gy = rng.uniform(-0.25, 0.25, 2)
    vig = rng.uniform(0.0, 0.3)
    xn = (X - cam.width / 2) / (cam.width / 2)
    yn = (Y - cam.height / 2) / (cam.height / 2)
    return np.clip(1.0 + gx * xn + gy * yn - vig * (xn ** 2 + yn ** 2) / 2, 0.3, 2.0)


def _sensor(cam: Camera, signal, rng, level):
    """signal: mean fraction of full scale per pixel -> quantised DN."""
    fs = 2 ** cam.bits - 1
    cols = 1.0 + cam.fpn * rng.standard_normal(signal.shape[1])
    e = signal * cols[None, :] * level * cam.full_well
    e = rng.poisson(np.clip(e, 0, None)).astype(float) + cam.read_e * rng.standard_normal(e.shape)
    dn = np.clip(np.round(e / cam.full_well * fs), 0, fs)
    return dn.astype(np.uint8 if cam.bits == 8 else np.uint16)


def render_marks(cam: Camera, marks, rng, level=0.7, illum_seed=None):
    """The frame holding ``marks``; returns the quantised image."""
    H, W = cam.height, cam.width
    Y, X = np.mgrid[0:H, 0:W].astype(float)
    irng = np.random.default_rng(illum_seed) if illum_seed is not None else rng
    light = illumination(cam, X, Y, irng)
    absorb = np.zeros((H, W))
    for m in marks:
        a = math.radians(m.angle_deg)
        d = np.array([math.cos(a), -math.sin(a)])  # along (image y down)
        n = np.array([math.sin(a), math.cos(a)])
        half = m.length / 2
        # the pixels the mark can touch, through the lens (bounding box + margin)
        ends = np.array([[m.xc, m.yc] - d * half, [m.xc, m.yc] + d * half])
        pe = cv2.projectPoints(
            np.c_[(ends - [cam.cx, cam.cy]) / cam.f, np.ones(2)].astype(float),
            np.zeros(3), np.zeros(3), cam.K, cam.D)[0].reshape(-1, 2)
        mg = 8 + 4 * max(m.blur0, m.blur1) + m.width + abs(m.sagitta)
        x0 = int(max(0, math.floor(pe[:, 0].min() - mg)))
        x1 = int(min(W, math.ceil(pe[:, 0].max() + mg)))
        y0 = int(max(0, math.floor(pe[:, 1].min() - mg)))
        y1 = int(min(H, math.ceil(pe[:, 1].max() + mg)))
        ux, uy = pinhole_coords(cam, x0, y0, x1 - x0, y1 - y0, cam.ss)
        t = (ux - m.xc) * d[0] + (uy - m.yc) * d[1]
        q = (ux - m.xc) * n[0] + (uy - m.yc) * n[1]
        q = q - m.sagitta * (1 - (np.clip(t, -half, half) / half) ** 2)
        s = m.blur0 + (m.blur1 - m.blur0) * (np.clip(t, -half, half) + half) / m.length
        prof = _box(q, m.width / 2, s) * _box(t, half, s)
        absorb[y0:y1, x0:x1] = np.maximum(absorb[y0:y1, x0:x1], m.depth * _bin(prof, cam.ss))
    img = _sensor(cam, light * (1 - absorb), rng, level)
    return img


def render_family(cam: Camera, xc, yc, angle_deg, pitch, n, length, rng, width=4.0,
                  blur=1.2, level=0.6):
    """A ruled stage micrometer: n parallel lines, ``pitch`` apart, centred on (xc, yc)."""
    a = math.radians(angle_deg)
    nrm = np.array([math.sin(a), math.cos(a)])
    marks = [Mark(xc + (i - (n - 1) / 2) * pitch * nrm[0], yc + (i - (n - 1) / 2) * pitch * nrm[1],
                  angle_deg, length, width=width, blur0=blur, blur1=blur, depth=0.6)
             for i in range(n)]
    return render_marks(cam, marks, rng, level=level), marks


def save(cam: Camera, img, path: Path):
    path = Path(path)
    if cam.jpeg:
        path = path.with_suffix(".jpg")
        cv2.imwrite(str(path), img, [cv2.IMWRITE_JPEG_QUALITY, cam.jpeg])
    elif cam.bits == 16:
        path = path.with_suffix(".tif")
        cv2.imwrite(str(path), img)
    else:
        path = path.with_suffix(".png")
        cv2.imwrite(str(path), img)
    return path


# ------------------------------------------------------------------ chessboards


def _board_pose(rng, cols, rows, sq, cam: Camera, fill):
    """A board pose that fills ~``fill`` of the frame, tilted up to 35 deg, roughly centred."""
    bw, bh = (cols + 1) * sq, (rows + 1) * sq
    dist = cam.f * bw / (fill * cam.width)
    for _ in range(200):
        rv = np.deg2rad(rng.uniform(-35, 35, 3)) * np.array([1, 1, 0.4])
        R = cv2.Rodrigues(rv)[0]
        off = rng.uniform(-0.25, 0.25, 2) * np.array([cam.width, cam.height]) / cam.f * dist
        t = np.array([off[0], off[1], dist]) - R @ np.array([bw / 2, bh / 2, 0])
        corners = np.array([[x, y, 0] for x in (0, bw) for y in (0, bh)], float)
        p = cv2.projectPoints(corners, rv, t, cam.K, cam.D)[0].reshape(-1, 2)
        if (p[:, 0].min() > 10 and p[:, 1].min() > 10 and p[:, 0].max() < cam.width - 10
                and p[:, 1].max() < cam.height - 10):
            return R, t
    raise RuntimeError("no pose fits")


_MAPS: dict = {}


def render_board(cam: Camera, rng, cols=9, rows=6, sq=1.0, fill=0.7, blur=0.8, ss=2):
    """A chessboard photograph (cols x rows inner corners) through the camera."""
    key = (cam, ss)
    if key not in _MAPS:  # one map per camera: the views share it
        _MAPS.clear()
        _MAPS[key] = pinhole_coords(cam, 0, 0, cam.width, cam.height, ss)
    ux, uy = _MAPS[key]
    R, t = _board_pose(rng, cols, rows, sq, cam, fill)
    xn, yn = (ux - cam.cx) / cam.f, (uy - cam.cy) / cam.f
    nvec = R[:, 2]
    lam = (nvec @ t) / (nvec[0] * xn + nvec[1] * yn + nvec[2])
    P = np.stack([lam * xn - t[0], lam * yn - t[1], lam - t[2]], -1) @ R  # R^T (X - t)
    bx, by = P[..., 0] / sq, P[..., 1] / sq
    inside = (bx >= 0) & (bx < cols + 1) & (by >= 0) & (by < rows + 1)
    chk = ((np.floor(bx) + np.floor(by)) % 2 == 0) & inside
    refl = np.where(chk, 0.08, 0.9)
    refl = ndimage.gaussian_filter(refl, blur * ss)  # optics before sampling
    sig = _bin(refl, ss)
    Y, X = np.mgrid[0:cam.height, 0:cam.width].astype(float)
    sig = sig * illumination(cam, X, Y, rng)
    return _sensor(cam, sig, rng, 0.8)


def random_mark(cam: Camera, rng, where=None):
    """A mark as a user brings it: anywhere (centre, off-centre, corner), any length and
    direction, a defocus gradient, a bent print (sagitta 0.3-1 px in a third of them)."""
    where = where or rng.choice(["centre", "off", "corner"])
    W, H = cam.width, cam.height
    short = min(W, H)
    L = rng.uniform(0.25, 0.5) * short
    ang = rng.uniform(-90, 90)
    if where == "centre":
        fx, fy = rng.uniform(-0.08, 0.08, 2)
    elif where == "off":
        fx, fy = rng.uniform(-0.25, 0.25, 2)
    else:
        fx, fy = rng.choice([-1, 1], 2) * rng.uniform(0.25, 0.32, 2)
    b0 = rng.uniform(0.7, 1.5)
    b1 = b0 * rng.choice([1.0, rng.uniform(1.2, 2.0)])
    sag = rng.choice([0.0, 0.0, rng.uniform(0.3, 1.0) * rng.choice([-1, 1])])
    return Mark(W / 2 + fx * W, H / 2 + fy * H, ang, L, width=rng.uniform(2.5, 5.0),
                depth=rng.uniform(0.3, 0.7), blur0=b0, blur1=b1, sagitta=sag)


# ------------------------------------------------------------------ a whole session

ARCSEC = math.pi / 180 / 3600
VIEWS = {  # view: camera, right, up (platform unit vectors)
    "A": ("A", (1, 0, 0), (0, 0, 1)), "Ar": ("A", (-1, 0, 0), (0, 0, 1)),
    "B": ("B", (0, 1, 0), (0, 0, 1)), "Br": ("B", (0, -1, 0), (0, 0, 1)),
    "C": ("C", (1, 0, 0), (0, 1, 0)),  # the microscope, looking down: sees x against Y
}
HOUSINGS = {"A": ("x", "z"), "Ar": ("x", "z"), "B": ("y", "z"), "Br": ("y", "z"), "C": ("x",)}
ANGLES = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")


def axes(E):
    """The sensitivity axes s_i (rows of I + E) from a dict of E_ij [rad]."""
    M = np.eye(3)
    idx = {"x": 0, "y": 1, "z": 2, "X": 0, "Y": 1, "Z": 2}
    for k, v in E.items():
        M[idx[k[2]], idx[k[3]]] = v
    return {h: M[i] / np.linalg.norm(M[i]) for h, i in (("x", 0), ("y", 1), ("z", 2))}


def image_angle_deg(s, right, up, roll_rad=0.0):
    """A mark along s seen in a view: atan2(s.u, s.r) + roll, as a line in (-90, 90]."""
    a = math.degrees(math.atan2(float(np.dot(s, up)), float(np.dot(s, right))) + roll_rad)
    return (a + 90) % 180 - 90 if (a + 90) % 180 != 0 else 90.0


def gonio_log(E, rng, faces=("ref", "y", "x", "z"), revs=12, latitude_deg=50.45,
              counts_per_rev=2 ** 21, noise_arcsec=0.15, ref_offset_rad=0.0, rev_s=30.0):
    """Counter-log rows (count, counter, ref, t): the table turning ccw at ~constant rate.

    Face normals' azimuths psi (ref along +X... here: ref at its offset, x at 0 + E_xY,
    y at 90 deg - E_yX); faces pass in order of decreasing azimuth (docs/concepts.md).
    """
    s = axes(E)
    psi = {"x": math.atan2(s["x"][1], s["x"][0]),
           "y": math.atan2(s["y"][1], s["y"][0]),
           "ref": math.pi / 2 + math.pi / 2 + ref_offset_rad,  # nominally 90 deg beyond y
           "z": -math.pi / 2}
    # passing order ref -> y -> x -> z: decreasing azimuth, nominally 90 deg steps
    az = [psi[f] for f in faces]
    steps = [(az[k] - az[(k + 1) % 4]) % (2 * math.pi) for k in range(4)]
    earth = 7.292115e-5 * math.sin(math.radians(latitude_deg))
    rows, t, counter = [], 0.0, 1
    err_prev = rng.normal(0, noise_arcsec * ARCSEC)
    frac = rng.uniform()
    for _rev in range(revs):
        for k in range(4):
            dpsi = steps[k]
            dt = rev_s * dpsi / (2 * math.pi) * rng.uniform(0.97, 1.03)
            err = rng.normal(0, noise_arcsec * ARCSEC)
            sensed = dpsi + earth * dt + err - err_prev
            err_prev = err
            c = sensed / (2 * math.pi) * counts_per_rev + frac
            n = int(math.floor(c))
            frac = c - n
            t += dt
            rows.append((n, counter, 1 if (k + 1) % 4 == 0 else 0, t))
            counter = 3 - counter
    return rows


def write_session(folder, seed, cams, models=None, E=None, roll_arcsec=None, where=None,
                  tolerance_arcsec=60.0, sagitta=0.0, lens_keys=None, ref_u_arcsec=2.0):
    """A session folder (cameras + goniometer) with known E; returns the truth.

    cams: {"A": Camera, "B": Camera}; models: {"A": "camA.json"} paths copied in (or None:
    ``lens_keys`` {"A": {...}} written instead).
    """
    import shutil

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    if E is None:
        E = {k: rng.uniform(-80, 80) * ARCSEC for k in ANGLES}
    roll = roll_arcsec if roll_arcsec is not None else {c: rng.uniform(-40, 40) for c in cams}
    s = axes(E)
    toml = [f'name = "u16-{seed}"', "latitude_deg = 50.45", "",
            "[goniometer]", 'log = "gonio.csv"', 'faces = ["ref", "y", "x", "z"]',
            "nominal_deg = [90.0, 90.0, 90.0, 90.0]", 'direction = "ccw"',
            "reference_offset_arcsec = 0.0", f"reference_offset_u_arcsec = {ref_u_arcsec}", ""]
    for c in cams:
        toml.append(f"[cameras.{c}]")
        if models and models.get(c):
            shutil.copy(models[c], folder / f"cam{c}.json")
            toml.append(f'model = "cam{c}.json"')
        for k, v in ((lens_keys or {}).get(c) or {}).items():
            toml.append(f"{k} = {v}")
        toml.append("")
    for v, (c, r, u) in VIEWS.items():
        if c not in cams:
            continue
        name = {(1, 0, 0): "+X", (-1, 0, 0): "-X", (0, 1, 0): "+Y", (0, -1, 0): "-Y"}[r]
        upn = {(0, 0, 1): "+Z", (0, 1, 0): "+Y"}[u]
        toml += [f"[views.{v}]", f'camera = "{c}"', f'right = "{name}"', f'up = "{upn}"', ""]
    truth_marks = {}
    for v, (c, r, u) in VIEWS.items():
        if c not in cams:
            continue
        cam = cams[c]
        for h in HOUSINGS[v]:
            ang = image_angle_deg(s[h], np.array(r, float), np.array(u, float),
                                  roll[c] * ARCSEC)
            m = random_mark(cam, rng, where=where)
            m = dataclasses.replace(m, angle_deg=ang, sagitta=sagitta,
                                    length=min(m.length, 0.45 * min(cam.width, cam.height)))
            img = render_marks(cam, [m], rng)
            p = save(cam, img, folder / f"{h}_{v}")
            truth_marks[p.name] = ang
            nominal = "horizontal" if h in ("x", "y") else "vertical"
            toml += ["[[images]]", f'file = "{p.name}"', f'housing = "{h}"', f'view = "{v}"',
                     f'nominal = "{nominal}"', ""]
    rows = gonio_log(E, rng)
    with open(folder / "gonio.csv", "w") as fh:
        fh.write("count,counter,ref,t\n")
        for n, ctr, ref, t in rows:
            fh.write(f"{n},{ctr},{ref},{t:.6f}\n")
    if tolerance_arcsec:
        toml += ["[tolerance]", f"arcsec = {tolerance_arcsec}", ""]
    (folder / "session.toml").write_text("\n".join(toml) + "\n")
    return {"E_arcsec": {k: v / ARCSEC for k, v in E.items()}, "roll_arcsec": roll,
            "marks_deg": truth_marks}
