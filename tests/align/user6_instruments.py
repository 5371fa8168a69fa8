"""user6's own instruments, written from physics with numpy only (split from
:mod:`tests.align.user6_inputs`, which re-exports them): a ring-laser goniometer's counter
log and a tumble of an accelerometer triad with effects. Angles inside are radians;
arc-seconds only where a name says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ARCSEC = np.pi / 180 / 3600
OMEGA_EARTH = 7.2921150e-5  # rad/s


# ----------------------------------------------------------------------------- goniometer

@dataclass
class Gonio:
    """A rotary table with a polygon of faces, watched by an autocollimator, timed by a ring
    laser whose phase is counted by two alternating counters."""

    deviations_arcsec: tuple = (287.6, 0.4, -355.9, 67.9)  # face k -> k+1 minus 90 deg
    counts_per_rev: float = 764355.84
    rev_per_s: float = 1.0
    revolutions: int = 100
    ripple: float = 0.01        # table speed ripple (fraction), locked to the table
    wander: float = 0.005       # slow speed wander (fraction)
    jitter_arcsec: float = 0.3  # autocollimator trigger jitter
    latitude_deg: float = 50.45
    seed: int = 0

    def face_angles(self) -> np.ndarray:
        """Table rotation from face k to face k+1 [rad]; closes to 2 pi (last absorbs)."""
        d = np.asarray(self.deviations_arcsec, float) * ARCSEC
        d[-1] = -d[:-1].sum()
        return np.full(len(d), np.pi / 2) + d

    def truth_deg(self) -> np.ndarray:
        return np.rad2deg(self.face_angles())

    def rows(self) -> np.ndarray:
        """(count, counter, ref, t) rows: the first row is the pulse after the arming
        reference pulse (which has no row)."""
        rng = np.random.default_rng(self.seed)
        a = self.face_angles()
        nf = len(a)
        n = self.revolutions * nf
        cum = np.concatenate([[0.0], np.cumsum(np.tile(a, self.revolutions))])  # pulse angles
        cum = cum + rng.normal(0, self.jitter_arcsec * ARCSEC, cum.size)
        cum[0] = 0.0
        w = 2 * np.pi * self.rev_per_s
        # table angle theta(t) = w t + ripple sin(theta-locked) + wander: invert by Newton
        wp = rng.uniform(0, 2 * np.pi)
        slow = 2 * np.pi * 0.013

        def theta(t):
            return w * t + self.ripple * np.sin(w * t) + self.wander * np.sin(slow * t + wp)

        def dtheta(t):
            return w + self.ripple * w * np.cos(w * t) + self.wander * slow * np.cos(slow * t + wp)

        t = cum / w
        for _ in range(30):
            t = t - (theta(t) - theta(0.0) - cum) / dtheta(t)
        t = t - t[0]
        omega_v = OMEGA_EARTH * np.sin(np.deg2rad(self.latitude_deg))
        phase = self.counts_per_rev / (2 * np.pi) * (cum + omega_v * t) + rng.uniform()
        counts = np.diff(np.floor(phase)).astype(np.int64)
        k = np.arange(1, n + 1)
        counter = np.where(k % 2 == 1, 1, 2)
        ref = (k % nf == 0).astype(int)
        return np.column_stack([counts, counter, ref, t[1:]]).astype(object)


def write_gonio(path: Path, rows, with_t: bool = True) -> Path:
    lines = ["count,counter,ref,t" if with_t else "count,counter,ref"]
    for r in rows:
        c = f"{int(r[0])},{int(r[1])},{int(r[2])}"
        lines.append(c + (f",{float(r[3]):.9f}" if with_t else ""))
    path.write_text("\n".join(lines) + "\n")
    return path


# ----------------------------------------------------------------------------- triad

def cube14() -> np.ndarray:
    """14 tumble attitudes as the specific force's direction in the triad's fixture frame:
    the six faces and the eight cube corners."""
    f = [np.eye(3)[i] * s for i in range(3) for s in (1, -1)]
    c = [np.array([a, b, d]) / np.sqrt(3) for a in (1, -1) for b in (1, -1) for d in (1, -1)]
    return np.array(f + c)


def random_dirs(n: int, rng) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None]


@dataclass
class Triad:
    """u_i = k_i (1 + eps_i(temp)) (s_i . f) + b_i + noise: s_i the sensitive axes in the
    fixture/platform frame (rows of S), f the specific force [g]."""

    S: np.ndarray
    k: np.ndarray = field(default_factory=lambda: np.array([2.41, 2.39, 2.42]))   # V/g
    b: np.ndarray = field(default_factory=lambda: np.array([0.8e-3, -1.1e-3, 0.4e-3]))  # V
    noise: float = 60e-6   # V per sample

    def read(self, f: np.ndarray, rng, scale_factor=1.0) -> np.ndarray:
        f = np.atleast_2d(f)
        clean = (np.asarray(scale_factor)[..., None] * self.k) * (f @ self.S.T) + self.b
        return clean + rng.normal(0, self.noise, clean.shape)


def s_from_E(E: np.ndarray) -> np.ndarray:
    """Unit sensitive axes (rows) with E_ij = s_ij / s_ii exactly."""
    M = np.eye(3) + E
    return M / np.linalg.norm(M, axis=1)[:, None]


def E_arcsec(exy, exz, eyx, eyz, ezx, ezy) -> np.ndarray:
    return np.array([[0, exy, exz], [eyx, 0, eyz], [ezx, ezy, 0]]) * ARCSEC


def tumble_rows(triad: Triad, dirs: np.ndarray, rng, n: int = 200, rate: float = 20.0,
                labels=None, scale_of_t=None, vib=None, clip=None, t_gap: float = 5.0):
    """Per-sample rows (pose, t, ux, uy, uz). ``scale_of_t(t)``: the scale factor's relative
    factor at time t (e.g. temperature); ``vib = (pose, amp_g, freq_hz)``: a vibration along
    the pose's up; ``clip = (axis, rail)``: the analogue stage saturates at rail [V] and the
    ADC adds its noise after it (no pile at one value)."""
    out = []
    t0 = 0.0
    for p, d in enumerate(dirs):
        t = t0 + np.arange(n) / rate
        f = np.tile(d, (n, 1))
        if vib is not None and vib[0] == p:
            f = f + np.outer(vib[1] * np.sin(2 * np.pi * vib[2] * t), d)
        sf = scale_of_t(t) if scale_of_t is not None else np.ones(n)
        clean = (sf[:, None] * triad.k) * (f @ triad.S.T) + triad.b
        if clip is not None:
            ax, rail = clip
            clean[:, ax] = np.clip(clean[:, ax], -rail, rail)
        u = clean + rng.normal(0, triad.noise, clean.shape)
        lab = labels[p] if labels is not None else str(p)
        out += [(lab, ti, *ui) for ti, ui in zip(t, u, strict=True)]
        t0 = t[-1] + t_gap
    return out


def write_tumble(path: Path, rows, with_t: bool = True, header_unit: str = "") -> Path:
    h = "pose,t,ux,uy,uz" if with_t else "pose,ux,uy,uz"
    if header_unit:
        h = h.replace("ux,uy,uz", f"ux [{header_unit}],uy [{header_unit}],uz [{header_unit}]")
    lines = [h]
    for r in rows:
        vals = ",".join(f"{v:.9e}" for v in r[2:])
        lines.append(f"{r[0]},{r[1]:.4f},{vals}" if with_t else f"{r[0]},{vals}")
    path.write_text("\n".join(lines) + "\n")
    return path


def pose_means(rows) -> list:
    """Per-pose means (pose, ux, uy, uz) in the order the poses first appear."""
    order, acc = [], {}
    for r in rows:
        if r[0] not in acc:
            order.append(r[0])
            acc[r[0]] = []
        acc[r[0]].append(r[2:])
    return [(p, *np.mean(acc[p], axis=0)) for p in order]
