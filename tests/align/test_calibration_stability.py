"""The declared scale-factor stability (align/calibration/stability.py): one rule for the
flag and the session key, the default without a temperature column, the propagation of a
±X ppm wander to k, beta and the biases, and its coverage of a temperature cycle."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from align.calibration import calibrate, poses_from_samples
from align.calibration.stability import (
    FLAG,
    STABILITY,
    chosen_ppm,
    stability_ppm,
)
from align.cli import main
from align.errors import InputError
from synth.tumble import Triad, TumbleSpec, r_matrix, tumble

SIX = ("+x", "+y", "+z", "-x", "-y", "-z")  # synth's order of the six faces


def _poses(d, labels=None):
    sel = d.pose < d.n_cal
    return poses_from_samples(d.pose[sel], d.u[sel], d.t[sel], labels)


def _csv(path: Path, d, temp: bool = False) -> Path:
    sel = d.pose < d.n_cal
    head = "pose,ux,uy,uz,t" + (",temp" if temp else "")
    path.write_text(head + "\n" + "".join(
        f"{p + 1},{a:.6f},{b:.6f},{c:.6f},{t:.2f}" + (f",{20 + 0.001 * t:.4f}" if temp else "")
        + "\n" for p, (a, b, c), t in zip(d.pose[sel], d.u[sel], d.t[sel], strict=True)))
    return path


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), 2e5, "100", True, None])
def test_the_rule_refuses_what_is_no_stability(bad):
    with pytest.raises(InputError, match=r"^here = "):
        stability_ppm(bad, "here")


def test_the_rule_accepts_zero_and_ppm():
    assert stability_ppm(0, "here") == 0.0 and stability_ppm(100, "here") == 100.0


def test_flag_and_key_are_refused_in_one_line_naming_them(tmp_path, capsys):
    d = tumble(TumbleSpec(seed=1, check_poses=0))
    path = _csv(tmp_path / "t.csv", d)
    assert main(["calibrate", str(path), FLAG, "-5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and FLAG in err[0] and "[0, 100000]" in err[0], err
    from align.session.config import load_session

    toml = tmp_path / "session.toml"
    toml.write_text('[calibration]\nstatic = "t.csv"\nscale_stability_ppm = "a lot"\n')
    with pytest.raises(InputError, match=r"\[calibration\] scale_stability_ppm = 'a lot'"):
        load_session(tmp_path)
    toml.write_text('[calibration]\nstatic = "t.csv"\nscale_stability_ppm = 30\n')
    assert load_session(tmp_path).calibration.scale_stability_ppm == 30.0


def test_nothing_declared_is_an_assumption_only_without_a_temperature_column():
    assert chosen_ppm(None, False) == (0.0, True)
    assert chosen_ppm(None, True) == (0.0, False)
    assert chosen_ppm(20.0, False) == (20.0, False) == chosen_ppm(20.0, True)


def test_cli_states_the_assumption_and_a_declaration_puts_the_term_per_parameter(
        tmp_path, capsys):
    """No temperature column, nothing declared: the JSON and the terminal state that the
    scale factors were assumed stable (no term, u unchanged); declared: u_widening has the
    term and its u per parameter; with a temperature column nothing is assumed."""
    d = tumble(TumbleSpec(seed=2, check_poses=0))
    for temp in (False, True):
        path = _csv(tmp_path / f"t{temp}.csv", d, temp)
        assert main(["calibrate", str(path), "--json", "-", "-q"]) == 0
        js = json.loads(capsys.readouterr().out)
        st = js["scale_stability"]
        assert st["assumed"] is (not temp) and (st["ppm"] is None) is (not temp), st
        wid = js["u_widening"]
        assert wid is None, wid  # nothing declared: no term widens u (it was "none, or no
        # stability term": these clean poses need no widening at all)
        if not temp:
            assert "assumed stable" in st["statement"] and "--scale-stability-ppm" in (
                st["statement"])
            assert main(["calibrate", str(path)]) == 0
            assert "scale stability: no temperature column" in capsys.readouterr().out
    path = tmp_path / "tFalse.csv"
    assert main(["calibrate", str(path), "--json", "-", "-q",
                 "--scale-stability-ppm", "20"]) == 0
    js = json.loads(capsys.readouterr().out)
    wid = js["u_widening"]
    assert js["scale_stability"] == {"ppm": 20.0, "assumed": False, "statement": (
        "scale factors declared stable to ±20 ppm over the run (carried in u)")}
    assert STABILITY in wid["terms"], js["warnings"]
    k = wid["parameters"]["scale_factor_x"]
    assert k[STABILITY] > 0 and k["u"] >= k[STABILITY]


def test_known_pose_propagation_is_the_derived_one():
    """Six faces, the linear fit u = M d + o: o_x is the mean of the six faces' x readings
    (one per face and sign: +-M_xx, +-M_xy, +-M_xz, each + o_x), so readings anywhere within
    ±X move it by at most X (2 k + 4 |o_x| + ...) / 6, i.e. b_x by X g / 3; M_xx = (u(+x) -
    u(-x)) / 2 moves by X k; beta (from M_xy = (u_x(+y) - u_x(-y)) / 2, readings k (b_x
    +- beta)) only through second-order terms. The term's u: X g / (3 sqrt 3), X k /
    sqrt 3, and a tenth of the biases' for beta."""
    tr = Triad()
    d = tumble(TumbleSpec(triad=tr, poses="six", check_poses=0, seed=3, fixture_error_rad=0))
    x = 200.0
    poses = _poses(d, SIX)
    cal = calibrate(poses, fixture_error_rad=0.0, scale_stability_ppm=x)
    p = cal.widening.to_dict()["parameters"]
    term = {n: v[STABILITY] for n, v in p.items()}
    for i, (ax, k) in enumerate(zip("xyz", np.abs(tr.k), strict=True)):
        # [g]: 1/3 + 2 |b| / 3 + ...; the fit weighs the faces by their standard errors
        # (each from 200 samples: +-5 %), so o_x is a weighted mean: within 5 %.
        mean_of_six = np.abs(poses.u[:, i]).sum() / 6 / k
        assert term[f"bias_{ax}"] == pytest.approx(x * 1e-6 * mean_of_six / np.sqrt(3),
                                                   rel=0.05)
        assert term[f"k_{ax}"] == pytest.approx(x * 1e-6 * k / np.sqrt(3), rel=0.02)
    assert all(term[f"beta_{ax}"] < 0.1 * term[f"bias_{ax}"] for ax in "xyz"), term
    # The worst case is reached: readings scaled by X sign(G_j) and refitted move each
    # parameter j by X sum |G_j| = sqrt 3 x its term (the fit is linear in the readings).
    G = cal.known.scale_gain
    for j, name in enumerate(cal.model.names[:9]):
        eps = x * 1e-6 * np.sign(G[j]).reshape(-1, 3)
        moved = calibrate(replace(poses, u=poses.u * (1 + eps)), fixture_error_rad=0.0,
                          scale_stability_ppm=0.0).model
        shift = np.concatenate([moved.k, moved.beta, moved.bias])[j] - np.concatenate(
            [cal.model.k, cal.model.beta, cal.model.bias])[j]
        assert abs(shift) == pytest.approx(np.sqrt(3) * term[name], rel=0.01), name


