"""Seeded logs without times that lose a whole number of revolutions (4-20 rows on a 4-face
table, anywhere: each such burst takes a reference pulse's row with it), and their
drop-out-free twins: shared by ``test_dropouts.py`` and ``benchmarks/gonio_stitched.py``."""

from __future__ import annotations

import numpy as np

from synth.gonio import ARCSEC, GonioSpec, drop_out, simulate

N_FACES = 4


def stitched_case(seed: int, with_time: bool = False):
    """One log of 120 revolutions, 0.2-5 rev/s, half on an unsteady table (2 % ripple, 1 %
    wander), autocollimator jitter 0.05-0.4″; returns (spec, twin, stitched, rows lost, first
    row after the gap)."""
    rng = np.random.default_rng(8000 + seed)
    unsteady = rng.random() < 0.5
    spec = GonioSpec(revolutions=120, rev_per_s=float(np.exp(rng.uniform(np.log(0.2),
                                                                            np.log(5.0)))),
                     direction=int(rng.choice([-1, 1])), with_time=with_time,
                     ripple=0.02 if unsteady else 0.0, wander=0.01 if unsteady else 0.0,
                     latency_s=0.0 if unsteady else 5e-6,
                     jitter_rad=float(np.exp(rng.uniform(np.log(0.05), np.log(0.4)))) * ARCSEC,
                     seed=seed)
    twin = simulate(spec)
    rows = len(twin["rows"]["count"])
    k = N_FACES * int(rng.integers(1, 6))
    r0 = int(rng.integers(1, rows - k - 1))
    return spec, twin, drop_out(twin, r0, k), k, r0
