"""An independent user's own physics generators for axis-align sessions (no project import).

Written from the documentation only (docs/concepts.md, docs/formats.md): a triad whose
sensitive axes s_i (unit vectors in the platform frame P) are row i of I + E normalised; a
tumble of static poses in ADC counts; the mounted platform's static poses; a ring-laser
goniometer counter log (the inertial phase floored per pulse, Earth rate included,
autocollimator jitter on the pulse angle); and a session.toml tying them together.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ARCSEC = np.pi / 180 / 3600
OMEGA_EARTH = 7.2921150e-5  # [rad/s] sidereal rate
E_NAMES = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")
_IDX = {"E_xY": (0, 1), "E_xZ": (0, 2), "E_yX": (1, 0), "E_yZ": (1, 2), "E_zX": (2, 0),
        "E_zY": (2, 1)}


@dataclass
class Truth:
    """What the user knows of the unit: E [rad], scale [counts/g], bias [counts]."""

    E: np.ndarray
    scale: np.ndarray
    bias: np.ndarray
    latitude_deg: float = 50.45
    extra: dict = field(default_factory=dict)

    def axes(self) -> np.ndarray:
        """Rows s_i: unit sensitive axes in P."""
        m = np.eye(3) + self.E
        return m / np.linalg.norm(m, axis=1, keepdims=True)

    def angle(self, name: str) -> float:
        """E_ij [rad] = s_ij / s_ii (docs/concepts.md)."""
        i, j = _IDX[name]
        s = self.axes()
        return float(s[i, j] / s[i, i])


def make_truth(seed: int, spread_arcsec: float = 300.0, E_arcsec: dict | None = None) -> Truth:
    rng = np.random.default_rng(seed)
    E = np.zeros((3, 3))
    for n in E_NAMES:
        E[_IDX[n]] = rng.uniform(-spread_arcsec, spread_arcsec) * ARCSEC
    for n, v in (E_arcsec or {}).items():
        E[_IDX[n]] = v * ARCSEC
    scale = 1.0e5 * (1 + rng.uniform(-0.02, 0.02, 3))
    bias = rng.uniform(-500, 500, 3)
    return Truth(E, scale, bias)


def _readings(truth: Truth, f_p: np.ndarray, n: int, sigma_g: float, rng) -> np.ndarray:
    """n samples [counts] of specific force f_p [g] (platform frame), integer ADC codes."""
    a = truth.axes() @ f_p  # [g] along each sensitive axis
    # an undeclared second-order non-linearity K2 [g/g^2] per axis (Truth.extra["k2"])
    a = a + np.asarray(truth.extra.get("k2", (0.0, 0.0, 0.0))) * a ** 2
    ideal = truth.scale * a + truth.bias
    noisy = ideal + rng.normal(0, sigma_g, (n, 3)) * truth.scale
    return np.round(noisy)


def tumble_directions(n_poses: int = 14) -> np.ndarray:
    """Six faces and eight cube diagonals (unit vectors), the classic 14-pose tumble."""
    d = [np.eye(3)[i] * s for i in range(3) for s in (1, -1)]
    d += [np.array([a, b, c]) / np.sqrt(3) for a in (1, -1) for b in (1, -1) for c in (1, -1)]
    return np.array(d[:n_poses])


def write_tumble(path: Path, truth: Truth, seed: int, samples: int = 40,
                 sigma_g: float = 30e-6, repeats: int = 1) -> None:
    """The 14-pose tumble (``repeats`` times: a second tumble is 14 more poses)."""
    rng = np.random.default_rng([seed, 1])
    lines = ["pose,ux,uy,uz"]
    for k, f in enumerate(np.tile(tumble_directions(), (repeats, 1))):
        # the fixture is not a perfect cube: each pose a little off its nominal direction
        f = f + rng.normal(0, 0.01, 3)
        f /= np.linalg.norm(f)
        for r in _readings(truth, f, samples, sigma_g, rng):
            lines.append(f"T{k:02d},{r[0]:.0f},{r[1]:.0f},{r[2]:.0f}")
    path.write_text("\n".join(lines) + "\n")


PLATFORM_POSES = {"L000": ((0, 0, 1), 0.0), "L090": ((0, 0, 1), 90.0),
                  "L180": ((0, 0, 1), 180.0), "L270": ((0, 0, 1), 270.0),
                  "Xup": ((1, 0, 0), None), "Xdn": ((-1, 0, 0), None),
                  "Yup": ((0, 1, 0), None), "Ydn": ((0, -1, 0), None)}


def write_platform(path: Path, truth: Truth, seed: int, samples: int = 40,
                   sigma_g: float = 30e-6, table_tilt_arcsec: tuple = (0.0, 0.0)) -> None:
    """Specific force +1 g along the declared 'up'. ``table_tilt_arcsec``: the true vertical
    seen in the table's base frame leans by (x, y) [″]; at table angle theta the platform
    (turned by theta about the table axis) sees it turned by -theta."""
    rng = np.random.default_rng([seed, 2])
    lines = ["pose,ux,uy,uz"]
    v = np.array([table_tilt_arcsec[0] * ARCSEC, table_tilt_arcsec[1] * ARCSEC, 1.0])
    v /= np.linalg.norm(v)
    for name, (up, table_deg) in PLATFORM_POSES.items():
        f = np.array(up, float)
        if table_deg is not None:
            c, s_ = np.cos(np.deg2rad(table_deg)), np.sin(np.deg2rad(table_deg))
            f = np.array([[c, s_, 0], [-s_, c, 0], [0, 0, 1]]) @ v
        for r in _readings(truth, f, samples, sigma_g, rng):
            lines.append(f"{name},{r[0]:.0f},{r[1]:.0f},{r[2]:.0f}")
    path.write_text("\n".join(lines) + "\n")


def face_azimuths(truth: Truth) -> np.ndarray:
    """Azimuths [rad] of faces ref, y, x, z (the passing order of a ccw table)."""
    s = truth.axes()
    psi_x = np.arctan2(s[0, 1], s[0, 0])
    psi_y = np.arctan2(s[1, 1], s[1, 0])
    return np.array([np.pi, psi_y, psi_x, -np.pi / 2])


def gonio_truth_angles(truth: Truth, direction: str = "ccw") -> np.ndarray:
    """Table angle [rad] from face k to k+1 in passing order (sum 2 pi): ref, y, x, z when
    the table turns ccw, ref, z, x, y when cw."""
    psi = face_azimuths(truth)
    if direction == "cw":
        psi = -psi[[0, 3, 2, 1]]
    a = psi - np.roll(psi, -1)
    return np.mod(a, 2 * np.pi)


def gonio_rows(truth: Truth, seed: int, revolutions: int = 60, rev_per_s: float = 1.0,
               counts_per_rev: int = 1_179_648, jitter_arcsec: float = 0.2,
               direction: str = "ccw") -> list[tuple]:
    """(count, counter, ref, t) per pulse; ring-laser counts the inertial angle.

    ``direction = "cw"``: the table turns clockwise seen from above, so the faces pass in
    order of increasing azimuth (ref, z, x, y) and the Earth's rate is subtracted."""
    rng = np.random.default_rng([seed, 3])
    q = 2 * np.pi / counts_per_rev
    omega_v = OMEGA_EARTH * np.sin(np.deg2rad(truth.latitude_deg))  # ccw from above, north
    w = 2 * np.pi * rev_per_s
    # table angle at each pass, measured from the reference face's (arming) pulse
    steps = gonio_truth_angles(truth, direction)
    if direction == "cw":
        omega_v = -omega_v
    alpha = np.concatenate([[0.0], np.cumsum(steps)[:-1]])
    table = (np.arange(revolutions)[:, None] * 2 * np.pi + alpha[None, :]).ravel()
    table = np.append(table, revolutions * 2 * np.pi)
    table = table + rng.normal(0, jitter_arcsec * ARCSEC, table.size)
    t = 0.37 + table / w
    phase = np.floor((table + omega_v * t) / q + rng.uniform())
    counts = np.diff(phase).astype(int)
    refs = (np.arange(1, table.size) % 4 == 0).astype(int)
    return [(int(c), 1 + k % 2, int(r), float(tt))
            for k, (c, r, tt) in enumerate(zip(counts, refs, t[1:], strict=True))]


