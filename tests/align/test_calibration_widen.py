"""u widened for structure the model cannot explain (issue 19, point 1).

The classes of :mod:`tests.align.effects_cases` with the loop's candidates withheld (the
model lacks the effect, as it would lack any effect nobody wrote): the loop reports
unexplained structure and u must then cover the error of every parameter (|err| / u <= 3);
on clean data nothing is widened. Effects the poses cannot tell apart (aliased on the paper's
14 poses) widen u over the alternatives; the known-pose fit is widened for structure too.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from align.calibration import TriadModel, calibrate, poses_from_samples
from align.calibration.widen import AMBIGUITY, USEFUL_FACTOR
from synth.tumble import TumbleSpec, tumble, write_tumble_csv
from tests.align.effects_cases import EXPECTED, plan28, poses_of, run, sweep, triad_of, truth_at

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


@pytest.mark.parametrize(("name", "seed"), [("cross", 13), ("hysteresis", 8),
                                            ("hysteresis", 12)])
def test_an_aliased_wrong_effect_leaves_no_confident_number(name, seed):
    """Issue 19's seeds on the paper's 14 poses: the loop takes an effect that explains the
    data as well as the true one (a bias drift beat the cross-axis product by 12 in BIC; a
    scale warm-up for the hysteresis) and erred by 173 u and 10.7 u. The poses cannot tell
    them apart (the alternatives reproduce >= 99 % of its signal): u spans the alternatives,
    and the warning says so and what to record."""
    tr = triad_of(name)
    d = tumble(TumbleSpec(triad=tr, seed=seed))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    assert EXPECTED[name] not in [e.name for e in cal.loop.effects]  # the wrong one taken
    o = run(name, seed)
    assert np.abs(o.z).max() <= 3.0
    w = cal.widening.to_dict()["terms"][AMBIGUITY]
    assert "these poses cannot tell" in w and EXPECTED[name] in w and "--plan 28" in w
    assert any("cannot tell" in n for n in cal.notes)


def test_ambiguity_in_the_json_follows_its_schema(tmp_path):
    """``align calibrate --json`` on the cross-axis seed: u_widening names the aliased
    alternatives and validates against the shipped schema; u of bias_y widened x217 by the
    ambiguity: not ok (exit 2), the widened u kept."""
    from align.cli import main
    from align.contract import validate

    p = write_tumble_csv(tumble(TumbleSpec(triad=triad_of("cross"), seed=13)),
                         tmp_path / "t.csv")
    assert main(["calibrate", str(p), "--scale-sign", "-", "--json",
                 str(tmp_path / "c.json")]) == 2
    js = json.loads((tmp_path / "c.json").read_text())
    validate(js, "calibration")
    assert js["ok"] is False and js["warnings"][0].startswith("calibration NOT OK: ")
    assert js["u_widening"]["parameters"]["bias_y"]["factor"] > USEFUL_FACTOR
    alts = js["u_widening"]["alternatives"]
    assert any(a["effects"] == "cross_x_xy" and a["aliased"] and a["explained"] >= 0.99
               for a in alts)
    assert any("cannot tell" in w for w in js["warnings"])


def test_hysteresis_that_the_poses_cannot_tell_apart_is_not_ok(tmp_path):
    """A 50 µg hysteresis on the paper's 14 poses: the loop takes it (seed 0) and cannot
    tell it from a scale warm-up; u of k widened x78 covers both but is no measurement:
    not ok, naming both and the plan; its widened u kept. The same hysteresis on the
    28-pose plan: found, ok."""
    tr = triad_of("hysteresis")
    cal = calibrate(poses_of(tumble(TumbleSpec(triad=tr, seed=0))), np.sign(tr.k))
    assert not cal.ok and len(cal.problems) == 1
    why = cal.problems[0]
    assert "bias_hysteresis and scale_warmup cannot be told apart" in why
    assert "--plan 28" in why
    w = cal.widening
    k = [i for i, n in enumerate(w.names) if n.startswith("scale_factor_")]
    assert np.max(w.factor[k]) > USEFUL_FACTOR  # kept, not cut back
    assert np.allclose(cal.model.sensitivity_u(), w.u[k])
    up = tuple(map(tuple, plan28()))
    cal = calibrate(poses_of(tumble(TumbleSpec(triad=tr, seed=0, up=up))), np.sign(tr.k))
    assert "bias_hysteresis" in [e.name for e in cal.loop.effects] and cal.ok


@pytest.mark.slow
def test_aliasing_is_a_property_of_the_poses():
    """On the 28-pose plan the true effect is found and no alternative is aliased with it
    (the widening for ambiguity stays off) — the 14 poses' aliasing is theirs, not the
    effect's."""
    up = plan28()
    for name in ("cross", "hysteresis"):
        o = run(name, 13 if name == "cross" else 8, up=up)
        assert EXPECTED[name] in o.effects and not o.widened and np.abs(o.z).max() <= 3.0


