"""Independent user 14's session generator (written from the docs only, no pipeline code).

A calibration lab's whole session with a known misalignment matrix E and the effects a lab
really has, none of them declared to the tool:

* camera images of scribe marks (grooves: a flat-floored dark band, blurred by the optics
  *before* the pixels, integrated over each pixel's area, seen through the REAL lens of
  ``/work/shared/data/real/opencv-chessboard`` calibrated here with ``cv2.calibrateCamera``,
  photon + read noise, 8-bit), camera A rolled on its mount, one bent mark, one image out
  of focus, camera B's lens never calibrated (no ``model``);
* a ring-laser goniometer counter log (quantised counts of inertial rotation: table + Earth
  rate, a scale-factor error, a wandering table speed, autocollimator jitter);
* a 14-pose tumble of the triad and 8 platform static poses, with the triad's bias drifting
  with temperature during the session (no ``temp`` column) and the table axis not level.

Conventions taken from docs/concepts.md: E_ij = s_ij / s_ii (row i accelerometer, column j
platform axis); a mark's angle is atan2(s.up, s.right) of the view; faces pass in decreasing
azimuth turning counter-clockwise, angle ref->y = 90 deg + E_yX.
"""

from __future__ import annotations

import functools
import glob
import json
import os
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.special import erf

ARCSEC = np.pi / 180 / 3600
DEG = np.pi / 180
EARTH_RATE = 7.292115e-5  # rad/s
CHESS = "/work/shared/data/real/opencv-chessboard"
E_NAMES = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")
AXIS = {"x": 0, "y": 1, "z": 2, "X": 0, "Y": 1, "Z": 2}


def e_index(name):
    """(row, column) of an angle name such as ``E_xZ``."""
    return AXIS[name[2]], AXIS[name[3]]


@functools.lru_cache(maxsize=1)
def real_lens():
    """Calibrate the real camera from the chessboard photographs left*.jpg (9x6 corners).

    Returns
    -------
    (K, dist, (width, height), rms): OpenCV camera matrix [px], k1 k2 p1 p2 k3, image size,
    reprojection RMS [px].
    """
    pattern = (9, 6)
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2)
    objpts, imgpts, size = [], [], None
    for f in sorted(glob.glob(os.path.join(CHESS, "left*.jpg"))):
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, pattern)
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3))
        objpts.append(obj)
        imgpts.append(c)
        size = g.shape[::-1]
    rms, K, dist, _, _ = cv2.calibrateCamera(objpts, imgpts, size, None, None)
    return K, dist.ravel()[:5], size, rms


def camera_json(path):
    """The calibrated lens as the 3-key OpenCV JSON the docs accept (formats.md)."""
    K, dist, size, _ = real_lens()
    with open(path, "w") as f:
        json.dump({"camera_matrix": K.tolist(), "dist_coeffs": dist.tolist(),
                   "image_size": list(size)}, f)


def truth_matrix(rng, scale_arcsec=120.0):
    """A misalignment E [rad] with angles of a few arc-minutes, zero diagonal."""
    E = rng.uniform(-1, 1, (3, 3)) * scale_arcsec * ARCSEC
    np.fill_diagonal(E, 0.0)
    return E


def axes(E):
    """Unit sensitivity axes s_i (rows) from E: s_i ~ e_i + E_i (E_ij = s_ij / s_ii)."""
    S = np.eye(3) + E
    return S / np.linalg.norm(S, axis=1, keepdims=True)


# ----------------------------------------------------------------------------- images
def groove_profile(d, width, blur, contrast):
    """Fraction of light removed at perpendicular distance d [px] from a flat-floored groove.

    A box of ``width`` blurred by a Gaussian of ``blur`` [px] (the optics, before the pixels).
    """
    s = np.sqrt(2.0) * max(blur, 1e-6)
    return contrast * 0.5 * (erf((d + width / 2) / s) - erf((d - width / 2) / s))