def write_gonio(path: Path, truth: Truth, seed: int, **kw) -> None:
    rows = gonio_rows(truth, seed, **kw)
    path.write_text("count,counter,ref,t\n" + "".join(
        f"{c},{k},{r},{t:.6f}\n" for c, k, r, t in rows))


SESSION_TOML = """name = "{name}"
latitude_deg = {lat}

[calibration]
static = "tumble.csv"
units = "counts"
scale_sign = "+"

[goniometer]
log = "gonio.csv"
faces = ["ref", "y", "x", "z"]
nominal_deg = [90.0, 90.0, 90.0, 90.0]
direction = "ccw"

[platform]
static = "platform.csv"
[platform.poses]
L000 = {{ up = "+Z", table_deg = 0.0 }}
L090 = {{ up = "+Z", table_deg = 90.0 }}
L180 = {{ up = "+Z", table_deg = 180.0 }}
L270 = {{ up = "+Z", table_deg = 270.0 }}
Xup = {{ up = "+X" }}
Xdn = {{ up = "-X" }}
Yup = {{ up = "+Y" }}
Ydn = {{ up = "-Y" }}
{tolerance}"""


def write_session(folder: Path, truth: Truth, seed: int, tolerance: str = "",
                  gonio_kw: dict | None = None, static_samples: int = 40,
                  tumble_samples: int = 40, tumble_repeats: int = 1,
                  table_tilt_arcsec: tuple = (0.0, 0.0)) -> Path:
    """An image-less session (goniometer, tumble, platform static) of the unit ``truth``."""
    folder.mkdir(parents=True, exist_ok=True)
    write_tumble(folder / "tumble.csv", truth, seed, samples=tumble_samples,
                 repeats=tumble_repeats)
    write_gonio(folder / "gonio.csv", truth, seed, **(gonio_kw or {}))
    write_platform(folder / "platform.csv", truth, seed, samples=static_samples,
                   table_tilt_arcsec=table_tilt_arcsec)
    (folder / "session.toml").write_text(SESSION_TOML.format(
        name=folder.name, lat=truth.latitude_deg, tolerance=tolerance))
    return folder


