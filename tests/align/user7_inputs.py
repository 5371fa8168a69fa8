"""Independent user 7's input generators, written from physics (numpy/scipy/opencv only).

Nothing here imports from the project: the images are rendered from a scene (a scribed groove
on a flat housing face, fronto-parallel to the camera) through an OpenCV Brown-Conrady lens of
my own choosing, by supersampling each pixel's area: every sub-sample is mapped back through
the lens (``cv2.undistortPointsIter``) into the normalised pinhole plane, where the groove is a
straight band. So a straight groove is bowed by the lens exactly as a real camera bows it, and
the truth angle is the groove's direction in the normalised plane (which a fronto-parallel
housing face preserves), in the tool's convention (from +x towards -y, in (-90, 90] degrees).

The groove is flat-bottomed, ``width_px`` wide, its reflectance ``contrast`` lower, with square
ends, seen through a Gaussian PSF (defocus, ``blur_px``) convolved analytically. The sensor
integrates each pixel's area (sub-samples) and adds shot noise (Poisson on ``full_well``
electrons at full scale) and read noise, and quantises to 8, 12 (in a 16-bit file) or 16 bits.
"""

from __future__ import annotations

import csv
import glob
import math
import os
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.ndimage import map_coordinates
from scipy.special import erf as _erf

REAL = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "data", "real")
CHESSBOARD = os.path.join(REAL, "opencv-chessboard")


@dataclass
class Lens:
    """An OpenCV camera: K (fx, fy, cx, cy in px) and dist (k1 k2 p1 p2 k3)."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def camera_json(self, size: tuple[int, int], u: dict | None = None) -> dict:
        """A camera model in the documented `align camera` format (docs/formats.md)."""
        d = {
            "format": "axis-align/camera",
            "format_version": 3,
            "camera_matrix": self.K.tolist(),
            "dist_coeffs": list(self.dist),
            "image_size": [int(size[0]), int(size[1])],
            "rms_px": 0.1,
            "views": 10,
        }
        if u is not None:
            d["u"] = u
        return d


def chessboard_lens(side: str = "left") -> tuple[Lens, tuple[int, int]]:
    """Calibrate the real OpenCV sample camera myself (cv2.calibrateCamera, 9x6 inner corners)."""
    files = sorted(glob.glob(os.path.join(CHESSBOARD, f"{side}0*.jpg")))
    objp = np.zeros((9 * 6, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj, img, size = [], [], None
    for f in files:
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        size = g.shape[::-1]
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3))
        obj.append(objp)
        img.append(c)
    _, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None)
    d = tuple(float(v) for v in dist.ravel()[:5])
    return Lens(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), d), size


def charuco_lens() -> Lens:
    """The real camera of OpenCV's ChArUco tutorial (its own calibration, fy/fx = 1.0094)."""
    fs = cv2.FileStorage(os.path.join(REAL, "opencv-lines", "tutorial_camera_charuco.yml"),
                         cv2.FILE_STORAGE_READ)
    K = fs.getNode("camera_matrix").mat()
    D = fs.getNode("distortion_coefficients").mat().ravel()
    return Lens(float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                tuple(float(v) for v in D[:5]))


@dataclass
class Mark:
    """A straight groove in the normalised plane: centre and direction given in *ideal pixels*
    (normalised coordinates x fx, measured from the principal point) for convenience."""

    centre_px: tuple[float, float]  # ideal-pixel position of the mark's middle from (cx, cy)
    angle_deg: float  # tool convention: from +x towards -y (counter-clockwise as displayed)
    length_px: float = 300.0
    width_px: float = 4.0
    contrast: float = 0.5
    sagitta_px: float = 0.0  # a truly bent groove (parabolic bow), in ideal pixels
    wiggle_px: float = 0.0  # scribe chatter: a lateral sine of this amplitude [ideal px]
    wiggle_period_px: float = 60.0