@functools.lru_cache(maxsize=2)
def ideal_subpixels(lens, oversample):
    """Ideal (undistorted) pinhole coordinates [px] of every sub-pixel sample of the sensor."""
    K, dist, (W, H), _ = real_lens()
    o = (np.arange(oversample) + 0.5) / oversample - 0.5
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    sub = np.stack([(xx[..., None, None] + o[None, None, :, None]).repeat(oversample, -1),
                    (yy[..., None, None] + o[None, None, None, :]).repeat(oversample, -2)],
                   -1).reshape(-1, 2)
    if not lens:
        return sub
    return cv2.undistortPoints(sub.reshape(-1, 1, 2), K, dist, None, None, K,
                               (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40,
                                1e-9)).reshape(-1, 2)


def render_mark(angle_img_rad, *, centre_off=(0.0, 0.0), length=380.0, width=5.0, blur=1.2,
                contrast=0.6, bow_px=0.0, lens=True, rng=None, level=170.0,
                read_noise=1.5, oversample=4):
    """An 8-bit image of one scribe mark through the real lens.

    ``angle_img_rad`` is the mark's direction in the ideal pinhole image, counter-clockwise
    from image right as seen (image up = -rows). ``centre_off`` is the mark's centre from
    the principal point [px, (right, up)]. ``bow_px`` bends the groove: a parabola of that
    sagitta across its length (a bent scribe mark; its chord keeps the angle).
    """
    K, dist, (W, H), _ = real_lens()
    cx, cy = K[0, 2], K[1, 2]
    und = ideal_subpixels(bool(lens), oversample)
    # ideal coordinates relative to the mark's centre, up positive
    u = und[:, 0] - (cx + centre_off[0])
    v = -(und[:, 1] - (cy - centre_off[1]))
    c, s = np.cos(angle_img_rad), np.sin(angle_img_rad)
    along = u * c + v * s
    perp = -u * s + v * c
    if bow_px:
        half = length / 2
        perp = perp - bow_px * (1 - (np.clip(along, -half, half) / half) ** 2)
    prof = groove_profile(perp, width, blur, contrast)
    # the groove's square ends, blurred too
    sb = np.sqrt(2.0) * blur
    prof *= 0.5 * (erf((along + length / 2) / sb) - erf((along - length / 2) / sb))
    img = level * (1.0 - prof.reshape(H, W, oversample * oversample).mean(-1))
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    # mild vignetting of the lamp (smooth, slow)
    r2 = ((xx - W / 2) ** 2 + (yy - H / 2) ** 2) / (W * W / 4 + H * H / 4)
    img *= 1.0 - 0.08 * r2
    rng = rng if rng is not None else np.random.default_rng(0)
    gain = 0.1  # DN per electron: photon noise sqrt(DN/gain)*gain
    img = img + rng.normal(0, 1, img.shape) * np.sqrt(img * gain + read_noise ** 2)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------- gonio
def gonio_rows(E, rng, *, revolutions=120, rev_per_s=1.0, latitude_deg=50.45,
               scale_error_ppm=0.0, counts_per_rev=1_000_003.3, jitter_arcsec=0.15,
               wander=0.01, z_face_err_arcsec=25.0, ref_offset_arcsec=0.0):
    """A counter log: count,counter,ref,t of a table turning counter-clockwise.

    Face azimuths: ref 180 deg (+offset), y = azimuth of s_y, x = azimuth of s_x, z 270 deg
    (-90 deg + its own error); passing order ref, y, x, z (decreasing azimuth).
    """
    S = axes(E)
    az = {"ref": np.pi + ref_offset_arcsec * ARCSEC,
          "y": np.arctan2(S[1, 1], S[1, 0]),
          "x": np.arctan2(S[0, 1], S[0, 0]) % (2 * np.pi),
          "z": -0.5 * np.pi + z_face_err_arcsec * ARCSEC}
    az["x"] = az["x"] if az["x"] < np.pi else az["x"] - 2 * np.pi
    order = ["ref", "y", "x", "z"]
    # table angle at which each face meets the autocollimator (at azimuth 2 pi): theta = A - psi
    w0 = 2 * np.pi * rev_per_s
    tw = 37.0  # s, the table's speed wander period

    def theta(t):
        return w0 * t - wander * w0 * tw / (2 * np.pi) * (np.cos(2 * np.pi * t / tw) - 1)

    def rate(t):
        return w0 * (1 + wander * np.sin(2 * np.pi * t / tw))

    targets = []
    for n in range(revolutions + 1):
        for f in order:
            targets.append((f, 2 * np.pi * (n + 1) - az[f]
                            + rng.normal(0, jitter_arcsec * ARCSEC)))
    t = np.array([tg / w0 for _, tg in targets])
    tgt = np.array([tg for _, tg in targets])
    for _ in range(8):
        t = t - (theta(t) - tgt) / rate(t)
    omega_v = EARTH_RATE * np.sin(latitude_deg * DEG)
    q = 2 * np.pi / counts_per_rev
    phase = (theta(t) + omega_v * t) * (1 + scale_error_ppm * 1e-6) / q + rng.uniform()
    cnt = np.floor(phase).astype(np.int64)
    # logging armed at the first ref pulse: rows start with the next pulse
    counts = np.diff(cnt)
    faces = [f for f, _ in targets][1:]
    rows = {"count": counts, "counter": np.array([1 + (k % 2) for k in range(len(counts))]),
            "ref": np.array([1 if f == "ref" else 0 for f in faces]), "t": t[1:] - t[0]}
    return rows


