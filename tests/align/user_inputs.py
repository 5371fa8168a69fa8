"""Independent input generators for the user-level tests (test_independent_user.py).

Written from the README alone, without the project's ``synth`` package, so that the
pipeline is checked against inputs it was not built with.  Everything is seeded.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.special import erf

# --------------------------------------------------------------------------- images


@dataclass(frozen=True)
class MarkTruth:
    """What a rendered mark is: angle [deg, from +x towards -y], offset [px]."""

    angle_deg: float
    offset_px: float
    centre_xy: tuple[float, float]
    length_px: float
    width_px: float


def _box_blur(d: np.ndarray, half: float, s: float) -> np.ndarray:
    """A box of half-width ``half`` convolved with a Gaussian of sd ``s`` at ``d``."""
    k = 1.0 / (np.sqrt(2.0) * s)
    return 0.5 * (erf((d + half) * k) - erf((d - half) * k))


def render_mark(
    shape: tuple[int, int],
    angle_deg: float,
    centre_xy: tuple[float, float],
    length_px: float,
    *,
    width_px: float = 4.0,
    blur_px: float = 1.2,
    level: float = 0.6,
    contrast: float = 0.5,
    snr: float = 40.0,
    seed: int = 0,
    supersample: int = 4,
    extra_marks: list[tuple[float, tuple[float, float], float]] | None = None,
) -> tuple[np.ndarray, MarkTruth]:
    """A dark straight groove on a lit surface, area-integrated over each pixel.

    Intensities are in [0, 1] (float); noise is Gaussian, sd = level*contrast/snr.
    ``extra_marks`` adds further grooves (angle, centre, length) of the same profile.
    """
    h, w = shape
    rng = np.random.default_rng(seed)
    img = np.full((h, w), level, dtype=np.float64)
    ss = supersample
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    marks = [(angle_deg, centre_xy, length_px)] + list(extra_marks or [])
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth_total = np.zeros((h, w))
    for a_deg, (cx, cy), L in marks:
        a = np.radians(a_deg)
        tx, ty = np.cos(a), -np.sin(a)  # direction, y down
        nx, ny = np.sin(a), np.cos(a)  # normal
        d0 = (xx - cx) * nx + (yy - cy) * ny
        t0 = (xx - cx) * tx + (yy - cy) * ty
        reach = width_px / 2 + 6 * blur_px + 2
        band = (np.abs(d0) < reach) & (np.abs(t0) < L / 2 + 6 * blur_px + 2)
        iy, ix = np.nonzero(band)
        acc = np.zeros(iy.size)
        for oy in sub:
            for ox in sub:
                px = ix + ox
                py = iy + oy
                d = (px - cx) * nx + (py - cy) * ny
                t = (px - cx) * tx + (py - cy) * ty
                acc += _box_blur(d, width_px / 2, blur_px) * _box_blur(t, L / 2, blur_px)
        depth_total[iy, ix] += acc / ss**2
    img = level * (1.0 - contrast * np.clip(depth_total, 0, 1))
    sigma = level * contrast / snr
    img = img + rng.normal(0.0, sigma, img.shape)
    a = np.radians(angle_deg)
    ccx, ccy = (w - 1) / 2, (h - 1) / 2
    off = (centre_xy[0] - ccx) * np.sin(a) + (centre_xy[1] - ccy) * np.cos(a)
    return img, MarkTruth(angle_deg, off, centre_xy, length_px, width_px)


def quantise(img: np.ndarray, bits: int) -> np.ndarray:
    """Float [0, 1] image to uint8 / uint16."""
    full = 2**bits - 1
    q = np.clip(np.round(img * full), 0, full)
    return q.astype(np.uint8 if bits == 8 else np.uint16)


def write_image(path: Path, arr: np.ndarray) -> Path:
    import cv2

    if not cv2.imwrite(str(path), arr):
        raise OSError(f"could not write {path}")
    return path


def wrap_angle(d_deg: float) -> float:
    """An angle difference of a line (period 180 deg) into (-90, 90]."""
    return (d_deg + 90.0) % 180.0 - 90.0


# --------------------------------------------------------------------------- counter logs

Q_ARCSEC = 1.696  # ring-laser count [arcsec]
COUNTS_PER_REV = 1296000.0 / Q_ARCSEC


def counter_log(
    face_deg: list[float],
    *,
    revs: int = 60,
    rev_per_s: float = 0.5,
    jitter_s: float = 2e-6,
    seed: int = 0,
    with_time: bool = True,
    phase0: float = 0.37,
) -> tuple[list[list], list[float]]:
    """Rows count,counter,ref[,t] of a table turning at constant speed.

    ``face_deg`` are the face positions in passing order (first = reference, at 0).
    Row k holds the counts between pulse k-1 and pulse k (the first one from an
    unlogged arming pulse half a face before the reference); counters alternate 1, 2.
    Returns the rows and the true angle from each face to the next [deg].
    """
    rng = np.random.default_rng(seed)
    faces = np.asarray(face_deg, dtype=float) / 360.0  # in revolutions
    times = []
    refs = []
    for r in range(revs):
        for i, f in enumerate(faces):
            times.append((r + f) / rev_per_s + 1.0)
            refs.append(1 if i == 0 else 0)
    t = np.asarray(times) + rng.normal(0.0, jitter_s, len(times))
    arm = t[0] - 0.1 / rev_per_s  # the unlogged arming pulse
    # ring-laser phase: counts of table angle since t=0 (constant speed)
    phi = (t - 1.0) * rev_per_s * COUNTS_PER_REV + phase0
    phi_arm = (arm - 1.0) * rev_per_s * COUNTS_PER_REV + phase0
    fl = np.floor(np.concatenate([[phi_arm], phi]))
    counts = np.diff(fl).astype(np.int64)
    rows = []
    for k in range(len(t)):
        row = [int(counts[k]), 1 + (k % 2), refs[k]]
        if with_time:
            row.append(round(float(t[k]), 9))
        rows.append(row)
    f = np.asarray(face_deg, dtype=float)
    true = list(np.diff(np.concatenate([f, [360.0]])))
    return rows, true


# --------------------------------------------------------------------------- triad


@dataclass(frozen=True)
class Triad:
    k: np.ndarray  # scale [V/g]
    bias_g: np.ndarray  # [g]
    axes: np.ndarray  # rows: unit sensing directions in the platform frame


def make_triad(seed: int = 0, mis_rad: float = 2e-4) -> Triad:
    rng = np.random.default_rng(seed)
    k = 1.0 + rng.normal(0, 0.01, 3)
    bias = rng.normal(0, 2e-3, 3)
    axes = np.eye(3) + rng.normal(0, mis_rad, (3, 3)) * (1 - np.eye(3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    return Triad(k, bias, axes)


def read_triad(tri: Triad, f: np.ndarray) -> np.ndarray:
    """Outputs for specific force(s) ``f`` [g] in the platform frame."""
    f = np.atleast_2d(f)
    return tri.k * (f @ tri.axes.T + tri.bias_g)


def tumble_rows(
    tri: Triad,
    *,
    poses: int = 18,
    samples: int = 50,
    noise: float = 2e-5,
    seed: int = 0,
    with_time: bool = True,
) -> list[list]:
    """pose,ux,uy,uz[,t] rows for ``poses`` well-spread static orientations."""
    rng = np.random.default_rng(seed)
    dirs = [np.array(v, float) for v in
            [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]]
    while len(dirs) < poses:
        v = rng.normal(size=3)
        dirs.append(v / np.linalg.norm(v))
    rows = []
    t = 0.0
    for p, f in enumerate(dirs[:poses]):
        u = read_triad(tri, f)[0]
        for _ in range(samples):
            s = u + rng.normal(0, noise, 3)
            row = [f"P{p:02d}", *(round(float(x), 9) for x in s)]
            if with_time:
                row.append(round(t, 4))
            t += 0.01
            rows.append(row)
        t += 5.0
    return rows


def readings_rows(
    tri: Triad, n: int = 40, seed: int = 1, noise: float = 2e-5
) -> tuple[list[list], np.ndarray]:
    """t,ux,uy,uz rows of tilted static readings and their true f [g]."""
    rng = np.random.default_rng(seed)
    roll = rng.uniform(-0.5, 0.5, n)
    pitch = rng.uniform(-0.5, 0.5, n)
    f = np.stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll), np.cos(pitch) * np.cos(roll)], 1)
    u = read_triad(tri, f) + rng.normal(0, noise, (n, 3))
    rows = [[round(0.1 * i, 3), *(round(float(x), 9) for x in u[i])] for i in range(n)]
    return rows, f


def platform_rows(
    tri: Triad, *, samples: int = 40, noise: float = 2e-5, seed: int = 2
) -> list[list]:
    """pose,ux,uy,uz,t rows of the platform poses of the README's example session."""
    rng = np.random.default_rng(seed)
    poses = {"L000": (0, 0, 1), "L090": (0, 0, 1), "L180": (0, 0, 1), "L270": (0, 0, 1),
             "Xup": (1, 0, 0), "Xdn": (-1, 0, 0), "Yup": (0, 1, 0), "Ydn": (0, -1, 0)}
    rows = []
    t = 0.0
    for name, f in poses.items():
        u = read_triad(tri, np.array(f, float))[0]
        for _ in range(samples):
            s = u + rng.normal(0, noise, 3)
            rows.append([name, *(round(float(x), 9) for x in s), round(t, 3)])
            t += 0.01
        t += 5.0
    return rows