@dataclass
class Scene:
    size: tuple[int, int] = (640, 480)  # W, H
    lens: Lens | None = None
    marks: list = field(default_factory=list)
    background: float = 0.7  # reflectance of the surface (fraction of full scale)
    shading: float = 0.05  # linear illumination fall-off across the frame
    blur_px: float = 0.8  # defocus PSF sigma [px]
    full_well: float = 20000.0  # electrons at full scale
    read_noise_e: float = 10.0
    bits: int = 16  # 8, 12 (stored in a 16-bit file) or 16
    supersample: int = 3
    scale_lines: dict | None = None  # a ruled scale: {"angle_deg", "pitch_px", "n", "length_px"}


def _sub_grid(W: int, H: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    o = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(W)[:, None] + o[None, :]).ravel()
    ys = (np.arange(H)[:, None] + o[None, :]).ravel()
    return np.meshgrid(xs, ys)  # shape (H*s, W*s)


def ideal_coords(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Each sub-sample's position in ideal pixels (normalised x fx) about the principal point."""
    W, H = scene.size
    X, Y = _sub_grid(W, H, scene.supersample)
    L = scene.lens
    if L is None:
        return X - (W - 1) / 2, Y - (H - 1) / 2
    # The lens map is smooth: undistort a 2-px grid exactly and interpolate it (cubic) at the
    # sub-samples, which is ~1e-5 px accurate and 20x faster than undistorting every sub-sample.
    step = 1.0
    gx = np.arange(-4.0, W + 4.0, step)
    gy = np.arange(-4.0, H + 4.0, step)
    GX, GY = np.meshgrid(gx, gy)
    pts = np.stack([GX.ravel(), GY.ravel()], axis=1).astype(np.float64)[:, None, :]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 60, 1e-12)
    und = cv2.undistortPoints(pts, L.K, np.array(L.dist, float), criteria=crit)
    und = und.reshape(GX.shape + (2,)) * L.fx
    fr = np.stack([(Y - gy[0]) / step, (X - gx[0]) / step])
    xi = map_coordinates(und[..., 0], fr, order=3)
    yi = map_coordinates(und[..., 1], fr, order=3)
    return xi, yi


def _groove_depth(xi: np.ndarray, yi: np.ndarray, m: Mark, blur_px: float) -> np.ndarray:
    a = math.radians(m.angle_deg)
    d = np.array([math.cos(a), -math.sin(a)])  # direction in image coords (y down)
    n = np.array([math.sin(a), math.cos(a)])
    dx, dy = xi - m.centre_px[0], yi - m.centre_px[1]
    t = dx * d[0] + dy * d[1]
    sn = dx * n[0] + dy * n[1]
    if m.sagitta_px:
        half = m.length_px / 2
        sn = sn - m.sagitta_px * (1 - (t / half) ** 2)  # parabolic bow (sagitta at the middle)
    if m.wiggle_px:
        sn = sn - m.wiggle_px * np.sin(2 * np.pi * t / m.wiggle_period_px + 0.7)
    # a flat-bottomed groove seen through the Gaussian PSF, convolved analytically: point
    # sampling a sharp-edged profile on the sub-sample grid aliases it onto the pixel grid
    # (measured: a -200" mark rendered at -143" with 2x2 sub-samples), the erf edges do not.
    hw = m.width_px / 2
    sig = math.sqrt(2) * max(blur_px, 0.3)
    half = m.length_px / 2
    # Beyond hw + 8 sig from the groove both erf are exactly -1 and +1 (|argument| > 6):
    # the depth there is exactly 0, so only the sub-samples nearer are evaluated (the same
    # array bit for bit; a NaN position stays among those evaluated).
    near = ~(np.abs(sn) > hw + 8 * sig)
    sn, t = sn[near], t[near]
    prof = 0.5 * (_erf((hw - sn) / sig) + _erf((hw + sn) / sig))
    end = 0.5 * (_erf((half - t) / sig) + _erf((half + t) / sig))
    out = np.zeros(near.shape)
    out[near] = prof * end
    return out


