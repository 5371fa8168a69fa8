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


def _stepped_poses(seed: int, step_g: float, pose: int = 7, at: int = 7):
    """14 poses (the cube's faces and corners, k = 1) of 200 samples at 20 Hz with 20 µg of
    white noise, 5 s turns; the x bias steps by ``step_g`` at sample ``at`` of ``pose``."""
    rng = np.random.default_rng(seed)
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
                    + [[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)], float)
    samples, times = [], []
    for p, d in enumerate(dirs):
        x = d / np.linalg.norm(d) + rng.normal(0, 2e-5, (200, 3))
        x[:, 0] += step_g * ((p > pose) | ((p == pose) & (np.arange(200) >= at)))
        samples.append(x)
        times.append(15.0 * p + np.arange(200) / 20.0)
    return samples, times


def test_a_step_within_one_pose_is_not_a_walk():
    """User 17's 2 mg bias step inside pose 7: that pose alone is beyond the others' low
    frequencies (left out of the walk's level, which is then none), the step located at its
    sample and size (within 3 of its u), and a bias u below the step makes the result not
    ok; the same step on a face across gravity is also a tilt (not judged); no step: none."""
    from align.calibration.steps import pose_steps, step_problem
    from align.calibration.walk import walk_levels, walk_outliers

    samples, times = _stepped_poses(0, 2e-3)
    assert walk_outliers(samples, times) == (7,)
    assert walk_levels(samples, times, (7,))[0] is None
    assert walk_levels(samples, times)[0] is not None  # (the step taken for a walk before)
    (s,) = pose_steps(samples, times, [str(i) for i in range(14)])
    assert abs(s.t_s - times[7][7]) < 0.05
    assert abs(s.size[0] - 2e-3) < 3 * s.size_u[0]
    (why,) = step_problem([s], np.ones(3), np.diag(np.full(9, 1e-8)))
    assert "x bias stepped by +" in why and "pose 7" in why
    assert step_problem([s], np.ones(3), np.diag(np.full(9, 9e-6))) == ()  # within u: one bias
    (s2,) = pose_steps(*_stepped_poses(0, 2e-3, pose=2), [str(i) for i in range(14)])
    assert s2.pose == 2 and step_problem([s2], np.ones(3), np.diag(np.full(9, 1e-8))) == ()
    assert walk_outliers(*_stepped_poses(0, 0.0)) == ()


@pytest.mark.slow
def test_no_pose_is_a_step_in_walking_tumbles():
    """synth tumbles, clean and walking at 1e-6, 3e-6, 1e-5 g/√s, 10 seeds each: no pose is
    beyond the others' low frequencies (0 of 40 seeds each; Satterthwaite's dof flagged 3 of
    40 at 1e-5)."""
    from align.calibration.walk import walk_outliers

    for level in (0.0, 1e-6, 3e-6, 1e-5):
        for s in range(10):
            tr = _walk_triad(level) if level else triad_of("clean")
            assert walk_outliers(*_samples(tumble(TumbleSpec(triad=tr, seed=s)))) == (), (level, s)
