"""A bias that random-walks (a bias instability every triad has) is not turned into a
confident effect (issue 19; align/calibration/walk.py).

Rendered by :func:`synth.tumble.bias_walk` (a Wiener bias going on while the unit is turned,
10 s dwell at 20 Hz, 5 s turns, the paper's 14 poses): at 1e-6 g/√s (14 µg over the 210 s
run, 3 µg within a pose) the samples within the poses do not show the walk and the loop
takes a drift, K2 or nothing; u then covers the wander the samples allow. At 3e-6 g/√s and
above they show it, and it enters the noise model.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from align.calibration import calibrate
from align.calibration.walk import WALK_ALPHA, walk_estimate
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import poses_of, triad_of, truth_at


def _walk_triad(level: float, name: str = "clean"):
    return replace(triad_of(name), bias_walk_g=(level,) * 3)


def _z(level: float, seed: int, name: str = "clean", up=None) -> tuple[np.ndarray, object]:
    """(k, beta) normalised errors; the walk leaves them alone (the biases are its)."""
    tr = _walk_triad(level, name)
    d = tumble(TumbleSpec(triad=tr, seed=seed, up=up))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    m = cal.model
    truth = truth_at(tr, m.t_ref)
    z = np.r_[(m.sensitivity() - truth[:3]) / m.sensitivity_u(),
              (m.beta - truth[3:6]) / m.u_per_axis("beta")]
    return z, cal


def _samples(d):
    sel = d.pose < d.n_cal
    return ([d.u[sel][d.pose[sel] == i] for i in range(d.n_cal)],
            [d.t[sel][d.pose[sel] == i] for i in range(d.n_cal)])


def test_walk_level_is_measured_within_the_poses():
    """3e-6 g/√s: shown (p < WALK_ALPHA) and each axis's rate [g²/s] within 4 of its standard
    deviations of the truth, over 4 seeds; clean: not shown over 20 seeds (α = 1e-3)."""
    for s in range(4):
        tr = _walk_triad(3e-6)
        rate, sd, p = walk_estimate(*_samples(tumble(TumbleSpec(triad=tr, seed=s))))
        k2 = np.asarray(tr.k) ** 2
        assert p < WALK_ALPHA
        assert np.all(np.abs(rate / k2 - 9e-12) < 4 * sd / k2), (rate / k2, sd / k2)
    shown = [walk_estimate(*_samples(tumble(TumbleSpec(triad=triad_of("clean"), seed=s))))[2]
             < WALK_ALPHA for s in range(20)]
    assert not any(shown)


@pytest.mark.parametrize("level", [1e-6, 3e-6])
def test_bias_walk_is_not_turned_into_a_confident_effect(level):
    """Two seeds each (12 normalised errors): |z| < 3.5 (measured over 10 seeds: max 1.73 at
    1e-6 g/√s, 2.30 at 3e-6; before: 13.3 and 2.6 with K2, drifts taken at 1e-6)."""
    for s in (0, 1):
        z, cal = _z(level, s)
        assert np.abs(z).max() < 3.5, (s, z, [e.name for e in cal.loop.effects])


@pytest.mark.slow
@pytest.mark.parametrize("level", [1e-6, 3e-6, 1e-5])
def test_bias_walk_sweep(level):
    """20 seeds per level, 120 normalised errors of (k, beta): max < 4, RMS < 1.3 (1e-6, seed
    109 took cross_z_xy with k_x 10.2 u off before the wander was weighed against every
    effect)."""
    z = np.concatenate([_z(level, s)[0] for s in range(100, 120)])
    assert np.abs(z).max() < 4.0 and np.sqrt(np.mean(z ** 2)) < 1.3, z