def render(scene: Scene, seed: int = 0) -> np.ndarray:
    """The image as an integer array (uint8 or uint16)."""
    rng = np.random.default_rng(seed)
    W, H = scene.size
    s = scene.supersample
    xi, yi = ideal_coords(scene)
    depth = np.zeros_like(xi)
    marks = list(scene.marks)
    if scene.scale_lines:
        sl = scene.scale_lines
        a = math.radians(sl["angle_deg"])
        nrm = np.array([math.sin(a), math.cos(a)])
        c0 = np.array(sl.get("centre_px", (0.0, 0.0)))
        for k in range(sl["n"]):
            off = (k - (sl["n"] - 1) / 2) * sl["pitch_px"]
            c = c0 + off * nrm
            marks.append(Mark((c[0], c[1]), sl["angle_deg"], sl["length_px"],
                              sl.get("width_px", 4.0), sl.get("contrast", 0.5)))
    for m in marks:
        depth = np.maximum(depth, _groove_depth(xi, yi, m, scene.blur_px) * m.contrast)
    X, Y = _sub_grid(W, H, s)
    illum = 1 + scene.shading * (X / W - 0.5)
    refl = scene.background * (1 - depth) * illum
    img = refl.reshape(H, s, W, s).mean(axis=(1, 3))
    electrons = rng.poisson(np.clip(img, 0, None) * scene.full_well).astype(float)
    electrons += rng.normal(0, scene.read_noise_e, electrons.shape)
    full = 2 ** scene.bits - 1
    dn = np.clip(np.round(electrons / scene.full_well * full), 0, full)
    return dn.astype(np.uint8 if scene.bits == 8 else np.uint16)


def truth_angle(m: Mark) -> float:
    """The tool's convention, (-90, 90] degrees."""
    a = (m.angle_deg + 90.0) % 180.0 - 90.0
    return 90.0 if a == -90.0 else a


def write_png(path: str, img: np.ndarray) -> str:
    cv2.imwrite(path, img)
    return path


# ---------------------------------------------------------------------------------------------
# Static tumble of a triad (for `align calibrate`), from the physics of a misaligned triad.
# ---------------------------------------------------------------------------------------------

def tumble_poses(n: int, rng: np.random.Generator) -> np.ndarray:
    """n gravity directions in the sensor frame: the 6 faces then random attitudes."""
    faces = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    extra = rng.normal(size=(max(0, n - 6), 3))
    extra /= np.linalg.norm(extra, axis=1, keepdims=True)
    return np.vstack([faces, extra])[:n]


def tumble_csv(path: str, seed: int, n_poses: int = 18, samples: int = 50,
               scale=(1.02, 0.98, 1.01), bias=(0.01, -0.02, 0.015),
               mis_rad=(1e-3, -5e-4, 7e-4, 2e-4, -8e-4, 3e-4), noise_g: float = 2e-4,
               quad: float = 0.0, cross_quad: float = 0.0, drift_per_pose: float = 0.0,
               units_scale: float = 1.0) -> dict:
    """Write pose,ux,uy,uz samples (V); return the truth (scale, bias, the lower-triangular
    misalignment) so a test can compare.  Effects: ``quad`` a second-order term k2 g^2 on
    every axis, ``cross_quad`` a cross-axis term g_x g_y on ux, ``drift_per_pose`` a scale
    drift (fraction per pose, e.g. warm-up)."""
    rng = np.random.default_rng(seed)
    g = tumble_poses(n_poses, rng)
    a = mis_rad
    M = np.array([[1, -a[0], a[1]], [a[2], 1, -a[3]], [-a[4], a[5], 1]])
    S = np.diag(scale)
    rows = []
    for i, gi in enumerate(g):
        drift = 1 + drift_per_pose * i
        for _ in range(samples):
            u = drift * (S @ M @ gi) + np.array(bias) + quad * gi ** 2
            u[0] += cross_quad * gi[0] * gi[1]
            u += rng.normal(0, noise_g, 3)
            rows.append((f"P{i:02d}", *(u * units_scale)))
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["pose", "ux", "uy", "uz"])
        for r in rows:
            w.writerow([r[0]] + [f"{v:.7f}" for v in r[1:]])
    return {"scale": scale, "bias": bias, "M": M}


# ---------------------------------------------------------------------------------------------
# A whole session with known truth E: cameras A (along Y) and B (along X) with their reversals,
# a tumble of the triad, and the mounted triad's static readings (docs/concepts.md).
# ---------------------------------------------------------------------------------------------

ARCSEC = math.pi / 180 / 3600
E_NAMES = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")
AXIS = {"+X": (1, 0, 0), "-X": (-1, 0, 0), "+Y": (0, 1, 0), "-Y": (0, -1, 0),
        "+Z": (0, 0, 1), "-Z": (0, 0, -1)}