@pytest.mark.parametrize("name", ["hysteresis", "scale_drift", "scale_warmup"])
def test_known_pose_u_covers_structure(name):
    """The known-pose (six-face) fit gets the same widening: a 50 µg hysteresis put k_y, k_z
    up to 61 u off and a scale drift 10 u, at the noise-only u; now u covers them."""
    z, widened = [], 0
    for seed in range(8):
        tr, p = _six(name, seed)
        cal = calibrate(p, fixture_error_rad=0.0)
        assert cal.method == "known-pose"
        z.append(_z(cal.model, tr))
        widened += cal.widening is not None
    assert widened == 8 and np.abs(z).max() <= 3.0


def test_known_pose_clean_faces_keep_their_u():
    """No structure flag on clean faces (the runs and spectral tests, which took the
    fit's own correlations of 18 components in 6 dof for structure, flagged 9 in 100)."""
    out = []
    for seed in range(8):
        tr, p = _six("clean", seed)
        cal = calibrate(p, fixture_error_rad=0.0)
        out.append((cal.widening is None, np.abs(_z(cal.model, tr)).max()))
    assert all(kept for kept, _ in out) and max(z for _, z in out) < 4


SIX = ("+x", "+y", "+z", "-x", "-y", "-z")  # synth 'six' order


def _six(name: str, seed: int):
    tr = replace(triad_of(name), k=(2.41, 2.40, 2.37))
    d = tumble(TumbleSpec(triad=tr, poses="six", seed=seed, fixture_error_rad=0.0))
    sel = d.pose < d.n_cal
    return tr, poses_from_samples(d.pose[sel], d.u[sel], d.t[sel], SIX)


def _z(m, tr) -> np.ndarray:
    est = np.concatenate([m.sensitivity(), m.beta, m.bias])
    u = np.concatenate([m.sensitivity_u(), [m.u_of(f"{q}_{a}") for q in ("beta", "bias")
                                            for a in "xyz"]])
    return (est - truth_at(tr, m.t_ref)) / u


@pytest.mark.slow
@pytest.mark.parametrize("name", UNKNOWN)
def test_paper_poses_leave_no_confident_number_sweep(name):
    """Every class on the paper's 14 poses, all candidates, 20 seeds: whatever effect the loop
    takes, u covers every parameter (before the aliased alternatives counted: cross-axis
    173 u, hysteresis 10.7 u). Bounds from the noise: 180 values of N(0, 1) exceed 4 with
    probability 1 %; RMS <= 1.25 (u not understated on the whole)."""
    r = sweep(name, range(20))
    assert r["max"] <= 4.0 and r["rms"] <= 1.25, r


@pytest.mark.parametrize(("chosen", "alt"), [((), "nonlinearity_k3"),
                                             (("bias_drift",), ""),
                                             (("bias_drift",), "hysteresis")])
def test_not_ok_message_names_both_sets_even_an_empty_one(chosen, alt):
    """An alternative that moves k_x by 100 x its noise u makes the result not ok; the message
    names both sets, the empty one (the loop added no effect) as the declared model — never a
    blank. Control: an alternative within the noise says nothing."""
    from align.calibration.widen import NO_EFFECT, Alternative, Widening

    names = tuple(f"p{i}" for i in range(12))

    def widening(shift0):
        shift = np.zeros(9)
        shift[0] = shift0
        a = Alternative(alt, "", 1.0, float("nan"), shift, np.zeros((9, 9)))
        return Widening((), names, np.ones(12), (), np.ones(12), (a,))

    why = widening(100.0).undetermined(chosen, 28, "wander")
    assert why is not None and ":  and" not in why and " and  cannot" not in why
    first, second = why.removeprefix("calibration NOT OK: ").split(" cannot be told apart")[0] \
        .split(" and ", 1)
    assert first == (" + ".join(chosen) or NO_EFFECT) and second == (alt or NO_EFFECT)
    assert widening(0.5).undetermined(chosen, 28, "wander") is None