def _cycled(seed: int, up=None):
    rng = np.random.default_rng(100 + seed)
    tr = Triad(scale_cycle=(1e-4,) * 3, cycle_phase=float(rng.uniform(0, 2 * np.pi)))
    d = tumble(TumbleSpec(triad=tr, seed=seed, dwell_s=60.0, move_s=30.0, up=up))
    s = 1 + 1e-4 * np.sin(2 * np.pi * d.t / tr.cycle_period_s + tr.cycle_phase)
    rows = np.linalg.norm(r_matrix(np.asarray(tr.beta)), axis=1)
    truth = np.concatenate([np.asarray(tr.k) * s.mean() * rows, tr.beta, tr.bias])
    return tr, _poses(d), truth


def _z(cal, truth):
    m = cal.model
    est = np.concatenate([m.sensitivity(), m.beta, m.bias])
    u = np.concatenate([m.sensitivity_u(), m.u_per_axis("beta"), m.u_per_axis("bias")])
    return (est - truth) / u


@pytest.mark.slow
def test_a_temperature_cycle_is_covered_when_declared_and_not_without():
    """HVAC ±1 K at 100 ppm/K (±100 ppm, 15 min), 60 s poses of the paper's 14: declared
    100 ppm, every parameter of every seed within 3 u of the run's truth (scale factors at
    the run's mean scale). Declared 0: before stop 28 some seed was beyond 3 u unflagged
    (seed 0: beta_z 5.4 u); the structure it leaves is now carried by the loop's own terms
    (the candidates it could not add: ``plausible_effect``), so every seed is within 3 u
    and its u says it was widened."""
    worst = {}
    for x in (100.0, 0.0):
        zs = []
        for seed in range(5):
            tr, poses, truth = _cycled(seed)
            cal = calibrate(poses, np.sign(tr.k), scale_stability_ppm=x)
            zs.append(np.abs(_z(cal, truth)).max())
            if x == 0.0:
                assert cal.widening is not None and cal.widening.reasons, seed
        worst[x] = max(zs)
    assert worst[100.0] < 3.0 and worst[0.0] < 3.0, worst


@pytest.mark.slow
def test_user6_cycle_is_covered_when_its_stability_is_declared(tmp_path, capsys):
    """user6's own case (tests/align/user6_inputs.py: ±100 ppm, 15 min, 60 s poses, no
    temperature column) with --scale-stability-ppm 100: every k within 3 u of the run's mean
    or of k at the mean time (the user's test's criterion), and the term named."""
    from tests.align import user6_inputs as U
    from tests.align.test_independent_user6 import k_z, triad

    for seed in range(3):
        tri, rng = triad(seed)
        ph = rng.uniform(0, 2 * np.pi)

        def sf(t, ph=ph):
            return 1 + 100e-6 * np.sin(2 * np.pi * t / 900.0 + ph)

        rows = U.tumble_rows(tri, U.cube14(), rng, n=1200, scale_of_t=sf, t_gap=30.0)
        ts = np.array([r[1] for r in rows])
        p = U.write_tumble(tmp_path / f"t{seed}.csv", rows)
        assert main(["calibrate", str(p), FLAG, "100", "--json", "-", "-q"]) == 0
        js = json.loads(capsys.readouterr().out)
        assert "declared stable to ±100 ppm" in js["u_widening"]["terms"][STABILITY]
        z_ref = k_z(js, tri.k * sf(np.array([ts.mean()]))[0])
        z_avg = k_z(js, tri.k * sf(ts).mean())
        assert np.all(np.minimum(np.abs(z_ref), np.abs(z_avg)) < 3), (seed, z_ref, z_avg)
