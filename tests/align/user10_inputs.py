"""Independent user 10's inputs, written from the physics (numpy/scipy only; nothing from the
project): a ring-laser goniometer's counter log and a tumble of an accelerometer triad.

Goniometer. A rotary table carries a polygon of faces; an autocollimator fires a pulse when a
face normal passes its axis. A ring laser on the table counts its own inertial rotation: its
phase (in periods) is K/2π · (θ(t) + d·Ω sin φ · t), θ the table angle along the motion, d = +1
turning counter-clockwise seen from above (the Earth's vertical rate adds, northern
hemisphere), −1 clockwise. Two counters alternate at every pulse; a row holds the whole
periods counted between two pulses (floor of the phase at the pulse minus floor at the
previous one), which counter held them, 1 if the pulse is the reference face, and its time.
The table's speed wanders (a slow random walk in angle) and may carry a ripple locked to the
table's angle; the autocollimator fires `latency` late, with a Gaussian angle jitter. The log
starts at an unlogged arming pulse on a random face.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

OMEGA_E = 7.2921150e-5  # Earth's sidereal rate [rad/s]
ARCSEC = np.pi / 180 / 3600


def true_angles(rng: np.random.Generator, n_faces: int = 4, spread_arcsec: float = 300.0
                ) -> np.ndarray:
    """Face-to-face angles [rad] of a polygon: nominal 360°/n plus deviations, closing at 2π."""
    dev = rng.normal(0, spread_arcsec, n_faces) * ARCSEC
    dev -= dev.mean()
    return np.full(n_faces, 2 * np.pi / n_faces) + dev


def gonio_log(path: Path, angles: np.ndarray, rng: np.random.Generator, *, revs: int = 60,
              rev_per_s: float = 1.0, wander: float = 0.05, ripple: float = 0.0,
              coast: float = 0.0, latency_s: float = 0.0, jitter_arcsec: float = 0.5,
              latitude_deg: float = 50.0,
              counts_per_rev: float = 764355.84, direction: int = +1,
              missing: tuple[int, ...] = (), doubled: tuple[int, ...] = (),
              double_delay_s: float = 2e-3, t0: float = 1000.0) -> dict:
    """Write a counter log ``count,counter,ref,t`` to ``path``.

    ``angles`` [rad] are the table angles from face k to face k+1 in the *forward*
    (counter-clockwise) passing order, face 0 the reference. ``direction`` −1 turns the table
    clockwise: the faces then pass in reverse order (ref, then the last face, ...).
    ``coast``: the table coasts, its speed falling by that fraction over the log (constant
    friction: ω² falls linearly with angle). ``missing``/``doubled`` are pulse indexes (of the
    logged pulses) the autocollimator misses /
    fires twice (the second ``double_delay_s`` later). Returns what was done.
    """
    n = len(angles)
    if direction > 0:
        step = np.asarray(angles, float)          # passing order ref, 1, 2, ...
        order = np.arange(n)
    else:
        step = np.asarray(angles, float)[::-1]    # ref, n-1, ..., 1
        order = np.r_[0, np.arange(n - 1, 0, -1)]
    pos = np.r_[0.0, np.cumsum(step)[:-1]]       # face positions along the motion [rad]
    arm = int(rng.integers(n))
    k_total = revs * n + 2
    idx = arm + np.arange(k_total)
    theta_f = 2 * np.pi * (idx // n) + pos[idx % n]
    # table speed as a function of the table angle (physical angle: the ripple is locked to
    # the table, so it flips with the direction); a random walk wander, smooth over ~1 rev
    grid = np.linspace(0, theta_f[-1] + 1.0, int((theta_f[-1] + 1.0) / (2 * np.pi) * 4096))
    dth = grid[1] - grid[0]
    steps = rng.normal(0, 1, grid.size) * np.sqrt(dth / grid[-1])  # O(1) over the log
    kern = np.exp(-0.5 * (np.arange(-2048, 2049) / 600.0) ** 2)
    walk = np.convolve(np.cumsum(steps), kern / kern.sum(), mode="same")
    walk -= walk.mean()
    phys = direction * grid
    omega = 2 * np.pi * rev_per_s * (1 + wander * walk + ripple * np.sin(phys + 0.7))
    # a coasting table (spun up, then free): the speed falls linearly with angle (a constant
    # friction torque), by the fraction ``coast`` over the log
    omega *= np.sqrt(np.clip(1 - (2 * coast - coast**2) * grid / grid[-1], 1e-6, None))
    omega = np.maximum(omega, 0.2 * 2 * np.pi * rev_per_s * (1 - coast))
    t_grid = np.r_[0.0, np.cumsum(0.5 * (1 / omega[1:] + 1 / omega[:-1]) * dth)]
    t_face = np.interp(theta_f, grid, t_grid)
    om_face = np.interp(theta_f, grid, omega)
    t_pulse = t_face + latency_s + rng.normal(0, jitter_arcsec * ARCSEC, k_total) / om_face
    faces = idx % n
    # the autocollimator's faults
    keep = np.ones(k_total, bool)
    for m in missing:
        keep[m + 1] = False
    t_p, f_p = list(t_pulse[keep]), list(faces[keep])
    for m in sorted(doubled, reverse=True):
        j = int(np.searchsorted(t_p, t_pulse[m + 1])) + 1
        t_p.insert(j, t_pulse[m + 1] + double_delay_s)
        f_p.insert(j, -1)
    t_p, f_p = np.array(t_p), np.array(f_p)
    th_p = np.interp(t_p, t_grid, grid)
    omega_v = OMEGA_E * np.sin(np.radians(latitude_deg))
    phase = counts_per_rev / (2 * np.pi) * (th_p + direction * omega_v * t_p) + rng.random()
    counts = np.diff(np.floor(phase)).astype(np.int64)
    ref = (f_p[1:] == 0).astype(int)
    counter = 1 + np.arange(counts.size) % 2  # the counters are 1 and 2 (formats.md)
    t_log = t0 + t_p[1:]
    with open(path, "w") as fh:
        fh.write("count,counter,ref,t\n")
        for c, k, r, t in zip(counts, counter, ref, t_log, strict=True):
            fh.write(f"{c},{k},{r},{t:.7f}\n")
    per_rev = np.diff(np.interp(2 * np.pi * np.arange(revs + 1), grid, t_grid))
    return {"arm_face": int(order[arm]), "rows": int(counts.size),
            "speed_min_max": (float(omega.min()) / (2 * np.pi), float(omega.max()) / (2 * np.pi)),
            "max_rev_period_ratio": float(np.max(per_rev[1:] / per_rev[:-1]))}


# ---------------------------------------------------------------- the tumble


def sensitive_axes(gamma: tuple[float, float, float]) -> np.ndarray:
    """Rows: the accelerometers' unit sensitive axes in the triad's calibration frame (x along
    accelerometer x, y in the plane of x and y): y tilted by γ0 towards −x, z by γ1 towards x
    and γ2 towards y [rad]."""
    g0, g1, g2 = gamma
    s = np.array([[1.0, 0, 0], [-np.sin(g0), np.cos(g0), 0], [g1, g2, 1.0]])
    return s / np.linalg.norm(s, axis=1)[:, None]


def tumble_poses(rng: np.random.Generator, n_random: int = 18) -> np.ndarray:
    """Unit 'up' vectors in the triad frame: the six faces and random attitudes."""
    six = np.vstack([np.eye(3), -np.eye(3)])
    r = rng.normal(size=(n_random, 3))
    return np.vstack([six, r / np.linalg.norm(r, axis=1)[:, None]])


def triad_output(a: np.ndarray, t: np.ndarray, temp: np.ndarray, truth: dict,
                 rng: np.random.Generator) -> np.ndarray:
    """Outputs [V] of the triad for specific force ``a`` [g] (N×3, triad frame) at times ``t``
    [s] and temperatures ``temp`` [K]: x = S a + b + c_T (T − T0) + step (t ≥ t_step); per axis
    u = k (1 + A sign x) (1 + k_T (T − T0)) x + noise."""
    x = a @ truth["S"].T + truth["b"] + np.outer(temp - truth["T0"], truth["cT"])
    if truth.get("step") is not None:
        x = x + np.outer(t >= truth["t_step"], truth["step"])
    k = truth["k"] * (1 + truth["A"] * np.sign(x))
    if truth.get("kT") is not None:  # scale factor following the temperature [1/K]
        k = k * (1 + np.outer(temp - truth["T0"], truth["kT"]))
    return k * x + rng.normal(0, truth["noise"], x.shape)


def default_truth(rng: np.random.Generator) -> dict:
    return {"S": sensitive_axes(tuple(rng.normal(0, 1e-3, 3))),
            "k": np.array([2.41, -2.38, 2.45]) * (1 + rng.normal(0, 0.01, 3)),
            "b": rng.normal(0, 1e-3, 3), "cT": np.zeros(3), "T0": 298.15, "A": np.zeros(3),
            "step": None, "t_step": np.inf, "noise": 2e-4}


def tumble_file(path: Path, truth: dict, rng: np.random.Generator, *, n_random: int = 18,
                samples: int = 50, rate_hz: float = 100.0, pose_s: float = 20.0,
                temp_span_k: float = 0.0, with_temp: bool = False, temp_cycle: bool = False
                ) -> np.ndarray:
    """Write ``pose,ux,uy,uz,t[,temp]`` (``samples`` per pose, a pose every ``pose_s``) and
    return the up vectors. The temperature rises linearly by ``temp_span_k`` over the run, or
    (``temp_cycle``) swings ±``temp_span_k``/2 through one sine period (a room's cycle)."""
    ups = tumble_poses(rng, n_random)
    rows = []
    n_p = len(ups)
    for p, up in enumerate(ups):
        t = p * pose_s + np.arange(samples) / rate_hz
        frac = t / (n_p * pose_s)
        temp = truth["T0"] + temp_span_k * (0.5 * np.sin(2 * np.pi * frac) if temp_cycle
                                            else frac - 0.5)
        u = triad_output(np.tile(up, (samples, 1)), t, temp, truth, rng)
        for j in range(samples):
            rows.append((f"P{p:02d}", *u[j], t[j], temp[j]))
    with open(path, "w") as fh:
        fh.write("pose,ux,uy,uz,t" + (",temp\n" if with_temp else "\n"))
        for r in rows:
            tail = f",{r[5]:.4f}" if with_temp else ""
            fh.write(f"{r[0]},{r[1]:.7f},{r[2]:.7f},{r[3]:.7f},{r[4]:.3f}{tail}\n")
    return ups


def roll_pitch(up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch [rad] of 'up' specific-force vectors (N×3), exact formula."""
    return (np.arctan2(up[:, 1], up[:, 2]),
            np.arctan2(-up[:, 0], np.hypot(up[:, 1], up[:, 2])))


def frame_from_axes(s: np.ndarray, first: int, second: int) -> np.ndarray:
    """Rotation (rows: the frame's x, y, z in the triad frame) of the orthogonal frame whose
    axis ``first`` lies along sensitive axis ``first`` and whose axis ``second`` lies in the
    plane of sensitive axes ``first`` and ``second`` (Gram–Schmidt)."""
    e = np.zeros((3, 3))
    e[first] = s[first] / np.linalg.norm(s[first])
    v = s[second] - (s[second] @ e[first]) * e[first]
    e[second] = v / np.linalg.norm(v)
    third = 3 - first - second
    e[third] = np.cross(e[(third + 1) % 3], e[(third + 2) % 3])
    return e
