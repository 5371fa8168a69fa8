"""The goniometer's loop and both directions against synth truth: the issue's undeclared
effects (Earth rate with an unsteady table, latitude not given; autocollimator latency with a
speed ripple locked to the table), before/after at the floor. 0.5 rev/s, 1000 revolutions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from align.cli import main
from align.gonio import EARTH, measure_log
from align.gonio_loop import loop_gonio
from axisbase.units import DEG
from goniometry import face_angles, kept_table, read_revolutions, vertical_earth_rate
from synth.gonio import GonioSpec, simulate, write_log

TOL = 4.5
SLOW = dict(revolutions=1000, rev_per_s=0.5)


def _log(tmp_path, name, **kw):
    sim = simulate(GonioSpec(**{**SLOW, **kw}))
    return write_log(sim, tmp_path / name), np.array(sim["truth"]["angles_rad"])


def test_clockwise_run_gives_angles_in_its_own_passing_order(tmp_path):
    p, truth = _log(tmp_path, "cw.csv", direction=-1, revolutions=300, seed=4)
    run = measure_log(p, 4, 50.45 * DEG, direction=-1)
    assert np.all(np.abs(run.angles.angles_rad - truth) < TOL * run.angles.u_rad)
    # cw passes faces 0, 3, 2, 1: its angles are the ccw order's, reversed.
    ccw = GonioSpec(**{**SLOW, "seed": 4}).angles
    assert np.allclose(truth, ccw[::-1])


def test_undeclared_earth_rate_with_unsteady_table_is_found(tmp_path):
    """2 % ripple locked to the table + 1 % slow wander, Earth rate present, no latitude: the
    counts per revolution follow the period (the duration-correlated residual), the loop adds
    the Earth rate, and the angles go from biased to the floor. (No latency here: with a
    locked ripple it leaves its own bias, which only both directions remove — next test.)"""
    p, truth = _log(tmp_path, "ccw.csv", ripple=0.02, wander=0.01, latency_s=0.0, seed=0)
    before = face_angles(read_revolutions(p, 4))
    run = measure_log(p, 4, latitude_rad=None)
    names = [e.name for e in run.loop.effects]
    assert names == [EARTH]
    e = run.loop.effects[0]
    assert abs(e.estimate - vertical_earth_rate(50.45 * DEG, 1)) < TOL * e.u
    z_before = (before.angles_rad - truth) / before.u_rad
    z_after = (run.angles.angles_rad - truth) / run.angles.u_rad
    assert np.max(np.abs(z_before)) > TOL
    assert np.all(np.abs(z_after) < TOL)


def test_both_directions_cancel_latency_and_earth_rate(tmp_path):
    """5 us latency, 2 % locked ripple, Earth rate, no latitude: one direction stays biased;
    the mean of ccw and cw is at the floor, and the direction-dependent part is reported."""
    kw = dict(ripple=0.02, wander=0.005, latency_s=5e-6)
    p1, truth = _log(tmp_path, "ccw.csv", seed=0, **kw)
    p2, _ = _log(tmp_path, "cw.csv", direction=-1, seed=100, **kw)
    one = face_angles(read_revolutions(p1, 4))  # one direction, declared model
    both = measure_log(p1, 4, reverse_log=p2)
    assert np.max(np.abs(one.angles_rad - truth) / one.u_rad) > TOL
    assert np.all(np.abs(both.angles.angles_rad - truth) < TOL * both.angles.u_rad)
    assert both.direction.p_value < 1e-3
    # The floor: quantisation averaged over all revolutions used (q / sqrt(6) / sqrt(R)).
    q = 2 * np.pi / both.angles.counts_per_rev
    limit = q / np.sqrt(6) / np.sqrt(both.angles.revolutions)
    assert np.all(both.angles.u_rad < 1.2 * limit)
    out = tmp_path / "g.json"
    assert main(["gonio", str(p1), "--faces", "ref,z,y,x", "--reverse-log", str(p2),
                 "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert "direction_dependent" in [x["name"] for x in js["effects"]]
    assert np.allclose(np.deg2rad(js["angles_deg"]), both.angles.angles_rad)


def _steady(tmp_path, seeds):
    """Per seed (300 revolutions at 1 rev/s, a steady table): z of the four angles from the
    pulse times, the ratios of their u to the autocollimator jitter, and the gains in u over
    the counts (one row a seed)."""
    z, ratio, gain = [], [], []
    for seed in seeds:
        p, truth = _log(tmp_path, f"s{seed}.csv", revolutions=300, rev_per_s=1.0, seed=seed)
        counts = measure_log(p, 4, 50.45 * DEG)
        run = measure_log(p, 4, 50.45 * DEG, steady_table=True)
        assert run.timing_used
        fa = run.angles
        z.append((fa.angles_rad - truth) / fa.u_rad)
        jitter = GonioSpec().jitter_rad * np.sqrt(2) / np.sqrt(fa.revolutions)
        ratio.append(fa.u_rad / jitter)
        gain.append(counts.angles.u_rad / fa.u_rad)
    return np.array(z), np.array(ratio), np.array(gain)


def test_steady_table_timing_goes_below_the_count_quantisation(tmp_path):
    """Constant speed, two seeds (the slow sweep below has eight and the RMS of z): the
    angles from pulse times are within TOL u of the truth, their u is the autocollimator
    jitter's (sqrt(2) x 0.1" per angle per revolution; each u a batch-means estimate, ~25 %
    scatter over 4 angles), several times below the counts' uncertainty; a 0.01 % ripple
    locked to the table is caught by the counts and the timing estimate refused."""
    z, ratio, gain = _steady(tmp_path, (0, 1))
    assert np.all(np.abs(z) < TOL), z
    ratio, gain = np.median(ratio, axis=1), np.median(gain, axis=1)  # each seed's
    assert np.all((0.7 < ratio) & (ratio < 1.3)), ratio
    assert np.all(gain > 2.5), gain
    p, _ = _log(tmp_path, "ripple.csv", revolutions=300, rev_per_s=1.0, ripple=1e-4, seed=1)
    run = measure_log(p, 4, 50.45 * DEG, steady_table=True)
    assert not run.timing_used and any("NOT confirmed" in n for n in run.notes)


@pytest.mark.slow  # the default run keeps two seeds and the ripple's refusal (above)
def test_steady_table_timing_sweep(tmp_path):
    """Eight seeds: angles from pulse times consistent with truth (RMS of z near 1) and
    limited by the autocollimator jitter, several times below the counts' uncertainty."""
    z, ratio, gain = _steady(tmp_path, range(8))
    assert np.all(np.abs(z) < TOL) and 0.6 < np.sqrt(np.mean(z**2)) < 1.5
    assert 0.7 < np.median(ratio) < 1.3
    # Expected gain: counts ~0.76 q/sqrt6 (benchmark) over sqrt2 sigma_j = 0.76 x 0.69" / 0.14"
    # = 3.7; each u is a batch-means estimate (~25 % scatter with ~37 blocks).
    assert np.median(gain) > 2.5