VIEWS = {"A": ("+X", "+Z", "A"), "Ar": ("-X", "+Z", "A"), "B": ("+Y", "+Z", "B"),
         "Br": ("-Y", "+Z", "B")}
IMAGES = [("x", "A", "horizontal"), ("z", "A", "vertical"), ("x", "Ar", "horizontal"),
          ("z", "Ar", "vertical"), ("y", "B", "horizontal"), ("z", "B", "vertical"),
          ("y", "Br", "horizontal"), ("z", "Br", "vertical")]


def axes_from_E(E_arcsec: dict) -> np.ndarray:
    """Unit sensitivity axes s_i (rows) in the platform frame: row i of I + E, normalised."""
    M = np.eye(3)
    idx = {"x": 0, "y": 1, "z": 2, "X": 0, "Y": 1, "Z": 2}
    for name, v in E_arcsec.items():
        M[idx[name[2]], idx[name[3]]] = v * ARCSEC
    return M / np.linalg.norm(M, axis=1, keepdims=True)


def write_session(folder: str, seed: int, E_arcsec: dict, lens_A: Lens | None = None,
                  lens_B: Lens | None = None, camera_keys: dict | None = None,
                  positions: dict | None = None, size=(640, 480), roll_A_arcsec: float = 0.0,
                  noise_g: float = 1e-4, tolerance_arcsec: float | None = None,
                  supersample: int = 2, platform_samples: int = 40) -> dict:
    """Write a session folder (session.toml and its files); return the truth.

    ``camera_keys`` maps camera name to extra ``[cameras.X]`` lines (e.g. lens declarations).
    ``positions`` maps an image's file stem (``x_A``) to the mark's ideal-pixel centre."""
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    S = axes_from_E(E_arcsec)
    k = np.array([2.01, 1.98, 2.03])  # V/g
    b = np.array([0.012, -0.021, 0.008])  # V
    # tumble: the triad alone in 18 attitudes, 40 samples each
    with open(os.path.join(folder, "tumble.csv"), "w") as fh:
        fh.write("pose,ux,uy,uz\n")
        for i, g in enumerate(tumble_poses(18, rng)):
            for _ in range(40):
                u = k * (S @ g) + b + rng.normal(0, noise_g, 3) * k
                fh.write(f"T{i:02d}," + ",".join(f"{v:.7f}" for v in u) + "\n")
    poses = {"L000": ("+Z", 0), "L090": ("+Z", 90), "L180": ("+Z", 180), "L270": ("+Z", 270),
             "Xup": ("+X", 0), "Xdn": ("-X", 0), "Yup": ("+Y", 0), "Ydn": ("-Y", 0)}
    with open(os.path.join(folder, "platform.csv"), "w") as fh:
        fh.write("pose,ux,uy,uz\n")
        for name, (up, _) in poses.items():
            f = np.array(AXIS[up], float)
            for _ in range(platform_samples):
                u = k * (S @ f) + b + rng.normal(0, noise_g, 3) * k
                fh.write(f"{name}," + ",".join(f"{v:.7f}" for v in u) + "\n")
    positions = positions or {}
    lenses = {"A": lens_A, "B": lens_B}
    truth_angles = {}
    toml = [f'name = "{os.path.basename(folder)}"', "", "[calibration]",
            'static = "tumble.csv"', 'units = "V"', 'scale_sign = "+"', ""]
    for cam in ("A", "B"):
        toml.append(f"[cameras.{cam}]")
        toml += (camera_keys or {}).get(cam, [])
        toml.append("")
    for v, (r, u, cam) in VIEWS.items():
        toml += [f"[views.{v}]", f'camera = "{cam}"', f'right = "{r}"', f'up = "{u}"', ""]
    H = {"x": 0, "y": 1, "z": 2}
    for j, (h, v, nominal) in enumerate(IMAGES):
        r, u, cam = VIEWS[v]
        s = S[H[h]]
        ang = math.degrees(math.atan2(s @ np.array(AXIS[u]), s @ np.array(AXIS[r])))
        if cam == "A":
            ang += roll_A_arcsec / 3600
        stem = f"{h}_{v}"
        pos = positions.get(stem, (0.0, 0.0))
        m = Mark(pos, ang, 260.0)
        truth_angles[stem] = truth_angle(m)
        lens = lenses[cam]
        if lens is None:
            lens = Lens(1000.0, 1000.0, (size[0] - 1) / 2, (size[1] - 1) / 2)
        img = render(Scene(size=size, lens=lens, marks=[m], supersample=supersample),
                     seed * 100 + j)
        write_png(os.path.join(folder, stem + ".png"), img)
        toml += ["[[images]]", f'file = "{stem}.png"', f'housing = "{h}"', f'view = "{v}"',
                 f'nominal = "{nominal}"', ""]
    toml += ["[platform]", 'static = "platform.csv"', "[platform.poses]"]
    for name, (up, t) in poses.items():
        toml.append(f'{name} = {{ up = "{up}", table_deg = {float(t)} }}')
    if tolerance_arcsec is not None:
        toml += ["", "[tolerance]", f"arcsec = {tolerance_arcsec}"]
    with open(os.path.join(folder, "session.toml"), "w") as fh:
        fh.write("\n".join(toml) + "\n")
    return {"E_arcsec": dict(E_arcsec), "angles_deg": truth_angles}