# ------------------------------------------------------------------ camera images of the marks

def calibrate_lens(board_dir: Path, pattern: tuple[int, int] = (9, 6), window: int = 5) -> dict:
    """My own OpenCV lens from the chessboard photographs ``left*.jpg``: K, dist, size.

    ``window``: cornerSubPix's half window [px] (5: the lowest reprojection RMS on these
    photographs, 0.19 px; 3 gives 0.23 px and a lens within the tool's stated u of it)."""
    import cv2

    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2)
    objs, imgs, size = [], [], None
    for f in sorted(Path(board_dir).glob("left*.jpg")):
        g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, pattern)
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (window, window), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4))
        objs.append(obj)
        imgs.append(c)
        size = g.shape[::-1]
    rms, K, dist, _, _ = cv2.calibrateCamera(objs, imgs, size, None, None)
    return {"K": K, "dist": dist.ravel(), "size": size, "rms": rms,
            "files": sorted(str(f) for f in Path(board_dir).glob("left*.jpg"))}


def _ideal_of(px: np.ndarray, lens: dict) -> np.ndarray:
    """Distorted pixel coordinates -> ideal pinhole pixel coordinates (same K)."""
    import cv2

    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    pts = px.reshape(-1, 1, 2).astype(np.float64)
    out = cv2.undistortPoints(pts, lens["K"], lens["dist"], R=None, P=lens["K"], criteria=crit)
    return out.reshape(-1, 2)


def _groove(d: np.ndarray, half_w: float, sigma: float) -> np.ndarray:
    """A box groove of half-width half_w [px] seen through a Gaussian PSF of sigma [px]."""
    from scipy.special import erf

    s = np.sqrt(2) * sigma
    return 0.5 * (erf((d + half_w) / s) - erf((d - half_w) / s))


def render_mark(lens: dict, direction: np.ndarray, centre_px: tuple[float, float], seed: int,
                width_px: float = 4.0, length_px: float = 260.0, blur_px: float = 1.2,
                contrast: float = 0.5, full_well: float = 20000.0, sub: int = 5) -> np.ndarray:
    """A 16-bit image of one straight groove through the calibrated lens.

    ``direction``: the mark's direction in the object plane as (along image right, along
    image up). The line is straight in the ideal pinhole image (pixels fx, fy); each
    sensor pixel integrates the blurred groove over ``sub``×``sub`` points mapped through
    the lens (distorted -> ideal), then shot and read noise.
    """
    rng = np.random.default_rng([seed, 7])
    w, h = lens["size"]
    fx, fy = lens["K"][0, 0], lens["K"][1, 1]
    d = np.array([fx * direction[0], -fy * direction[1]])
    d /= np.linalg.norm(d)
    n = np.array([-d[1], d[0]])
    c = np.asarray(centre_px, float)
    yy, xx = np.mgrid[0:h, 0:w]
    centres = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    ideal = _ideal_of(centres, lens)
    near = np.abs((ideal - c) @ n) < 6 * (width_px + blur_px)
    near &= np.abs((ideal - c) @ d) < length_px / 2 + 10 * blur_px
    dark = np.zeros(h * w)
    offs = (np.arange(sub) + 0.5) / sub - 0.5
    ox, oy = np.meshgrid(offs, offs)
    pts = (centres[near][:, None, :] + np.stack([ox.ravel(), oy.ravel()], 1)[None]).reshape(
        -1, 2)
    q = _ideal_of(pts, lens) - c
    across, along = q @ n, q @ d
    prof = _groove(across, width_px / 2, blur_px) * _groove(along, length_px / 2, blur_px)
    dark[near] = prof.reshape(-1, sub * sub).mean(axis=1)
    electrons = full_well * 0.7 * (1 - contrast * dark)
    img = rng.poisson(electrons).astype(float) + rng.normal(0, 5.0, electrons.size)
    return np.clip(np.round(img * 65535 / full_well), 0, 65535).astype(np.uint16).reshape(h, w)