def _independent(tmp_path, seed, name="ind.csv"):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parents[1] / "goniometry"))
    from independent_log import independent_log

    p = tmp_path / name
    truth = independent_log(p, 2000, 0.5, ripple=0.016, wander=0.004, latitude_deg=50.45,
                            seed=seed)
    return p, truth


@pytest.mark.slow
def test_undetermined_earth_rate_is_carried_as_type_b(tmp_path):
    """The issue's case, on a log written independently of synth (2^20 periods per inertial
    revolution, 10 MHz stamps): 1.6 % locked ripple + 0.4 % random wander, 0.5 rev/s, 2000
    revolutions, no latitude. The log cannot determine the Earth rate (structure remains),
    so its effect over all latitudes enters u, named; the normalised errors stay well inside
    3 (1.43 at most here: since the order tests no longer read the counter's quantisation
    stretches as structure, docs/false-alarms.md, a wander below one count RMS no longer
    inflates u on top of the Type B term; it was 1.2).
    With a latitude range the term shrinks and still covers; with --latitude it is gone."""
    p, truth = _independent(tmp_path, 0)
    run = measure_log(p, 4)
    fa = run.angles
    z = (fa.angles_rad - truth) / fa.u_rad
    assert np.all(np.abs(z) < 2.0), z
    (name,) = fa.type_b_terms
    assert name.startswith("earth_rate")
    if "all latitudes" in name:
        # The term is what moves the angles: without it the errors are several u.
        u_a = np.sqrt(fa.u_rad**2 - fa.type_b_terms[name] ** 2)
        assert np.max(np.abs(fa.angles_rad - truth) / u_a) > 3
    else:
        # Since the order tests leave the counter's quantisation stretches alone, this log's
        # 0.4 % wander (under one count RMS) no longer counts as structure, and the loop
        # estimates the Earth rate from its period (2000 revolutions): carried with the
        # estimate's u, the errors still within 2 u (above).
        assert name == "earth_rate (estimated)", name
    rng = measure_log(p, 4, latitude_range_rad=(40.0 * DEG, 60.0 * DEG)).angles
    assert np.all(rng.u_rad <= fa.u_rad + 1e-15)
    assert np.all(np.abs(rng.angles_rad - truth) < 2.0 * rng.u_rad)
    lat = measure_log(p, 4, 50.45 * DEG).angles
    assert not lat.type_b_terms
    assert np.all(np.abs(lat.angles_rad - truth) < TOL * lat.u_rad)
    out = tmp_path / "tb.json"
    # (one direction on a rippled table: a latency up to 1 ms could move it beyond u, which
    # the log cannot tell: not ok, exit 2; the Earth rate's term is still reported)
    assert main(["gonio", str(p), "--faces", "ref,z,y,x", "--latitude-range", "40,60",
                 "--json", str(out)]) == 2
    js = json.loads(out.read_text())
    assert not js["ok"] and any("latency" in w for w in js["warnings"])
    assert any(k.startswith("earth_rate") for k in js["type_b_terms_arcsec"])
    assert main(["gonio", str(p), "--faces", "ref,z,y,x", "--latitude-range", "60,40"]) == 2
    assert main(["gonio", str(p), "--faces", "ref,z,y,x", "--latitude-range", "40,60",
                 "--latitude", "50"]) == 2


