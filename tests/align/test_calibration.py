"""Calibration against synth truth: the paper's fit, ML refinement, the loop, bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from align.calibration import (
    DRIFT,
    NONLIN,
    Poses,
    StaticSettings,
    algebraic,
    calibrate,
    delta_g,
    find_static,
    poses_from_samples,
    read_poses,
)
from align.calibration.model import ASYMMETRY
from align.calibration.walk import WANDER
from align.errors import InputError
from synth.tumble import Triad, TumbleSpec, fisher_crlb, recording, tumble, write_tumble_csv

NOISE_V = 4.8e-5  # per sample: 2e-5 g; 200 samples a pose -> 1.4 µg per pose mean


def poses_of(d, check=False) -> Poses:
    """Calibration (or check) poses of a synthetic tumble as per-pose means."""
    sel = (d.pose >= d.n_cal) if check else (d.pose < d.n_cal)
    return poses_from_samples(d.pose[sel], d.u[sel], d.t[sel])


def test_algebraic_fit_is_exact_on_noise_free_data():
    tr = Triad(noise_v=0.0)
    d = tumble(TumbleSpec(triad=tr, fixture_error_rad=0.02, seed=1))
    m = algebraic(poses_of(d), np.sign(tr.k))
    assert np.allclose(m.k, tr.k, rtol=0, atol=1e-12)
    assert np.allclose(m.beta, tr.beta, rtol=0, atol=1e-12)
    assert np.allclose(m.bias, tr.bias, rtol=0, atol=1e-12)


def test_table1_recovered_within_stated_uncertainty():
    tr = Triad(noise_v=NOISE_V)
    d = tumble(TumbleSpec(triad=tr, seed=5))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    m = cal.model
    truth = np.concatenate([tr.k, tr.beta, tr.bias])
    est = np.concatenate([m.k, m.beta, m.bias])
    u = np.sqrt(np.diag(m.cov))[:9]
    assert np.all(np.abs(est - truth) < 4.5 * u)
    assert not cal.loop.effects and not cal.loop.unexplained_structure
    # The paper's check poses: |Δg| at its 3e-5 g level or better.
    assert np.max(np.abs(delta_g(m, poses_of(d, True)))) < 3e-5
    # The stated uncertainty is the Cramér–Rao bound (within 20 %), not an arbitrary number.
    crlb = np.sqrt(np.diag(fisher_crlb(tr, d.up[:d.n_cal], NOISE_V / np.sqrt(200))))
    assert np.all(np.abs(u / crlb - 1) < 0.2)


@pytest.mark.parametrize("k2, alternatives", [((40e-6, 0.0, -30e-6), None),
                                               ((0.0, 25e-6, 0.0), {WANDER, ASYMMETRY})])
def test_undeclared_nonlinearity_found_and_removed(k2, alternatives):
    tr = Triad(noise_v=NOISE_V, k2=k2)
    # 24 poses: on the paper's 14 a K2 and a cross-axis product or a drifting scale factor
    # explain the data alike (the calibration then widens u for the ambiguity, see
    # test_calibration_effects.py); the edges' poses tell them apart.
    d = tumble(TumbleSpec(triad=tr, poses="cube24", seed=7))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    assert [e.name for e in cal.loop.effects] == [NONLIN]
    # Each attitude held once, in one order: a bias wander at a level the samples within
    # the poses allow explains K2's signal too (25e-6 on y: bias_y's u x12.8); no other
    # effect is an alternative but a scale-factor asymmetry (x + A |x|: |x| and x² differ
    # only at the edges' 0.707, a near-alias the loop refuses in K2's favour and the
    # widening weighs). (The plan's repeated attitudes exclude the wander.)
    # Decided (it was "none, or some of these two"): x and z's K2 is told apart (no
    # alternative: u carries only the K3 these poses do not exclude, k3_not_excluded,
    # test_calibration_nonlinearity.py); y's 25e-6 has both alternatives.
    found = {a.effects for a in cal.widening.alternatives} if cal.widening else set()
    assert (found or None) == alternatives
    assert np.all(np.abs(cal.model.k2 - k2) < 4.5 * np.array(
        [cal.model.u_of(f"{NONLIN}_{a}") for a in "xyz"]))
    before = np.abs(cal.algebraic.bias - tr.bias)
    after = np.abs(cal.model.bias - tr.bias)
    u = np.array([cal.model.u_of(f"bias_{a}") for a in "xyz"])
    u0 = u if cal.widening is None else np.array(  # the noise's u: what K2 left alone costs
        [cal.widening.u_noise[cal.widening.names.index(f"bias_{a}")] for a in "xyz"])
    assert np.all(after < 4.5 * u) and np.max(before / u0) > 8
    dg_after = np.abs(delta_g(cal.model, poses_of(d, True)))
    # Per check pose: 1.4 µg of mean noise and ~1.5 µg from the parameters -> ~2 µg. (On 24
    # poses the algebraic fit's check poses are at that level too: the gain is in the biases.)
    assert dg_after.max() < 4.5 * 2e-6


def test_undeclared_bias_drift_found():
    drift = np.array([4e-8, -2e-8, 5e-8])
    tr = Triad(noise_v=NOISE_V, drift=tuple(drift))
    d = tumble(TumbleSpec(triad=tr, poses="cube24", seed=2))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    assert [e.name for e in cal.loop.effects] == [DRIFT]
    u = np.array([cal.model.u_of(f"{DRIFT}_{a}") for a in "xyz"])
    assert np.all(np.abs(cal.model.drift - drift) < 4.5 * u)
    # bias_g is the value at the mean sample time of the session.
    bias_mid = np.asarray(tr.bias) + drift * d.t[d.pose < d.n_cal].mean()
    ub = np.array([cal.model.u_of(f"bias_{a}") for a in "xyz"])
    assert np.all(np.abs(cal.model.bias - bias_mid) < 4.5 * ub)


@pytest.mark.parametrize("n", [10, pytest.param(50, marks=pytest.mark.slow)])
def test_no_false_effects_over_fifty_clean_datasets(n):
    # (17 candidates since issue 19: ~0.3 s a calibration, the 50 datasets are a slow test)
    false = 0
    for seed in range(n):
        tr = Triad(noise_v=NOISE_V)
        d = tumble(TumbleSpec(triad=tr, seed=100 + seed))
        cal = calibrate(poses_of(d), np.sign(tr.k))
        false += bool(cal.loop.effects) or cal.loop.unexplained_structure
    assert false <= 1


def test_static_intervals_found_in_a_recording():
    spec = TumbleSpec(triad=Triad(noise_v=NOISE_V), rate_hz=100.0, dwell_s=6.0, move_s=3.0,
                      seed=4)
    t, u, truth = recording(spec)
    found = find_static(t, u, StaticSettings())
    assert len(found) == len(truth)
    st = StaticSettings()
    for iv, (a, b) in zip(found, truth, strict=True):
        # Inside the true interval, shortened by the margins and at most a window per end.
        assert a - 0.05 <= iv.start_s and iv.end_s <= b + 0.05
        assert iv.duration_s > (b - a) - 2 * st.margin_s - 2 * st.window_s


def test_files_round_trip_and_bad_input(tmp_path):
    tr = Triad(noise_v=NOISE_V)
    d = tumble(TumbleSpec(triad=tr, seed=9))
    p = write_tumble_csv(d, tmp_path / "s.csv")
    poses, _ = read_poses(p)
    assert len(poses.u) == 14 and poses.sigma_u is not None
    lines = p.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines[:5] + [lines[5].replace(lines[5].split(",")[1], "abc")]
                             + lines[6:]))
    with pytest.raises(InputError, match=r"bad.csv:6: ux: 'abc' is not a number"):
        read_poses(bad)
    trunc = tmp_path / "trunc.csv"
    trunc.write_text("\n".join(lines[:-1] + [lines[-1][:10]]))
    with pytest.raises(InputError, match="truncated"):
        read_poses(trunc)
    few = tmp_path / "few.csv"
    d6 = tumble(TumbleSpec(triad=tr, poses="six", seed=1))
    write_tumble_csv(d6, few)
    # Six faces (recognised from the means): the known-pose method, not a refusal ...
    cal6 = calibrate(read_poses(few)[0])
    # (unlabelled: the faces are recognised from the outputs, so the sign of k is --scale-sign)
    assert cal6.method == "known-pose" and np.allclose(cal6.model.k, np.abs(tr.k), rtol=1e-3)
    # ... but five poses are too few for any method.
    five = tmp_path / "five.csv"
    five.write_text("\n".join(ln for ln in few.read_text().splitlines()
                              if not ln.startswith("5,")))
    with pytest.raises(InputError, match="at least 9"):
        calibrate(read_poses(five)[0])
    flat = tmp_path / "flat.csv"
    up = d.up[:d.n_cal].copy()
    up[:, 2] = 0
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    u = tr.outputs(up, np.zeros(len(up)), np.zeros(len(up)), None)
    flat.write_text("pose,ux,uy,uz\n" + "\n".join(
        f"{i},{a},{b},{c}" for i, (a, b, c) in enumerate(u)))
    with pytest.raises(InputError, match="plane"):
        read_poses(flat)
    sat = tmp_path / "sat.csv"
    sat_tr = replace(tr, full_scale_v=2.0)
    ds = tumble(TumbleSpec(triad=sat_tr, seed=3))
    write_tumble_csv(ds, sat)
    with pytest.raises(InputError, match="saturated"):
        read_poses(sat)


@pytest.mark.parametrize("key, index, value, words", [
    ("k_v_per_g", 0, float("nan"), "k_v_per_g[0] = nan"),
    ("k_v_per_g", 2, 0.0, "k_v_per_g[2] = 0"),
    ("bias_g", 1, float("inf"), "bias_g[1] = inf"),
    ("drift_g_per_s", 0, float("nan"), "drift_g_per_s[0]"),
    ("beta_rad", 2, 1.0, "beta_rad[2] = 1 rad"),
    ("t_ref_s", None, float("nan"), "t_ref_s = nan"),
    ("k2_per_g", None, [0.0, 0.0], "k2_per_g: 2 values"),
])
def test_model_from_dict_refuses_what_cannot_be_applied(key, index, value, words):
    from align.calibration import TriadModel
    from align.errors import InputError

    d = TriadModel(np.array([1.0, 2.0, 3.0]), np.zeros(3), np.zeros(3)).to_dict()
    assert TriadModel.from_dict(d, "cal.json").k.tolist() == [1.0, 2.0, 3.0]
    if index is None:
        d[key] = value
    else:
        d[key][index] = value
    with pytest.raises(InputError) as exc:
        TriadModel.from_dict(d, "cal.json")
    msg = str(exc.value)
    assert msg.startswith("cal.json: model.") and words in msg and "\n" not in msg


def test_triad_model_cov_of_and_per_axis():
    from align.calibration.triad import TriadModel, per_axis

    names = per_axis("k", "beta", "bias")
    assert names[:4] == ("k_x", "k_y", "k_z", "beta_x")
    c = np.diag(np.arange(1.0, 10.0))
    m = TriadModel(np.ones(3), np.zeros(3), np.zeros(3), cov=c, names=names)
    assert np.array_equal(m.cov_of("bias_y", "k_x"), np.diag([8.0, 1.0]))
    assert np.allclose(m.u_per_axis("beta"), np.sqrt([4.0, 5.0, 6.0]))
    assert np.isnan(m.u_of("k2_x"))
    with pytest.raises(KeyError, match="k2_x"):
        m.cov_of("k2_x")
