"""The one-direction latency warning (:mod:`align.gonio_timing`): said when the table's speed
varies with its angle, not when a locked ring laser's own count floors are all that makes
the pulse-time and count fractions differ."""

from __future__ import annotations

import numpy as np
import pytest

from align import measure_log
from align.gonio_timing import LATENCY
from axisbase.units import DEG
from synth.gonio import ARCSEC, OMEGA_EARTH, GonioSpec, simulate, write_log

LAT = 50.45
# 100 000 counts a revolution, the Earth's share included: the floors lock (same phase every
# revolution), so each angle keeps up to one count (13″) of error for good
K_LOCKED = 1e5 / (1 + OMEGA_EARTH * np.sin(np.radians(LAT)) / (2 * np.pi))


def warned(tmp_path, seed: int, **kw) -> bool:
    spec = GonioSpec(revolutions=60, latitude_deg=LAT, jitter_rad=0.05 * ARCSEC, seed=seed,
                     **kw)
    path = write_log(simulate(spec), tmp_path / f"g{seed}-{len(list(tmp_path.iterdir()))}.csv")
    run = measure_log(path, 4, LAT * DEG)
    return any(w.startswith(LATENCY) for w in run.warnings)


@pytest.mark.parametrize("seed", range(3))
def test_a_locked_ring_laser_on_a_steady_table_is_not_called_unsteady(seed, tmp_path):
    """Locked counts, constant speed: no latency warning (before: 'speed varies with its
    angle', p 0, on every seed)."""
    assert not warned(tmp_path, seed, k_per_rev=K_LOCKED)


@pytest.mark.parametrize("seed", range(2))
def test_a_rippling_table_is_still_called_unsteady(seed, tmp_path):
    """Controls: a 1 % locked speed ripple is warned of with the locked ring laser and with
    the default (dithered) one alike."""
    assert warned(tmp_path, seed, k_per_rev=K_LOCKED, ripple=0.01)
    assert warned(tmp_path, seed, ripple=0.01)