@pytest.mark.slow
def test_type_b_normalised_errors_over_seeds(tmp_path):
    """8 independent 2000-revolution logs, no latitude. The order tests leave the counter's
    quantisation stretches alone (SEQUENCE_ABOVE_COUNTS); the one wander under a count that
    matters here — the Earth rate's share of the wandering period, ~0.07 count RMS in N_r,
    4.6-5.0 u in the angles when not removed — is still found in every log (the period
    regressor's F-test), and the angles then agree with the true latitude's within 3 of the
    estimate's named u term. Before the rule the order tests flagged all 8 logs (the
    quantisation stretches), the estimate was not taken and u held the all-latitude bound:
    0.108" instead of 0.017-0.020" (max |z| 1.01 then from a 5x larger u, not from a
    better estimate: with the true latitude the same logs reach 1.94)."""
    zs, moved = [], []
    for seed in range(1, 9):
        p, truth = _independent(tmp_path, seed, f"i{seed}.csv")
        run = measure_log(p, 4)
        fa = run.angles
        zs.append((fa.angles_rad - truth) / fa.u_rad)
        assert run.loop is not None and not run.loop.unexplained_structure, seed
        assert [e.name for e in run.loop.effects] == ["earth_rate"], seed
        (name, term), = fa.type_b_terms.items()
        assert name == "earth_rate (estimated)", name
        lat = measure_log(p, 4, 50.45 * DEG).angles
        raw = measure_log(p, 4, apply_loop=False).angles
        moved.append(np.max(np.abs(raw.angles_rad - lat.angles_rad) / fa.u_rad))
        assert np.all(np.abs(fa.angles_rad - lat.angles_rad) <= 3 * term + 1e-15), seed
    zs = np.array(zs)
    print(f"Type B case: max |z| {np.max(np.abs(zs)):.2f}, RMS {np.sqrt(np.mean(zs**2)):.2f};"
          f" the Earth rate not removed: {min(moved):.1f}-{max(moved):.1f} u")
    # 32 angles: max 1.92, RMS 0.60 (before the quantisation rule of the order tests: 1.01,
    # 0.65 — from the all-latitude bound in u; the estimate's term still covers, RMS below 1)
    assert np.max(np.abs(zs)) < 2.5 and np.sqrt(np.mean(zs**2)) < 1.0
    assert min(moved) > 3.0  # the wander found matters


def test_session_latitude_range_key(tmp_path):
    from align.session.config import load_session
    from axisbase.errors import InputError

    p, _ = _log(tmp_path, "gonio.csv", revolutions=50)
    toml = '[goniometer]\nlog = "gonio.csv"\nfaces = ["ref", "z", "y", "x"]\n'
    (tmp_path / "session.toml").write_text("latitude_range_deg = [40, 60]\n" + toml)
    assert load_session(tmp_path).latitude_range_rad == (40.0 * DEG, 60.0 * DEG)
    (tmp_path / "session.toml").write_text("latitude_range_deg = [60, 40]\n" + toml)
    with pytest.raises(InputError, match="latitude_range_deg"):
        load_session(tmp_path)