# ---------------------------------------------------------------------------------------------
# A ring-laser goniometer's counter log (docs/commands/gonio.md): the laser counts the table's
# inertial angle (table + the Earth's vertical rate), a counter is latched at each face's
# autocollimator pulse, and the two counters alternate.
# ---------------------------------------------------------------------------------------------

EARTH_RATE = 7.2921159e-5  # rad/s


def gonio_log(path: str, seed: int, deviations_arcsec=(287.6, 0.4, -355.9, 67.9),
              revolutions: int = 40, counts_per_rev: float = 764355.84, period_s: float = 20.0,
              latitude_deg: float = 50.45, jitter_arcsec: float = 0.3,
              drop: tuple = (), spurious: tuple = ()) -> dict:
    """Write count,counter,ref,t; ``drop`` = pulse indices that never fired, ``spurious`` =
    pulse indices after which a glint fires at 40 % of the interval. Returns the truth."""
    rng = np.random.default_rng(seed)
    n = len(deviations_arcsec)
    steps = np.array([2 * np.pi / n + d * ARCSEC for d in deviations_arcsec])
    steps[-1] = 2 * np.pi - steps[:-1].sum()  # the faces close the circle
    face_angle = np.concatenate([[0.0], np.cumsum(steps)[:-1]])
    omega = 2 * np.pi / period_s
    rate_v = EARTH_RATE * math.sin(math.radians(latitude_deg))
    phase0 = rng.uniform(0, 1)
    times, faces = [], []
    for r in range(revolutions):
        for k in range(n):
            ang = 2 * np.pi * r + face_angle[k] + rng.normal(0, jitter_arcsec * ARCSEC)
            times.append(ang / omega)
            faces.append(k)
    times = np.array(times) + 5.0
    # the ring laser's phase: the table's angle plus the Earth's vertical rotation (ccw)
    ph = phase0 + (omega * (times - 5.0) + rate_v * times) / (2 * np.pi) * counts_per_rev
    cum = np.floor(ph)
    events = [(times[i], cum[i], faces[i] == 0) for i in range(len(times))]
    out, k_sp = [], set(spurious)
    for i, ev in enumerate(events):
        if i in drop:
            continue
        out.append(ev)
        if i in k_sp and i + 1 < len(events):
            t2 = ev[0] + 0.4 * (events[i + 1][0] - ev[0])
            c2 = np.floor(phase0 + (omega * (t2 - 5.0) + rate_v * t2) / (2 * np.pi)
                          * counts_per_rev)
            out.append((t2, c2, False))
    with open(path, "w") as fh:
        fh.write("count,counter,ref,t\n")
        prev = out[0][1]
        for j, (t, c, ref) in enumerate(out[1:]):
            fh.write(f"{int(c - prev)},{1 + j % 2},{int(ref)},{t:.6f}\n")
            prev = c
    return {"angles_deg": [math.degrees(s) for s in steps]}