PLATFORM_POSES_TOML = """[platform.poses]
L000 = { up = "+Z", table_deg = 0.0 }
L090 = { up = "+Z", table_deg = 90.0 }
L180 = { up = "+Z", table_deg = 180.0 }
L270 = { up = "+Z", table_deg = 270.0 }
Xup = { up = "+X" }
Xdn = { up = "-X" }
Yup = { up = "+Y" }
Ydn = { up = "-Y" }
"""


# --------------------------------------------------------------------------- CSV writing


def write_csv(
    path: Path,
    header: list[str],
    rows: list[list],
    *,
    sep: str = ",",
    eol: str = "\n",
    bom: bool = False,
    order: list[int] | None = None,
) -> Path:
    """Write a table; ``order`` permutes the columns (header and rows alike)."""
    if order is not None:
        header = [header[i] for i in order]
        rows = [[r[i] for i in order] for r in rows]
    text = eol.join([sep.join(header)] + [sep.join(str(v) for v in r) for r in rows]) + eol
    data = text.encode("utf-8")
    if bom:
        data = b"\xef\xbb\xbf" + data
    path.write_bytes(data)
    return path


# --------------------------------------------------------------------------- a session with cameras

_AXIS = {"X": 0, "Y": 1, "Z": 2}
VIEWS = {"A": ("+X", "+Z"), "Ar": ("-X", "+Z"), "B": ("+Y", "+Z"), "Br": ("-Y", "+Z")}
IMAGES = [("x", "A", "horizontal"), ("z", "A", "vertical"), ("x", "Ar", "horizontal"),
          ("z", "Ar", "vertical"), ("y", "B", "horizontal"), ("z", "B", "vertical"),
          ("y", "Br", "horizontal"), ("z", "Br", "vertical")]