@pytest.mark.slow
def test_latency_on_a_rippled_table_is_warned_in_one_direction_and_cancelled_in_two(tmp_path):
    """5 µs of autocollimator latency on a table whose speed is locked to its angle (2 %
    ripple) biases one direction's angles by tens of u — the latitude given, nothing in the
    counts shows it. The pulse times show the ripple: a warning with the bias per µs; with the
    other direction the bias cancels and so does the warning."""
    from align.gonio import LATENCY

    p, truth = _log(tmp_path, "f.csv", revolutions=3000, seed=3, ripple=0.02, wander=0.01,
                    latency_s=5e-6)
    one = measure_log(p, 4, 50.45 * DEG)
    assert np.max(np.abs(one.angles.angles_rad - truth) / one.angles.u_rad) > 10
    assert any(w.startswith(LATENCY) for w in one.warnings)
    assert one.problems  # (a latency up to 1 ms could bias it beyond u: not ok)
    r, _ = _log(tmp_path, "r.csv", revolutions=3000, seed=4, ripple=0.02, wander=0.01,
                latency_s=5e-6, direction=-1)
    both = measure_log(p, 4, 50.45 * DEG, reverse_log=r)
    assert np.all(np.abs(both.angles.angles_rad - truth) < TOL * both.angles.u_rad)
    assert not any(LATENCY in w for w in both.warnings)
    steady, _ = _log(tmp_path, "s.csv", revolutions=3000, seed=3, latency_s=5e-6)
    assert not any(w.startswith(LATENCY) for w in measure_log(steady, 4, 50.45 * DEG).warnings)


@pytest.mark.parametrize("seed", range(4))
def test_scale_drift_estimate_is_the_relative_drift_of_the_counts(seed):
    """Counts per revolution N_r = K (1 + kappa t) (a ring laser whose scale factor drifts by
    kappa per second), each face's count a floor of the accumulated phase plus 0.1-count
    jitter: the loop adds scale_drift and its estimate is kappa [1/s] within 3 u (it was
    reported 2 pi too large: the Earth rate's rad/s conversion)."""
    from align.gonio_loop import SCALE, loop_gonio

    rng = np.random.default_rng(seed)
    K, kappa, R, n = 764355.8, 4e-7, 400, 4
    t_pulse = np.arange(R * n + 1) * 0.25  # 1 rev/s, four faces
    rate = K * (1 + kappa * t_pulse) / n  # counts per face interval at each pulse
    phase = np.concatenate([[0.3], 0.3 + np.cumsum(rate[:-1])]) + rng.normal(0, 0.1, R * n + 1)
    counts = np.diff(np.floor(phase)).reshape(R, n)
    dt = np.diff(t_pulse).reshape(R, n)
    rep = loop_gonio(counts, dt, t_pulse[n::n])
    e = {x.name: x for x in rep.effects}
    assert SCALE in e, [x.name for x in rep.effects]
    assert abs(e[SCALE].estimate - kappa) < 3 * e[SCALE].u, (e[SCALE].estimate, e[SCALE].u)


# 0.2 rev/s with a 20 % wander over ~20 revolutions: the periods vary enough for the counts to
# pin the Earth rate; the regressor (the mean period of revolutions r-2 and r+2) follows T_r
# with an attenuation of 1.04-1.08 there, which read the rate 4-8 % high (z +3.8 … +8.0 over
# 12 seeds) until the stage divided it out.
WANDERING = dict(revolutions=300, rev_per_s=0.2, wander=0.2, ripple=0.05, latency_s=0.0)


def _loop_earth_z(tmp_path, seeds) -> np.ndarray:
    """(loop's Earth rate − truth) / its u, without --latitude, on wandering tables."""
    z = []
    for seed in seeds:  # (the loop as measure_log runs it, without the rest: 0.15 s a seed)
        spec = GonioSpec(**WANDERING, seed=seed)
        log = read_revolutions(write_log(simulate(spec), tmp_path / f"w{seed}.csv"), 4)
        earth = [e for e in loop_gonio(*kept_table(log)).effects if e.name == EARTH]
        assert earth, seed  # (20 % wander: the rate is always seen)
        truth = vertical_earth_rate(spec.latitude_deg * DEG, spec.direction)
        z.append((earth[0].estimate - truth) / earth[0].u)
    return np.array(z)


def test_the_loops_earth_rate_on_a_wandering_table_is_unbiased(tmp_path):
    """One seed (the slow twin runs 40): within 3 u (was 6.7 u high)."""
    z = _loop_earth_z(tmp_path, (0,))
    assert np.all(np.abs(z) < 3.0), z


@pytest.mark.slow
def test_the_loops_earth_rate_over_seeds_is_unbiased(tmp_path):
    """40 seeds: the mean normalised error within 3 standard errors of 0 (was +5.7), the
    RMS at most 1.3 (u may be conservative: the quantisation pattern's share), none beyond
    3.5."""
    z = _loop_earth_z(tmp_path, range(100, 140))
    assert abs(z.mean()) < 3 * z.std(ddof=1) / np.sqrt(len(z)), z
    assert np.sqrt(np.mean(z ** 2)) < 1.3, z
    assert np.all(np.abs(z) < 3.5), z