# ----------------------------------------------------------------------------- triad
def tumble_orientations():
    """14 attitudes of the tumble fixture (6 faces + 8 corners) as rotation matrices."""
    R = []
    for ax in range(3):
        for sgn in (1, -1):
            v = np.zeros(3)
            v[ax] = sgn
            R.append(_rot_to(v))
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                R.append(_rot_to(np.array([sx, sy, sz]) / np.sqrt(3)))
    return R


def _rot_to(v):
    """A rotation taking the world up (0,0,1) to the body direction v (body = R^T world)."""
    up = np.array([0.0, 0.0, 1.0])
    a = np.cross(v, up)
    s, c = np.linalg.norm(a), v @ up
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    a /= s
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    ang = np.arctan2(s, c)
    # body->world rotation mapping v to up
    return np.eye(3) + np.sin(ang) * Kx + (1 - np.cos(ang)) * Kx @ Kx


def rot_xy(tx, ty):
    """Small tilt rotation about world x then y [rad]."""
    cx_, sx_ = np.cos(tx), np.sin(tx)
    cy_, sy_ = np.cos(ty), np.sin(ty)
    Rx = np.array([[1, 0, 0], [0, cx_, -sx_], [0, sx_, cx_]])
    Ry = np.array([[cy_, 0, sy_], [0, 1, 0], [-sy_, 0, cy_]])
    return Ry @ Rx


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@dataclass
class Session:
    """A session's truth and its undeclared effects (what the lab knows and the tool not)."""

    seed: int = 1
    E_rad: np.ndarray = None
    roll_A_arcsec: float = 40.0          # camera A rolled on its mount, undeclared
    roll_B_arcsec: float = 0.0
    level_arcsec: tuple = (18.0, -12.0)  # the table axis off vertical, undeclared
    level_gimbal: bool = False           # the base's tilt also under the gimbal (X/Y up) poses
    gonio_scale_ppm: float = 80.0        # ring-laser scale error
    gonio_ref_offset_arcsec: float = 0.0  # the reference face's own azimuth offset
    gonio_ref_u_arcsec: float | None = None  # the lab's declared u of that offset (None: not)
    bias_drift_ug: float = 60.0          # bias drift over the session (temperature), no temp column
    bent_px: float = 0.0                 # sagitta of a bent mark (x_A)
    defocus_blur: float = 0.0            # blur [px] of one image (z_B) out of focus; 0: in focus
    lens_b_model: bool = False           # camera B: calibrated (model) or not
    views: tuple = ("A", "Ar", "B", "Br")
    mark_offsets_px: dict = field(default_factory=dict)
    gonio_revolutions: int = 120
    static_samples: int = 100
    tumble_samples: int = 100
    sample_noise_ug: float = 80.0
    tolerance_arcsec: float | None = None
    tolerance_angles: dict = field(default_factory=dict)  # per angle: T [″] (±T)
    with_gonio: bool = True
    with_static: bool = True
    with_tumble: bool = True
    image_repeat: dict = field(default_factory=dict)  # extra copies of an image: {"x_A": 1}

    def __post_init__(self):
        rng = np.random.default_rng(self.seed)
        if self.E_rad is None:
            self.E_rad = truth_matrix(rng)
        self.rng = rng

    def truth_arcsec(self):
        return {n: self.E_rad[e_index(n)] / ARCSEC for n in E_NAMES}


