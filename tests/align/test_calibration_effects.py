"""The effects real accelerometers have, as loop candidates (issue 19, point 2), and the pose
plan that makes them identifiable (point 3).

Classes from :mod:`tests.align.effects_cases` (each effect rendered by synth in the sensor's
physics). On the 28-pose plan each is found and the normalised errors are ~N(0,1); on the
paper's 14 poses the effects alias each other and u is widened for the ambiguity; clean data
get no effect.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration import calibrate, delta_g
from align.calibration.model import (
    ASYMMETRY,
    HYSTERESIS,
    NONLIN,
    SCALE_DRIFT,
    CalibrationStage,
)
from align.calibration.plan import identifiability, paper14, plan
from axisbase.errors import InputError
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import plan28, poses_of, sweep, triad_of

PLAN = plan28()
FAST = ("cross", "hysteresis", "scale_drift")


def test_stage_residual_is_the_model():
    """The stage's written-out inverse model agrees with TriadModel.specific_force."""
    tr = triad_of("scale_drift")
    p = poses_of(tumble(TumbleSpec(triad=tr, seed=1, temp_rate_k_per_s=0.01,
                                   up=tuple(map(tuple, PLAN)))))
    p = type(p)(p.u, p.t, p.t * 0.01, p.sigma_u, p.count, p.labels)
    st = CalibrationStage(p, np.sign(tr.k))
    for effects in (["nonlinearity_k2", "cross_y_xz"], ["scale_drift", "bias_warmup"],
                    ["scale_temperature", "bias_temperature"], ["scale_warmup"],
                    ["nonlinearity_k3", "scale_asymmetry"]):
        m, r, _ = st.refine(effects)
        assert np.allclose(r, delta_g(m, p), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", FAST)
def test_each_effect_found_on_the_plan(name):
    r = sweep(name, range(1), up=PLAN)
    assert r["found"] == 1.0 and r["widened"] == 0.0
    # 9 parameters: |z| max within the N(0,1) range for 9 draws (the sweep below: 20 seeds).
    assert r["max"] < 3.5


def test_cubic_nonlinearity_found_on_the_plan():
    """K3 = ±100 µg/g³ (user8's case, rendered by synth in the sensor): on the plan's edges
    and corners x³ differs from x, K3 is found and k is the linear coefficient within u."""
    r = sweep("k3", range(1), up=PLAN)
    assert r["found"] == 1.0 and r["widened"] == 0.0 and r["max"] < 3.5


def test_scale_asymmetry_found_on_the_plan():
    """A ±300 ppm asymmetry (k+ != k-): found; on these poses K2 reproduces 99.9 % of its
    signal (|x| and x² meet at 0 and ±1 g), so u covers the two (biases' u widened) and
    every parameter lies within it."""
    tr = triad_of("asymmetry")
    cal = calibrate(poses_of(tumble(TumbleSpec(triad=tr, seed=0, up=tuple(map(tuple, PLAN))))),
                    np.sign(tr.k))
    assert [e.name for e in cal.loop.effects] == [ASYMMETRY]
    # Decided (it was "no widening, or one by K2"): u is widened for K2, the one alternative.
    assert cal.widening is not None
    assert {a.effects for a in cal.widening.alternatives} == {NONLIN}
    assert np.all(np.abs(cal.model.asymmetry - tr.asymmetry) < 3.5 * np.array(
        [cal.model.u_of(f"{ASYMMETRY}_{a}") for a in "xyz"]))
    assert sweep("asymmetry", range(1), up=PLAN)["max"] < 3.5


def test_clean_plan_gets_no_effect():
    r = sweep("clean", range(4), up=PLAN)
    assert r["any_effect"] == 0.0 and r["structure"] == 0.0 and r["max"] < 4


def test_hysteresis_needs_the_pose_order():
    tr = triad_of("hysteresis")
    p = poses_of(tumble(TumbleSpec(triad=tr, seed=2, up=tuple(map(tuple, PLAN)))))
    ordered = calibrate(p, np.sign(tr.k))
    assert [e.name for e in ordered.loop.effects] == [HYSTERESIS]
    unordered = type(p)(p.u, p.t, None, p.sigma_u, p.count, p.labels, ordered=False)
    cal = calibrate(unordered, np.sign(tr.k))
    assert HYSTERESIS not in [e.name for e in cal.loop.effects]
    # Without it the model lacks the effect: structure or widening says so.
    assert cal.widening is not None


def test_the_plan_makes_the_effects_identifiable():
    mine, paper = identifiability(PLAN), identifiability(paper14())
    assert all(v["pair_condition"] < 100 for v in mine.values())
    # The paper's 14 poses: K2, drifts and hysteresis are one column with another effect.
    assert min(paper[e]["pair_condition"] for e in (SCALE_DRIFT, HYSTERESIS)) > 1e8
    with pytest.raises(InputError, match="at least 28 poses"):
        plan(20)


def test_plan_cli(capsys):
    from align.commands.main import main

    assert main(["calibrate", "--plan", "28"]) == 0
    out = capsys.readouterr().out
    assert out.count("°") >= 27 and "paper 14 poses" in out


@pytest.mark.slow
@pytest.mark.parametrize("name", [*FAST, "scale_warmup"])
def test_each_effect_found_on_the_plan_sweep(name):
    r = sweep(name, range(100, 120), up=PLAN)
    assert r["found"] >= 0.95 and r["max"] < 4.5 and 0.8 < r["rms"] < 1.25


@pytest.mark.slow
@pytest.mark.parametrize("name", ["k3", "asymmetry"])
@pytest.mark.parametrize("where", ["plan28", "cube24"])
def test_k3_and_asymmetry_sweep(name, where):
    """20 seeds: found in >= 95 %, every parameter within 3.5 u (180 draws of N(0,1): the max
    exceeds 3.5 with p 0.08, 4 with p 0.01) and the RMS of z at most 1.25 (below 1 where u
    is widened for the K2 alias)."""
    kw = {"up": PLAN} if where == "plan28" else {"poses": where}
    r = sweep(name, range(300, 320), **kw)
    assert r["found"] >= 0.95 and r["max"] < 4.0 and r["rms"] < 1.25, r


@pytest.mark.slow
def test_false_effects_on_clean_data_sweep():
    """False effects over 100 clean seeds, on the plan and on the paper's 14 poses: measured
    1 % on each (benchmarks/calibration_effects.py, seeds 0-99). A true rate of 1 % gives at
    most 3 in 100 in 98 % of runs: more is a real rise, not the draw."""
    plan_r = sweep("clean", range(200, 300), up=PLAN)
    paper_r = sweep("clean", range(200, 300))
    assert plan_r["any_effect"] <= 0.03 and paper_r["any_effect"] <= 0.03


def _tempco_poses(tempco: float, seed: int = 0):
    """The 28-pose plan, 40 samples a pose, an orthogonal triad whose scale factors follow
    the temperature by ``tempco`` [1/K] (x, -0.7 on y, 0.8 on z) through a ±5 K room cycle
    logged with the poses; returns (poses, k [V/g], T0 [K], tempco per axis)."""
    from dataclasses import replace

    from align.calibration import poses_from_samples

    rng = np.random.default_rng(seed)
    k, o = np.array([2.0, -1.5, 1.8]), np.array([2e-3, -1e-3, 3e-3])
    c = tempco * np.array([1.0, -0.7, 0.8])
    n, t0 = len(PLAN), 298.0
    temp = t0 + 5.0 * np.sin(2 * np.pi * (np.arange(n) + 0.5) / n)
    pid = np.repeat(np.arange(n), 40)
    gain = k * (1 + c * (temp - t0)[:, None])                       # (n, 3)
    u = (PLAN * gain + o)[pid] + rng.normal(0, 2e-5, (len(pid), 3))
    p = poses_from_samples(pid, u, pid * 10.0)
    return replace(p, temp=temp), k, t0, c


@pytest.mark.parametrize(("tempco", "fitted"), [(0.0, False), (300e-6, True), (500e-6, True),
                                                (3e-3, False)])
def test_scale_tempco_prior_is_a_tempco_bound(tempco, fitted):
    """The scale factor's temperature term is bounded by a tempco (SCALE_TEMPCO_PRIOR_PER_K,
    1000 ppm/K, times the poses' temperature span), not a fixed reach: the BMI160's 300 ppm/K
    and 500 ppm/K over 10 K (3e-3 and 5e-3 at 1 g; the old fixed 3e-3 g refused the latter)
    are fitted, k within 4 u of the truth at the reference temperature; 3000 ppm/K (3 x the
    bound) is refused as outside the physical prior; clean data (the control) get no
    effect."""
    from align.calibration.model import SCALE_TEMP, SCALE_TEMPCO_PRIOR_PER_K, prior_bound

    assert prior_bound(SCALE_TEMP, None, 10.0) == pytest.approx(10 * SCALE_TEMPCO_PRIOR_PER_K)
    p, k, t0, c = _tempco_poses(tempco)
    cal = calibrate(p, np.sign(k))
    m = cal.model
    names = [e.name for e in cal.loop.effects]
    assert (SCALE_TEMP in names) is fitted, (names, [r.to_dict() for r in
                                                     cal.loop.refused])
    if tempco == 0.0:
        assert names == [] and cal.ok
    elif fitted:
        z = (m.sensitivity() - k * (1 + c * (m.temp_ref - t0))) / m.sensitivity_u()
        assert cal.ok and np.all(np.abs(z) < 4), z
    else:
        why = [r.to_dict() for r in cal.loop.refused]
        assert any("outside the physical prior" in str(r) and SCALE_TEMP in str(r)
                   for r in why), why
