"""A declared Earth rate checked against the one the log shows (align/gonio_earth.py): a
latitude of the wrong sign or the wrong --direction on a wandering table is warned and
covered by u; the right declaration leaves the angles and warnings as they were."""

from __future__ import annotations

import numpy as np
import pytest

from align.gonio import measure_log
from axisbase.units import DEG
from synth.gonio import GonioSpec, simulate, write_log
from tests.align.test_independent_gonio_user import HEADER, make_log, rows_of, write

TOL = 3.5
# 0.2 rev/s with a 20 % wander: the periods vary enough for the counts to pin the rate.
WANDER = dict(revolutions=300, rev_per_s=0.2, wander=0.2, ripple=0.05, latency_s=0.0)


def _run(tmp_path, seed, latitude_deg, direction, declared_direction=None):
    sim = simulate(GonioSpec(**WANDER, direction=direction, seed=seed))
    p = write_log(sim, tmp_path / f"{seed}.csv")
    run = measure_log(p, 4, latitude_deg * DEG, direction=declared_direction or direction)
    z = (run.angles.angles_rad - np.array(sim["truth"]["angles_rad"])) / run.angles.u_rad
    return run, z


@pytest.mark.parametrize("seed", [0, 1])
def test_latitude_of_the_wrong_sign_is_warned_and_covered(tmp_path, seed):
    run, z = _run(tmp_path, seed, -50.45, 1)
    assert any("--latitude" in w and "latitude_deg" in w for w in run.warnings), run.warnings
    assert np.all(np.abs(z) < TOL), z


def test_wrong_direction_is_warned_and_covered(tmp_path):
    run, z = _run(tmp_path, 2, 50.45, -1, declared_direction=1)
    assert any("--direction" in w for w in run.warnings), run.warnings
    assert np.all(np.abs(z) < TOL), z


@pytest.mark.parametrize("seed", [3, 4])
def test_right_declaration_is_not_warned(tmp_path, seed):
    run, z = _run(tmp_path, seed, 50.45, 1)
    assert not any("Earth rate this log shows" in w for w in run.warnings), run.warnings
    assert np.all(np.abs(z) < TOL), z


@pytest.mark.slow
def test_false_alarms_of_the_declared_rate_check(tmp_path):
    """Over 40 clean seeds (right latitude, either direction) the check warns at most at its
    alpha (1e-3): none expected; 2 allowed for the estimate's own non-normality."""
    alarms = 0
    for seed in range(40):
        run, _ = _run(tmp_path, 100 + seed, 50.45, 1 if seed % 2 else -1)
        alarms += any("Earth rate this log shows" in w for w in run.warnings)
    assert alarms <= 2


def test_a_steady_table_pins_no_rate_and_raises_no_alarm(tmp_path):
    # At constant speed the periods differ by pulse jitter only: the largest Earth rate
    # moves no count over their spread, so the log shows no rate to check a latitude
    # against (the fit on them returned 15 rad/s at u 1e-14 on this independent user's
    # clean log: a false warning and a Type B term).
    c, k, r, t, _ = make_log(3, revs=300, jitter_arcsec=0.05, latitude=45.0)
    path = write(tmp_path / "steady.csv", "\n".join([HEADER, *rows_of(c, k, r, t)]) + "\n")
    run = measure_log(path, 4, latitude_rad=45 * DEG)
    assert not [w for w in run.warnings if "Earth rate this log shows" in w], run.warnings
