"""A counter log written the way a new user would simulate one, independently of synth/:
a ring laser of 2^20 periods per inertial revolution (table angle plus the Earth's rotation
about the vertical), its continuous phase floored by two alternating counters, the table's
speed with a ripple locked to its angle and a slow random part (a few random sinusoids in
time), autocollimator jitter on each pulse, time stamps of a 10 MHz clock, a ccw table.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

K = 2.0**20
OMEGA_E = 7.2921150e-5
ARCSEC = np.pi / 648000


def independent_log(path: Path, revs: int, rev_per_s: float, ripple: float, wander: float,
                    latitude_deg: float, seed: int, jitter_arcsec: float = 0.1,
                    arm_face: int = 0, stop_pulses: int = 0) -> np.ndarray:
    """Write the log; return the true angles between consecutive faces [rad]."""
    rng = np.random.default_rng(seed)
    az = np.array([0.0, np.pi / 2 + 140 * ARCSEC, np.pi - 210 * ARCSEC,
                   1.5 * np.pi + 80 * ARCSEC])
    w0 = 2 * np.pi * rev_per_s
    T = (revs + 2) / rev_per_s
    # The table's speed in time: locked ripple (a function of the angle, so integrated on an
    # angle grid) and a slow random part made of sinusoids of 30-300 s periods.
    per = rng.uniform(30, 300, 6)
    ph = rng.uniform(0, 2 * np.pi, 6)
    amp = rng.normal(0, 1, 6)
    amp *= wander / np.sqrt(np.sum(amp**2) / 2)
    dt = 2e-3
    t = np.arange(0, T, dt)
    theta = np.empty_like(t)
    th, ph_r = 0.0, 0.7
    arg = 2 * np.pi * t[None, :] / per[:, None] + ph[:, None]
    slow = (1 + (amp[:, None] * np.sin(arg)).sum(0)).tolist()
    # Midpoint steps: d theta / dt = w0 (1 + ripple sin(theta + ph_r)) * slow(t).
    for i in range(len(t)):
        theta[i] = th
        k1 = w0 * (1 + ripple * math.sin(th + ph_r)) * slow[i]
        mid = th + 0.5 * dt * k1
        th += dt * w0 * (1 + ripple * math.sin(mid + ph_r)) * slow[i]
    targets = (np.arange(revs + 1)[:, None] * 2 * np.pi + az[None, :]).ravel()
    t_face = np.interp(targets, theta, t)
    w_at = np.interp(t_face, t, np.gradient(theta, t))
    t_pulse = t_face + rng.normal(0, jitter_arcsec * ARCSEC, t_face.size) / w_at
    th_p = np.interp(t_pulse, t, theta)
    rate = OMEGA_E * np.sin(np.deg2rad(latitude_deg))  # ccw table, north: adds
    phase = K * (th_p + rate * t_pulse) / (2 * np.pi) + rng.random()
    cum = np.floor(phase)
    face = np.arange(t_pulse.size) % 4
    a = arm_face
    end = t_pulse.size - stop_pulses
    counts = np.diff(cum[a:end]).astype(np.int64)
    ref = (face[a + 1:end] == 0).astype(int)
    stamp = np.floor((t_pulse[a + 1:end] - t_pulse[a]) * 1e7) / 1e7
    counter = np.arange(counts.size) % 2 + 1
    with open(path, "x") as f:
        f.write("count,counter,ref,t\n")
        for row in zip(counts, counter, ref, stamp, strict=True):
            f.write(f"{row[0]},{row[1]},{row[2]},{row[3]:.7f}\n")
    return np.diff(np.append(az, 2 * np.pi))