VIEWS = {"A": ("A", "+X", "+Z"), "Ar": ("A", "-X", "+Z"), "B": ("B", "+Y", "+Z"),
         "Br": ("B", "-Y", "+Z")}
_AXIS = {"+X": np.array([1.0, 0, 0]), "-X": np.array([-1.0, 0, 0]),
         "+Y": np.array([0, 1.0, 0]), "-Y": np.array([0, -1.0, 0]),
         "+Z": np.array([0, 0, 1.0])}
IMAGES = (("x", "A", "horizontal"), ("z", "A", "vertical"), ("x", "Ar", "horizontal"),
          ("z", "Ar", "vertical"), ("y", "B", "horizontal"), ("z", "B", "vertical"),
          ("y", "Br", "horizontal"), ("z", "Br", "vertical"))


def write_images(folder: Path, truth: Truth, seed: int, lens: dict, model_json: Path,
                 centre_px: tuple[float, float] = (430.0, 300.0)) -> str:
    """Eight mark images (two cameras, each view also reversed) and the session.toml
    sections naming them; ``model_json`` is the camera model the user made with
    ``align camera`` from the same chessboard photographs (copied per camera)."""
    import cv2

    s = truth.axes()
    toml = []
    for cam in ("A", "B"):
        (folder / f"cam{cam}.json").write_bytes(Path(model_json).read_bytes())
        toml.append(f'[cameras.{cam}]\nmodel = "cam{cam}.json"\n')
    for view, (cam, right, up) in VIEWS.items():
        toml.append(f'[views.{view}]\ncamera = "{cam}"\nright = "{right}"\nup = "{up}"\n')
    for k, (housing, view, nominal) in enumerate(IMAGES):
        _, right, up = VIEWS[view]
        si = s["xyz".index(housing)]
        direction = np.array([si @ _AXIS[right], si @ _AXIS[up]])
        img = render_mark(lens, direction, centre_px, seed * 100 + k)
        name = f"{housing}_{view}.png"
        cv2.imwrite(str(folder / name), img)
        toml.append(f'[[images]]\nfile = "{name}"\nhousing = "{housing}"\nview = "{view}"\n'
                    f'nominal = "{nominal}"\n')
    return "\n".join(toml)


def write_tumble_recording(path: Path, truth: Truth, seed: int, rate_hz: float = 100.0,
                           static_s: float = 4.0, move_s: float = 2.0,
                           sigma_g: float = 30e-6) -> None:
    """A continuous recording ``t,ux,uy,uz`` of the 14-pose tumble: each pose held
    ``static_s``, then the triad turned to the next pose over ``move_s`` (the specific
    force's direction slerped with a smooth-step; a hand-turned fixture also shakes:
    2 mg of vibration while it moves)."""
    rng = np.random.default_rng([seed, 4])
    dirs = tumble_directions() + rng.normal(0, 0.01, (14, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    n_st, n_mv = int(static_s * rate_hz), int(move_s * rate_hz)
    f_all = []
    for k in range(14):
        f_all.append(np.repeat(dirs[k][None], n_st, axis=0))
        if k < 13:
            a, b = dirs[k], dirs[k + 1]
            om = np.arccos(np.clip(a @ b, -1, 1))
            x = (np.arange(1, n_mv + 1) / (n_mv + 1))
            s = x * x * (3 - 2 * x)
            if om < 1e-6:
                path_ = np.repeat(a[None], n_mv, axis=0)
            else:
                path_ = (np.sin((1 - s) * om)[:, None] * a
                         + np.sin(s * om)[:, None] * b) / np.sin(om)
            f_all.append(path_ + rng.normal(0, 2e-3, (n_mv, 3)))
    f = np.concatenate(f_all)
    a_ax = f @ truth.axes().T
    a_ax = a_ax + np.asarray(truth.extra.get("k2", (0.0, 0.0, 0.0))) * a_ax ** 2
    t = np.arange(len(a_ax)) / rate_hz
    # a bias that drifts over the run (warm-up) [g/s] per axis: Truth.extra["drift"]
    drift = np.asarray(truth.extra.get("drift", (0.0, 0.0, 0.0)))[None] * t[:, None]
    counts = np.round(truth.scale * (a_ax + drift + rng.normal(0, sigma_g, a_ax.shape))
                      + truth.bias)
    path.write_text("t,ux,uy,uz\n" + "".join(
        f"{tt:.3f},{c[0]:.0f},{c[1]:.0f},{c[2]:.0f}\n" for tt, c in zip(t, counts, strict=True)))
