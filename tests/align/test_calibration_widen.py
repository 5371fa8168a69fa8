"""u widened for structure the model cannot explain (issue 19, point 1).

The classes of :mod:`tests.align.effects_cases` with the loop's candidates withheld (the
model lacks the effect, as it would lack any effect nobody wrote): the loop reports
unexplained structure and u must then cover the error of every parameter (|err| / u <= 3);
on clean data nothing is widened.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration import TriadModel, calibrate
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import poses_of, run, sweep, triad_of

UNKNOWN = ("cross", "hysteresis", "scale_drift", "scale_warmup")


@pytest.mark.parametrize("name", UNKNOWN)
def test_u_covers_an_effect_the_model_lacks(name):
    r = sweep(name, range(8), candidates=())
    assert r["structure"] == 1.0 and r["widened"] == 1.0
    # |err|/u <= 3 for every parameter and seed (widened by 8-100x: without the widening
    # the same errors are 25-900 u, see docs/calibration-effects.md).
    assert r["max"] <= 3.0


def test_clean_data_are_not_widened():
    out = [run("clean", s, candidates=()) for s in range(20)]
    assert sum(o.widened for o in out) <= 1
    z = np.array([o.z for o in out if not o.widened])
    # The noise-only u stays right: normalised errors ~N(0,1) (RMS within its 5-sigma band
    # for ~180 values: 1 +- 5 * 0.053).
    assert abs(np.sqrt(np.mean(z**2)) - 1) < 0.27


def test_widening_is_stated_and_carried_into_the_model_file():
    tr = triad_of("hysteresis")
    p = poses_of(tumble(TumbleSpec(triad=tr, seed=3)))
    cal = calibrate(p, np.sign(tr.k), candidates=())
    w = cal.widening
    assert w is not None and cal.loop.unexplained_structure
    assert any(n.startswith("calibration: u widened") for n in cal.notes)
    js = cal.to_dict(p)
    par = js["u_widening"]["parameters"]
    assert set(par) >= {"k_x", "beta_y", "bias_z", "scale_factor_x"}
    assert all(v["u"] >= v["u_noise"] and v["factor"] >= 1 for v in par.values())
    # The model block (what 'align apply' and the fusion read) carries the widened covariance.
    m = TriadModel.from_dict(js["model"])
    assert np.allclose([m.u_of(f"bias_{a}") for a in "xyz"],
                       [par[f"bias_{a}"]["u"] for a in "xyz"])
    assert js["bias_u_g"] == [par[f"bias_{a}"]["u"] for a in "xyz"]


@pytest.mark.slow
@pytest.mark.parametrize("name", UNKNOWN)
def test_u_covers_an_effect_the_model_lacks_sweep(name):
    r = sweep(name, range(100, 150), candidates=())
    assert r["widened"] >= 0.98 and r["max"] <= 3.0