def _signed_axis(s: str) -> np.ndarray:
    v = np.zeros(3)
    v[_AXIS[s[1]]] = 1.0 if s[0] == "+" else -1.0
    return v


def image_session(d: Path, tri: Triad, *, seed: int = 3, roll_a_arcsec: float = 0.0,
                  shape: tuple[int, int] = (480, 640), length: float = 400.0,
                  platform: bool = True) -> str:
    """Write a session: tumble, two cameras with reversal views (README's example) and,
    optionally, the platform poses.  A mark's image angle is atan2(s.up, s.right) of the
    housing's axis s, plus the undeclared roll of camera A.  Returns session.toml's text."""

    rng = np.random.default_rng(seed)
    d.mkdir(parents=True, exist_ok=True)
    write_csv(d / "tumble.csv", ["pose", "ux", "uy", "uz", "t"], tumble_rows(tri, seed=seed))
    # The renders have no lens, and the file says so (docs/camera.md: an undeclared lens is
    # carried in u).
    flat = "lens_k1 = 0.0\nlens_k2 = 0.0\nlens_p = 0.0\nlens_aspect = 0.0\nlens_pp_px = 0.0\n"
    toml = (f'name = "cams{seed}"\n[calibration]\nstatic = "tumble.csv"\n[cameras.A]\n{flat}'
            f'[cameras.B]\n{flat}')
    for v, (r, u) in VIEWS.items():
        toml += f'[views.{v}]\ncamera = "{v[0]}"\nright = "{r}"\nup = "{u}"\n'
    h, w = shape
    for k, (housing, v, nominal) in enumerate(IMAGES):
        s = tri.axes["xyz".index(housing)]
        r, u = VIEWS[v]
        a = np.degrees(np.arctan2(s @ _signed_axis(u), s @ _signed_axis(r)))
        a = wrap_angle(a + (roll_a_arcsec / 3600.0 if v[0] == "A" else 0.0))
        centre = ((w - 1) / 2 + rng.uniform(-60, 60), (h - 1) / 2 + rng.uniform(-60, 60))
        img, _ = render_mark(shape, a, centre, length, snr=40, seed=seed * 100 + k)
        f = f"{housing}_{v}.png"
        write_image(d / f, quantise(img, 16))
        toml += (f'[[images]]\nfile = "{f}"\nhousing = "{housing}"\nview = "{v}"\n'
                 f'nominal = "{nominal}"\n')
    if platform:
        write_csv(d / "platform.csv", ["pose", "ux", "uy", "uz", "t"],
                  platform_rows(tri, seed=seed + 1))
        toml += '[platform]\nstatic = "platform.csv"\n' + PLATFORM_POSES_TOML
    (d / "session.toml").write_text(toml)
    return toml
