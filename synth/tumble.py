"""Synthetic static tumble tests of an accelerometer triad, with known truth.

The triad follows the seed paper's model with the exact trigonometric R of eq. (5):

    x = R (a + b(t, T) + h)                  input along each sensing axis [g]
    u_i = k_i s_i(t) (1 + A_i sign x_i) (x_i + K2_i x_i^2 + K3_i x_i^3
                                        + sum_{j<l} K_i,jl x_j x_l) + noise
                                             output [V], quantised to ``lsb_v``

a is the specific force in the unit's orthogonal "convenient" frame [g] (static: the unit
vector pointing up, times g_local / g0), b the bias [g] drifting linearly in time (``drift``
[g/s]) and with temperature (``temp_coeff`` [g/K]), K2 the second-order nonlinearity [1/g],
K_i,jl the cross-axis second-order terms (IEEE Std 1293's K_ip, K_io: the pendulum of axis i
also responds to the product of two inputs) [1/g], s_i(t) = 1 + ``scale_drift_i`` t +
``scale_warmup_i`` exp(-t / ``warmup_tau_s``) [+ ``scale_cycle_i`` sin(2 pi t / P + phi), a
temperature cycle] the scale factor drifting in time (electronics
ageing over the run, and settling after switch-on), h the bias hysteresis: a pendulum that
sticks lags behind the way it last moved, so each pose's bias is offset by
``hysteresis_g_i`` x the sign of the change of x_i in the turn into the pose (0 for the first
pose: it was not turned into).
Poses come from fixtures (the paper's cube: 6 faces + 8 vertices) placed with small random
errors, or are random; each pose is held for ``dwell_s`` and sampled at ``rate_hz``.

The Cramér–Rao bound of (k, beta, b) is computed from the Fisher information of the per-pose
means with every pose direction as a nuisance parameter (the directions are unknown to any
calibration that does not trust the fixture).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

# Seed paper, Table 1: k [V/g], beta [rad], b [g].
TABLE1_K = (-2.410618, -2.403823, -2.371761)
TABLE1_BETA = (625.454406e-6, 404.734018e-6, -65.046441e-6)
TABLE1_BIAS = (564.518583e-6, -288.4559e-6, 463.952349e-6)


def r_matrix(beta: np.ndarray) -> np.ndarray:
    """The paper's exact R (eq. 5) for beta = (bx, by, bz) [rad].

    Written here as well as in align.calibration on purpose: synth imports nothing from the
    pipeline, so a mistake on one side cannot hide in both.
    """
    bx, by, bz = beta
    return np.array([
        [1.0, np.sin(bz), np.cos(bz) * np.sin(by)],
        [0.0, np.cos(bz), np.cos(by) * np.sin(bx)],
        [0.0, 0.0, np.cos(bx) * np.cos(by)],
    ])


@dataclass(frozen=True)
class Triad:
    """Accelerometer triad parameters (SI-ish: V, g, rad, s, K)."""

    k: tuple[float, float, float] = TABLE1_K
    beta: tuple[float, float, float] = TABLE1_BETA
    bias: tuple[float, float, float] = TABLE1_BIAS
    k2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    k3: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Third-order nonlinearity K3 [1/g²] (IEEE Std 1293's K3: the pendulum's restoring
    force is not quite linear; odd, so a ±1 g pose cannot tell it from k)."""
    asymmetry: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Scale-factor asymmetry (k+ - k-) / (k+ + k-) [1]: the output per g differs for a
    positive and a negative input (IEEE Std 1293; a pendulous sensor's torquer); ``k`` is
    (k+ + k-) / 2."""
    drift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    temp_coeff: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cross: tuple[tuple[float, float, float], ...] = ((0.0,) * 3,) * 3
    """Per output axis i, (K_i,xy, K_i,xz, K_i,yz) [1/g] on the products of the inputs."""
    scale_drift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Relative scale-factor change per second [1/s] (from t = 0)."""
    scale_warmup: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Relative scale-factor excess at switch-on (t = 0), decaying with ``warmup_tau_s``."""
    warmup_tau_s: float = 300.0
    scale_cycle: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Relative scale-factor amplitude of a temperature cycle (an HVAC's ±1 K at 100 ppm/K:
    1e-4): s_i gains ``scale_cycle_i`` sin(2 pi t / ``cycle_period_s`` + ``cycle_phase``)."""
    cycle_period_s: float = 900.0
    cycle_phase: float = 0.0
    hysteresis_g: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Bias offset [g] x the sign of the last change of each axis's input (see the module)."""
    bias_walk_g: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Bias random walk [g/√s] per axis (a bias instability): the bias wanders by this x √t
    over t seconds, while the unit is turned too (from t = 0, where it is ``bias``)."""
    noise_v: float = 2.4e-5
    lsb_v: float = 0.0
    full_scale_v: float = 10.0
    axes: tuple[tuple[float, float, float], ...] | None = None

    def sensing(self) -> np.ndarray:
        """Rows: the sensing axes in the frame of ``a`` — ``axes`` (unit vectors of a
        mounted triad) when given, else the paper's R(beta) in its convenient frame."""
        return np.asarray(self.axes, float) if self.axes is not None else r_matrix(
            np.asarray(self.beta))

    def outputs(self, a: np.ndarray, t: np.ndarray, temp: np.ndarray,
                rng: np.random.Generator | None, offset: np.ndarray | None = None
                ) -> np.ndarray:
        """Outputs u (N, 3) [V] for specific forces a (N, 3) [g] at times t [s], temps [K];
        ``offset`` (N, 3) [g]: a bias added per sample (the hysteresis, from the motion)."""
        b = (np.asarray(self.bias) + np.outer(t, self.drift)
             + np.outer(temp, self.temp_coeff))
        if offset is not None:
            b = b + offset
        x = (a + b) @ self.sensing().T
        prod = np.column_stack([x[:, 0] * x[:, 1], x[:, 0] * x[:, 2], x[:, 1] * x[:, 2]])
        s = (1.0 + np.outer(t, self.scale_drift)
             + np.outer(np.exp(-np.asarray(t, float) / self.warmup_tau_s), self.scale_warmup)
             + np.outer(np.sin(2 * np.pi * np.asarray(t, float) / self.cycle_period_s
                               + self.cycle_phase), self.scale_cycle))
        # The asymmetry follows the sign of the sensor's own input x_i (its pendulum swings
        # one way or the other), not of the output.
        s = s * (1.0 + np.sign(x) * np.asarray(self.asymmetry))
        u = np.asarray(self.k) * s * (x + np.asarray(self.k2) * x * x
                                      + np.asarray(self.k3) * x ** 3
                                      + prod @ np.asarray(self.cross, float).T)
        if rng is not None and self.noise_v:
            u = u + rng.normal(0.0, self.noise_v, u.shape)
        if self.lsb_v:
            u = np.round(u / self.lsb_v) * self.lsb_v
        return np.clip(u, -self.full_scale_v, self.full_scale_v)


def pose_directions(kind: str, n: int = 24, rng: np.random.Generator | None = None
                    ) -> np.ndarray:
    """Up directions (unit vectors, unit frame) of a pose set.

    ``cube14``: the paper's cube on 6 faces and 8 vertices; ``six``: the faces;
    ``cube24``: faces, and the 12 edges' and 6 more face-diagonal... (24 = 6 faces + 8
    vertices + 10 edge midpoints); ``random``: n uniform on the sphere.
    """
    faces = np.vstack([np.eye(3), -np.eye(3)])
    verts = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)],
                     float) / np.sqrt(3)
    if kind == "six":
        return faces
    if kind == "cube14":
        return np.vstack([faces, verts])
    if kind == "cube24":
        edges = np.array([v for v in
                          [[1, 1, 0], [1, -1, 0], [-1, 1, 0], [-1, -1, 0], [1, 0, 1],
                           [1, 0, -1], [-1, 0, 1], [-1, 0, -1], [0, 1, 1], [0, -1, -1]]],
                         float) / np.sqrt(2)
        return np.vstack([faces, verts, edges])
    if kind == "random":
        rng = rng or np.random.default_rng(0)
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    raise ValueError(f"unknown pose set {kind!r}: use six, cube14, cube24 or random")