VIEW_DEF = {"A": ("A", (+1, 0, 0), (0, 0, 1)), "Ar": ("A", (-1, 0, 0), (0, 0, 1)),
            "B": ("B", (0, 1, 0), (0, 0, 1)), "Br": ("B", (0, -1, 0), (0, 0, 1))}
VIEW_HOUSINGS = {"A": (("x", "horizontal"), ("z", "vertical")),
                 "B": (("y", "horizontal"), ("z", "vertical"))}


def _sgn(v):
    ax = "XYZ"[int(np.flatnonzero(v)[0])]
    return ("+" if sum(v) > 0 else "-") + ax


def write_session(folder, spec: Session):
    """Write ``folder/session.toml`` and every file it names; return the truth [″] by angle."""
    os.makedirs(folder, exist_ok=True)
    rng = spec.rng
    S = axes(spec.E_rad)
    lat = 50.45
    toml = [f'name = "u14-{spec.seed}"', f"latitude_deg = {lat}", ""]
    t_session = 0.0  # seconds since the start: the bias drifts with it
    bias0 = rng.normal(0, 2e-3, 3)
    kscale = 1 + rng.normal(0, 2e-3, 3)
    drift_rate = spec.bias_drift_ug * 1e-6 / 3600.0 * np.array([1.0, -0.7, 0.4])  # g/s

    def reading(f_P, t):
        b = bias0 + drift_rate * t
        return kscale * (S @ f_P) + b + rng.normal(0, spec.sample_noise_ug * 1e-6, 3)

    if spec.with_tumble:
        lines = ["pose,ux,uy,uz,t"]
        # the tumble fixture holds the triad's own (mounted) axes: f_P = R^T up
        for k, R in enumerate(tumble_orientations()):
            f_P = R.T @ np.array([0.0, 0.0, 1.0])
            for _ in range(spec.tumble_samples):
                t_session += 0.01
                u = reading(f_P, t_session)
                lines.append(f"P{k:02d},{u[0]:.7f},{u[1]:.7f},{u[2]:.7f},{t_session:.3f}")
            t_session += 60.0
        open(os.path.join(folder, "tumble.csv"), "w").write("\n".join(lines) + "\n")
        toml += ["[calibration]", 'static = "tumble.csv"', 'units = "g"', ""]

    if spec.with_static:
        base = rot_xy(spec.level_arcsec[0] * ARCSEC, spec.level_arcsec[1] * ARCSEC)
        poses = {"L000": (np.eye(3), 0.0), "L090": (np.eye(3), 90.0),
                 "L180": (np.eye(3), 180.0), "L270": (np.eye(3), 270.0),
                 "Xup": (np.array([[0, 0, -1], [0, 1, 0], [1, 0, 0.0]]), None),
                 "Xdn": (np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0.0]]), None),
                 "Yup": (np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0.0]]), None),
                 "Ydn": (np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0.0]]), None)}
        ups = {"L000": "+Z", "L090": "+Z", "L180": "+Z", "L270": "+Z",
               "Xup": "+X", "Xdn": "-X", "Yup": "+Y", "Ydn": "-Y"}
        lines = ["pose,ux,uy,uz,t"]
        toml += ["[platform]", 'static = "platform.csv"', "[platform.poses]"]
        for name, (G, tab) in poses.items():
            tilt = base if (tab is not None or spec.level_gimbal) else np.eye(3)
            C = tilt @ G @ rot_z((tab or 0.0) * DEG)  # platform -> world
            f_P = C.T @ np.array([0.0, 0.0, 1.0])
            assert f_P[AXIS[ups[name][1]]] * (1 if ups[name][0] == "+" else -1) > 0.99
            for _ in range(spec.static_samples):
                t_session += 0.01
                u = reading(f_P, t_session)
                lines.append(f"{name},{u[0]:.7f},{u[1]:.7f},{u[2]:.7f},{t_session:.3f}")
            t_session += 120.0
            if tab is None:
                toml.append(f'{name} = {{ up = "{ups[name]}" }}')
            else:
                toml.append(f'{name} = {{ up = "{ups[name]}", table_deg = {tab} }}')
        open(os.path.join(folder, "platform.csv"), "w").write("\n".join(lines) + "\n")
        toml.append("")

    if spec.with_gonio:
        rows = gonio_rows(spec.E_rad, rng, revolutions=spec.gonio_revolutions,
                          latitude_deg=lat, scale_error_ppm=spec.gonio_scale_ppm,
                          ref_offset_arcsec=spec.gonio_ref_offset_arcsec)
        lines = ["count,counter,ref,t"] + [
            f"{c},{k},{r},{t:.6f}" for c, k, r, t in
            zip(rows["count"], rows["counter"], rows["ref"], rows["t"], strict=True)]
        open(os.path.join(folder, "gonio.csv"), "w").write("\n".join(lines) + "\n")
        toml += ["[goniometer]", 'log = "gonio.csv"', 'faces = ["ref", "y", "x", "z"]',
                 "nominal_deg = [90.0, 90.0, 90.0, 90.0]", 'direction = "ccw"']
        if spec.gonio_ref_u_arcsec is not None:
            toml.append(f"reference_offset_u_arcsec = {spec.gonio_ref_u_arcsec}")
        toml.append("")

    cams = sorted({VIEW_DEF[v][0] for v in spec.views})
    for cam in cams:
        toml.append(f"[cameras.{cam}]")
        if cam == "A" or (cam == "B" and spec.lens_b_model):
            camera_json(os.path.join(folder, f"cam{cam}.json"))
            toml.append(f'model = "cam{cam}.json"')
        toml.append("")
    for v in spec.views:
        cam, r, up = VIEW_DEF[v]
        toml += [f"[views.{v}]", f'camera = "{cam}"', f'right = "{_sgn(r)}"',
                 f'up = "{_sgn(up)}"', ""]
    for v in spec.views:
        cam, r, up = VIEW_DEF[v]
        roll = (spec.roll_A_arcsec if cam == "A" else spec.roll_B_arcsec) * ARCSEC
        for housing, nominal in VIEW_HOUSINGS[cam]:
            s = S[AXIS[housing]]
            a = np.arctan2(s @ np.array(up, float), s @ np.array(r, float))
            a_img = a + roll  # the camera rolled on its mount turns the whole image
            off = spec.mark_offsets_px.get(f"{housing}_{v}", (0.0, 0.0) if nominal ==
                                           "horizontal" else (0.0, 0.0))
            blur = 1.2
            if spec.defocus_blur and housing == "z" and v == "B":
                blur = spec.defocus_blur
            bow = spec.bent_px if (housing == "x" and v == "A") else 0.0
            for rep in range(1 + spec.image_repeat.get(f"{housing}_{v}", 0)):
                name = f"{housing}_{v}" + (f"_{rep}" if rep else "") + ".png"
                img = render_mark(a_img, centre_off=off, blur=blur, bow_px=bow,
                                  length=300.0, rng=rng)
                cv2.imwrite(os.path.join(folder, name), img)
                toml += ["[[images]]", f'file = "{name}"', f'housing = "{housing}"',
                         f'view = "{v}"', f'nominal = "{nominal}"', ""]
    if spec.tolerance_arcsec is not None:
        toml += ["[tolerance]", f"arcsec = {spec.tolerance_arcsec}", 'decision = "guarded"']
        toml += [f"{n} = {t}" for n, t in spec.tolerance_angles.items()] + [""]
    open(os.path.join(folder, "session.toml"), "w").write("\n".join(toml) + "\n")
    return spec.truth_arcsec()


def run_and_compare(folder, spec, extra=()):
    """Write the session, run ``python3 -m align run`` on it, return (rc, result, table).

    table: per angle (value, u, truth, error/u) [″].
    """
    import subprocess
    import sys
    truth = write_session(folder, spec)
    out = os.path.join(folder, "result.json")
    p = subprocess.run([sys.executable, "-m", "align", "run", folder, "--json", out, "-q",
                        "--force", *extra], capture_output=True, text=True)
    res = json.load(open(out)) if os.path.exists(out) else None
    table = {}
    if res is not None and res.get("misalignment_arcsec"):
        for n in E_NAMES:
            i, j = e_index(n)
            v, u = res["misalignment_arcsec"][i][j], res["misalignment_u_arcsec"][i][j]
            table[n] = (v, u, truth[n], (v - truth[n]) / u)
    return p.returncode, res, table, p.stderr
