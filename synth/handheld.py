"""Continuous hand-held recordings of an accelerometer triad: short poses, slow handling between.

What a user with a phone or a bare board records: the unit is set down (or held still) in one
orientation for ``dwell_s`` (1–3 s), then turned by hand to the next one over ``move_s`` with a
smooth minimum-jerk profile (slow at both ends: the hardest case for a static detector) while
the hand also carries it a few centimetres. The specific force is gravity in the body frame
plus the hand's linear acceleration; the outputs follow :class:`synth.tumble.Triad` (seed
paper's model, exact R) with white noise, optional quantisation. Each consecutive pair of
poses differs by ``min_turn_rad`` or more (a user turns the unit, not nudges it).

Imports nothing from the pipeline. Returns the samples and the true pose intervals.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from synth.tumble import Triad

G0 = 9.80665  # [m/s^2]


@dataclass(frozen=True)
class HandheldSpec:
    """A hand-held recording: ``n_poses`` orientations, ``rate_hz`` [Hz], dwell and move
    times drawn uniformly from the given ranges [s], white noise ``noise_g`` [g] per sample
    and axis, hand translation ``carry_m`` [m] per move, ``lead_s`` [s] of rest at the start."""

    triad: Triad = field(default_factory=lambda: Triad(k=(1.0, 1.0, 1.0), noise_v=0.0))
    n_poses: int = 30
    rate_hz: float = 50.0
    dwell_s: tuple[float, float] = (1.0, 3.0)
    move_s: tuple[float, float] = (1.0, 3.0)
    noise_g: float = 1e-3
    carry_m: float = 0.1
    min_turn_rad: float = np.deg2rad(30.0)
    lead_s: float = 0.0
    seed: int = 0


@dataclass(frozen=True)
class HandheldRecording:
    """Samples ``t`` [s], ``u`` (N, 3) [output units], the true static intervals ``poses``
    (start, end) [s] (first and last sample of each pose), and each pose's up direction in
    the unit's frame ``up`` (n, 3)."""

    t: np.ndarray
    u: np.ndarray
    poses: tuple[tuple[float, float], ...]
    up: np.ndarray
    spec: HandheldSpec

    def write_csv(self, path: str | Path, with_time: bool = False) -> Path:
        """``ux,uy,uz`` (or ``t,ux,uy,uz``) text; never overwrites."""
        path = Path(path)
        if path.exists():
            raise FileExistsError(f"{path}: exists; synth never overwrites files")
        cols = [self.t, *self.u.T] if with_time else list(self.u.T)
        head = ("t," if with_time else "") + "ux,uy,uz"
        np.savetxt(path, np.column_stack(cols), fmt="%.9g", delimiter=",", header=head,
                   comments="")
        return path


def _min_jerk(x: np.ndarray) -> np.ndarray:
    """Position profile 10x^3 - 15x^4 + 6x^5 on [0, 1] and its second derivative."""
    return 10 * x**3 - 15 * x**4 + 6 * x**5


def _min_jerk_acc(x: np.ndarray) -> np.ndarray:
    return 60 * x - 180 * x**2 + 120 * x**3


def _next_up(prev: np.ndarray, rng: np.random.Generator, min_turn: float) -> np.ndarray:
    while True:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if np.arccos(np.clip(v @ prev, -1, 1)) >= min_turn:
            return v


def handheld(spec: HandheldSpec) -> HandheldRecording:
    """Simulate the recording (seeded by ``spec.seed``)."""
    rng = np.random.default_rng(spec.seed)
    dt = 1.0 / spec.rate_hz
    ups = [np.array([0.0, 0.0, 1.0])]
    for _ in range(spec.n_poses - 1):
        ups.append(_next_up(ups[-1], rng, spec.min_turn_rad))
    # Body orientation whose "up" (world z seen in the body frame) is ups[i], random yaw.
    rots = []
    for u_ in ups:
        r = Rotation.align_vectors([u_], [[0, 0, 1]])[0]  # world->body maps z to u_
        rots.append(r * Rotation.from_rotvec([0, 0, rng.uniform(0, 2 * np.pi)]))
    f_chunks, t_chunks, poses = [], [], []
    k = 0
    for i, r in enumerate(rots):
        dwell = rng.uniform(*spec.dwell_s) + (spec.lead_s if i == 0 else 0.0)
        n = max(1, int(round(dwell * spec.rate_hz)))
        f_chunks.append(np.repeat(r.apply([0, 0, 1])[None], n, axis=0))
        t_chunks.append((k + np.arange(n)) * dt)
        poses.append(((k) * dt, (k + n - 1) * dt))
        k += n
        if i + 1 == len(rots):
            break
        move = rng.uniform(*spec.move_s)
        m = max(2, int(round(move * spec.rate_hz)))
        x = (np.arange(1, m + 1)) / (m + 1)
        s = Slerp([0, 1], Rotation.concatenate([r, rots[i + 1]]))(_min_jerk(x))
        # Hand translation: min-jerk over the move in a random world direction [m/s^2 -> g].
        d = rng.normal(size=3)
        d *= spec.carry_m / np.linalg.norm(d)
        acc_world = np.outer(_min_jerk_acc(x) / move**2, d) / G0
        f_world = np.array([0, 0, 1.0]) + acc_world
        f_chunks.append(s.apply(f_world))
        t_chunks.append((k + np.arange(m)) * dt)
        k += m
    f = np.vstack(f_chunks)
    t = np.concatenate(t_chunks)
    k_abs = float(np.mean(np.abs(spec.triad.k)))
    tr = replace(spec.triad, noise_v=spec.noise_g * k_abs)
    u = tr.outputs(f, t, np.zeros_like(t), rng)
    return HandheldRecording(t, u, tuple(poses), np.array(ups), spec)