@dataclass(frozen=True)
class TumbleSpec:
    """A tumble test. ``fixture_error_rad``: RMS placement error of each pose (random
    rotation); ``g_ratio``: local gravity / the g used as unit."""

    triad: Triad = field(default_factory=Triad)
    poses: str = "cube14"
    n_random: int = 24
    check_poses: int = 5
    fixture_error_rad: float = 100e-6
    dwell_s: float = 10.0
    move_s: float = 5.0
    rate_hz: float = 20.0
    temp_start_k: float = 0.0
    temp_rate_k_per_s: float = 0.0
    g_ratio: float = 1.0
    seed: int = 0
    up: tuple[tuple[float, float, float], ...] | None = None
    """Up directions of the poses in the order held (overrides ``poses``): a planned order."""


@dataclass(frozen=True)
class TumbleData:
    """Samples of a tumble test: ``pose`` index per sample (check poses after the
    calibration poses), ``t`` [s], ``u`` (N, 3) [V], ``temp`` [K]; ``up`` true directions."""

    pose: np.ndarray
    t: np.ndarray
    u: np.ndarray
    temp: np.ndarray
    up: np.ndarray
    n_cal: int
    spec: TumbleSpec

    def means(self, check: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-pose (mean u, mean t, sample count) of calibration or check poses."""
        ids = range(self.n_cal, len(self.up)) if check else range(self.n_cal)
        sel = [self.pose == i for i in ids]
        return (np.array([self.u[s].mean(0) for s in sel]),
                np.array([self.t[s].mean() for s in sel]),
                np.array([s.sum() for s in sel]))

    def truth(self) -> dict:
        tr = self.spec.triad
        return {"k_v_per_g": list(tr.k), "beta_rad": list(tr.beta), "bias_g": list(tr.bias),
                "k2_per_g": list(tr.k2), "k3_per_g2": list(tr.k3),
                "scale_asymmetry": list(tr.asymmetry), "drift_g_per_s": list(tr.drift),
                "temp_coeff_g_per_k": list(tr.temp_coeff),
                "cross_per_g": [list(r) for r in tr.cross], "scale_drift_per_s":
                list(tr.scale_drift), "scale_warmup": list(tr.scale_warmup),
                "warmup_tau_s": tr.warmup_tau_s, "hysteresis_g": list(tr.hysteresis_g),
                "bias_walk_g": list(tr.bias_walk_g),
                "noise_v": tr.noise_v,
                "lsb_v": tr.lsb_v, "poses": self.spec.poses, "n_cal": self.n_cal,
                "mean_time_s": float(self.t[self.pose < self.n_cal].mean()),
                "seed": self.spec.seed}


def _placed(up: np.ndarray, err: float, rng: np.random.Generator) -> np.ndarray:
    if err == 0:
        return up
    rot = Rotation.from_rotvec(rng.normal(0, err / np.sqrt(2), (len(up), 3)))
    return rot.apply(up)


def tumble(spec: TumbleSpec) -> TumbleData:
    """Simulate the static poses (samples only while the unit is at rest)."""
    rng = np.random.default_rng(spec.seed)
    dirs = (np.asarray(spec.up, float) if spec.up is not None
            else pose_directions(spec.poses, spec.n_random, rng))
    up = _placed(dirs, spec.fixture_error_rad, rng)
    n_cal = len(up)
    if spec.check_poses:
        up = np.vstack([up, pose_directions("random", spec.check_poses, rng)])
    n = int(round(spec.dwell_s * spec.rate_hz))
    pose = np.repeat(np.arange(len(up)), n)
    start = np.arange(len(up)) * (spec.dwell_s + spec.move_s)
    t = (start[:, None] + np.arange(n)[None, :] / spec.rate_hz).ravel()
    temp = spec.temp_start_k + spec.temp_rate_k_per_s * t
    a = up[pose] * spec.g_ratio
    offset = hysteresis(spec.triad, up)[pose]
    if any(spec.triad.bias_walk_g):
        offset = offset + bias_walk(spec.triad, t, rng)
    u = spec.triad.outputs(a, t, temp, rng, offset)
    return TumbleData(pose, t, u, temp, up, n_cal, spec)


def bias_walk(triad: Triad, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The bias's random walk (N, 3) [g] at the sample times ``t`` [s] (increasing): a Wiener
    process of ``bias_walk_g`` [g/√s] from 0 at t = 0 that goes on between the samples (the
    turns between poses included)."""
    dt = np.diff(np.concatenate([[0.0], np.asarray(t, float)]))
    steps = rng.normal(size=(len(dt), 3)) * np.sqrt(dt)[:, None]
    return np.cumsum(steps, axis=0) * np.asarray(triad.bias_walk_g, float)


HYSTERESIS_MOVE_G = 0.02
"""Smallest change of an axis's input [g] that carries its pendulum to the other side of its
hysteresis loop; a smaller one (a fixture's wobble) leaves it on the side it was."""


def hysteresis(triad: Triad, up: np.ndarray) -> np.ndarray:
    """Bias offset (N, 3) [g] of each pose held in the order given: ``hysteresis_g`` x the sign
    of the last change of each sensing axis's input larger than :data:`HYSTERESIS_MOVE_G`
    (0 before any: the first pose was not turned into)."""
    x = up @ triad.sensing().T
    state = np.zeros(3)
    out = np.zeros_like(x)
    for p in range(1, len(x)):
        d = x[p] - x[p - 1]
        state = np.where(np.abs(d) > HYSTERESIS_MOVE_G, np.sign(d), state)
        out[p] = state
    return out * np.asarray(triad.hysteresis_g, float)


def recording(spec: TumbleSpec, vibration_g: float = 0.05) -> tuple[np.ndarray, np.ndarray,
                                                                       list[tuple[float, float]]]:
    """A continuous recording (t, u) with motion between the static poses.

    Between poses the unit turns (slerp) and is shaken (random accelerations of
    ``vibration_g``); returns t [s], u (N, 3) [V] and the true static intervals [s]. The bias
    hysteresis is the tumble's (:func:`hysteresis`: each static pose on the side of the turn
    into it); during a turn an axis's pendulum changes side once its input (without the
    shaking) has moved more than :data:`HYSTERESIS_MOVE_G` from the pose it left.
    """
    rng = np.random.default_rng(spec.seed + 1)
    up = _placed(pose_directions(spec.poses, spec.n_random, rng), spec.fixture_error_rad, rng)
    side = hysteresis(spec.triad, up)
    sensing = spec.triad.sensing()
    # Orientations whose "up" is each pose direction (any yaw).
    rots = [Rotation.align_vectors([u_], [[0, 0, 1]])[0] for u_ in up]
    dt = 1 / spec.rate_hz
    ts, us, intervals = [], [], []
    t0 = 0.0
    for i, r in enumerate(rots):
        tt = t0 + np.arange(int(spec.dwell_s * spec.rate_hz)) * dt
        a = np.repeat(r.apply([0, 0, 1])[None] * spec.g_ratio, len(tt), axis=0)
        ts.append(tt)
        us.append(spec.triad.outputs(a, tt, spec.temp_start_k + 0 * tt, rng,
                                     np.repeat(side[i][None], len(tt), axis=0)))
        intervals.append((float(tt[0]), float(tt[-1])))
        t0 = tt[-1] + dt
        if i + 1 < len(rots):
            tm = t0 + np.arange(int(spec.move_s * spec.rate_hz)) * dt
            s = Slerp([0, 1], Rotation.concatenate([r, rots[i + 1]]))
            frac = (tm - tm[0]) / max(tm[-1] - tm[0], dt)
            a = s(frac).apply([0, 0, 1]) * spec.g_ratio
            moved = np.logical_or.accumulate(
                np.abs((a - a[0]) @ sensing.T) > HYSTERESIS_MOVE_G, axis=0)
            offset = np.where(moved, side[i + 1], side[i])
            a = a + rng.normal(0, vibration_g, a.shape)
            ts.append(tm)
            us.append(spec.triad.outputs(a, tm, spec.temp_start_k + 0 * tm, rng, offset))
            t0 = tm[-1] + dt
    return np.concatenate(ts), np.vstack(us), intervals


def fisher_crlb(triad: Triad, up: np.ndarray, sigma_mean_v: np.ndarray) -> np.ndarray:
    """Covariance bound of (k, beta, b) (9x9) from per-pose means with unknown directions.

    Each pose direction is a nuisance (two angles); the bound is the inverse of the Schur
    complement of the Fisher information. ``sigma_mean_v``: per-pose standard deviation of
    each mean output component [V] (scalar or per pose).
    """
    n = len(up)
    sig = np.broadcast_to(np.asarray(sigma_mean_v, float), (n,))
    theta0 = np.concatenate([triad.k, triad.beta, triad.bias])
    az = np.arctan2(up[:, 1], up[:, 0])
    el = np.arcsin(np.clip(up[:, 2], -1, 1))

    def model(theta, az, el):
        tr = replace(triad, k=tuple(theta[:3]), beta=tuple(theta[3:6]), bias=tuple(theta[6:9]),
                     noise_v=0.0, lsb_v=0.0)
        d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        return tr.outputs(d, np.zeros(n), np.zeros(n), None)

    cols = []
    for j in range(9):
        h = 1e-7 * max(1.0, abs(theta0[j]))
        tp, tm = theta0.copy(), theta0.copy()
        tp[j] += h
        tm[j] -= h
        cols.append(((model(tp, az, el) - model(tm, az, el)) / (2 * h)).ravel())
    Jt = np.column_stack(cols)  # (3n, 9)
    Jn = np.zeros((3 * n, 2 * n))
    for which, arr in ((0, az), (1, el)):
        h = 1e-7
        ap, am = arr.copy(), arr.copy()
        ap += h
        am -= h
        plus = model(theta0, ap, el) if which == 0 else model(theta0, az, ap)
        minus = model(theta0, am, el) if which == 0 else model(theta0, az, am)
        d = (plus - minus) / (2 * h)  # (n, 3): pose p only moves its own output
        for p in range(n):
            Jn[3 * p:3 * p + 3, 2 * p + which] = d[p]
    w = np.repeat(1 / sig**2, 3)
    Ftt = Jt.T @ (Jt * w[:, None])
    Ftn = Jt.T @ (Jn * w[:, None])
    Fnn = Jn.T @ (Jn * w[:, None])
    schur = Ftt - Ftn @ np.linalg.solve(Fnn, Ftn.T)
    return np.linalg.inv(schur)


def write_tumble_csv(data: TumbleData, path: str | Path, check: bool = False,
                     per_sample: bool = True) -> Path:
    """Write ``pose,ux,uy,uz,t[,temp]`` (calibration or check poses); never overwrite."""
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path}: exists; synth never overwrites files")
    lo, hi = (data.n_cal, len(data.up)) if check else (0, data.n_cal)
    with_temp = data.spec.temp_rate_k_per_s != 0 or data.spec.temp_start_k != 0
    head = "pose,ux,uy,uz,t" + (",temp" if with_temp else "")
    rows = []
    if per_sample:
        sel = (data.pose >= lo) & (data.pose < hi)
        cols = [data.pose[sel], *data.u[sel].T, data.t[sel]]
        if with_temp:
            cols.append(data.temp[sel])
        rows = np.column_stack(cols)
    else:
        for i in range(lo, hi):
            s = data.pose == i
            r = [i, *data.u[s].mean(0), data.t[s].mean()]
            if with_temp:
                r.append(data.temp[s].mean())
            rows.append(r)
        rows = np.array(rows)
    fmt = ["%d"] + ["%.9e"] * 3 + ["%.4f"] + (["%.4f"] if with_temp else [])
    np.savetxt(path, rows, fmt=fmt, delimiter=",", header=head, comments="")
    path.with_suffix(".truth.json").write_text(json.dumps(data.truth(), indent=2))
    return path

