"""The stated u against a counter-log simulator written independently of synth/ (its own
ring laser, table dynamics, jitter and 10 MHz stamps): random runs over what a user brings —
60-2000 revolutions, 0.3-5 rev/s, steady or unsteady table, jitter 0.02-3″, armed on any face,
stopped anywhere, any latitude (given)."""

from __future__ import annotations

import numpy as np
import pytest

from align.gonio import measure_log
from axisbase.units import DEG
from tests.goniometry.independent_log import independent_log


@pytest.mark.slow
def test_normalised_errors_over_random_independent_logs(tmp_path):
    rng = np.random.default_rng(20261124)
    z, methods = [], []
    for i in range(120):
        revs = int(rng.choice([60, 120, 300, 1000, 2000]))
        rate = float(np.exp(rng.uniform(np.log(0.3), np.log(5))))
        rate = max(rate, revs / 1000)  # (the simulator integrates the table at 2 ms steps)
        unsteady = rng.random() < 0.5
        lat = float(rng.uniform(-70, 70))
        p = tmp_path / f"l{i}.csv"
        truth = independent_log(p, revs, rate, 0.016 if unsteady else 0.0,
                                0.004 if unsteady else 0.0, lat, int(rng.integers(1 << 30)),
                                jitter_arcsec=float(np.exp(rng.uniform(np.log(0.02),
                                                                       np.log(3)))),
                                arm_face=int(rng.integers(4)),
                                stop_pulses=int(rng.integers(4)))
        run = measure_log(p, 4, lat * DEG)
        z.extend((run.angles.angles_rad - truth) / run.angles.u_rad)
        methods.append(run.angles.type_a_method)
        p.unlink()
    z = np.array(z)
    rms = float(np.sqrt(np.mean(z**2)))
    print(f"RMS z {rms:.3f}, max |z| {np.abs(z).max():.2f} over {z.size} angles; methods "
          f"{ {m: methods.count(m) for m in set(methods)} }")
    # 480 angles (4 per log, tied by the closure: ~360 independent): an honest u gives an RMS
    # within ~1 +- 3/sqrt(2 x 360) = 0.89..1.11; u may be conservative by its stated margins
    # (the jitter taken at the high end of its interval), not by more than a quarter.
    assert 0.75 < rms < 1.11
    # Gaussian errors: |z| > 4 in 480 angles has a 3 % chance.
    assert np.abs(z).max() < 4.0
