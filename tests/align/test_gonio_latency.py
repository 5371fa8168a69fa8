"""Two directions at different speeds (align/gonio_latency.py): the latency's bias scales with
the speed, so the plain mean leaves part of it; the model fitted from both runs' own speed
profiles removes it. A real reverse run with a large latency is accepted; the plain mean is
kept where the speeds agree."""

from __future__ import annotations

import numpy as np
import pytest

from align.gonio import measure_log
from align.gonio_directions import combine_directions
from axisbase.units import DEG
from synth.gonio import GonioSpec, simulate, write_log

TOL = 3.5
BASE = dict(revolutions=120, ripple=0.1, wander=0.02)


def _pair(tmp_path, seed, fwd_speed, rev_speed, latency_s):
    f = simulate(GonioSpec(**BASE, rev_per_s=fwd_speed, latency_s=latency_s, seed=seed))
    r = simulate(GonioSpec(**BASE, rev_per_s=rev_speed, latency_s=latency_s, direction=-1,
                           seed=seed + 1000))
    pf = write_log(f, tmp_path / f"f{seed}.csv")
    pr = write_log(r, tmp_path / f"r{seed}.csv")
    return pf, pr, np.array(f["truth"]["angles_rad"])


@pytest.mark.parametrize("latitude", [50.45 * DEG, None])
@pytest.mark.parametrize("seed", [0, 1])
def test_reverse_at_another_speed_is_modelled(tmp_path, seed, latitude):
    """0.5 and 0.2 rev/s, 100 µs: the plain mean is many u off; the model's within TOL."""
    pf, pr, truth = _pair(tmp_path, seed, 0.5, 0.2, 1e-4)
    run = measure_log(pf, 4, latitude, reverse_log=pr)
    fwd = measure_log(pf, 4, latitude, apply_loop=False)
    rev = measure_log(pr, 4, latitude, direction=-1, apply_loop=False)
    plain, _ = combine_directions(fwd.angles, rev.angles)
    assert np.max(np.abs(plain.angles_rad - truth) / plain.u_rad) > TOL  # the effect is there
    z = (run.angles.angles_rad - truth) / run.angles.u_rad
    assert np.all(np.abs(z) < TOL), z
    assert any("reverse run at 0.4" in n for n in run.notes), run.notes


@pytest.mark.parametrize("seed", [3, 5])
def test_a_real_reverse_with_a_large_latency_is_accepted(tmp_path, seed):
    """Same speed, 10 % ripple: 300 µs leaves 25″ of direction-dependent part (beyond the
    old fixed 10″ limit), all explained by the latency times the measured speeds: accepted,
    the mean within TOL."""
    pf, pr, truth = _pair(tmp_path, seed, 0.5, 0.5, 3e-4)
    run = measure_log(pf, 4, 50.45 * DEG, reverse_log=pr)
    assert np.max(np.abs(run.direction.half_difference_rad)) > 10 * np.pi / 180 / 3600
    z = (run.angles.angles_rad - truth) / run.angles.u_rad
    assert np.all(np.abs(z) < TOL), z


def test_equal_speeds_keep_the_plain_mean(tmp_path):
    """The control: both runs at 0.5 rev/s, 5 µs: no model note, no warning, the angles
    within a fraction of u of the plain mean, u as small."""
    pf, pr, truth = _pair(tmp_path, 4, 0.5, 0.5, 5e-6)
    run = measure_log(pf, 4, 50.45 * DEG, reverse_log=pr)
    fwd = measure_log(pf, 4, 50.45 * DEG, apply_loop=False)
    rev = measure_log(pr, 4, 50.45 * DEG, direction=-1, apply_loop=False)
    plain, _ = combine_directions(fwd.angles, rev.angles)
    assert not any("reverse run at" in n for n in run.notes), run.notes
    assert np.all(np.abs(run.angles.angles_rad - plain.angles_rad) < 0.5 * plain.u_rad)
    assert np.all(run.angles.u_rad < 1.05 * plain.u_rad)
    assert not run.warnings, run.warnings
