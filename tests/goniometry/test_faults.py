"""Pulse faults injected into the instrument (synth's autocollimator, binding signal and
interface) never bias a face angle and are all listed: double triggers 0.1-5 ms after and
before a face (the reference face too, its binding window marking both pulses or not),
glints at any phase including within 0.1 % of a face, missing pulses (reference pulses too),
bursts, a lost row, a mislabelled counter, failed reference signals, logs armed on any face
and stopped anywhere, 0.2-5 rev/s, both directions. Pass: every angle within 4 u of the
truth and every fault's row named by some reason (+-1 row)."""

from __future__ import annotations

import numpy as np
import pytest

from align.gonio import measure_log
from axisbase.units import DEG
from goniometry import read_revolutions
from goniometry.exclusions import R_DROPOUT, R_LABEL, R_LOST
from synth.gonio import GonioSpec, simulate, write_log

N_FACES = 4
REVS = 120


def fault_plan(seed: int) -> GonioSpec:
    """A random run with 4-10 faults (some in bursts) at random places."""
    rng = np.random.default_rng(1000 + seed)
    rate = float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
    n_pulses = REVS * N_FACES
    stop = int(rng.integers(0, 4))
    faults = []
    used: set[int] = set()

    def free_pulse(face: int | None = None) -> int:
        while True:
            i = int(rng.integers(8, n_pulses - stop - 8))
            if face is not None:
                i -= i % N_FACES - face
            if not used & {i - 1, i, i + 1}:
                used.add(i)
                return i

    def one(i: int | None = None) -> None:
        kind = rng.choice(["double", "double_ref", "glint", "glint_near", "missing",
                           "missing_ref", "ref_fail", "lost_row", "counter_swap"])
        ms = float(rng.uniform(0.1, 5.0)) * 1e-3 * rng.choice([-1, 1])
        if kind == "double":
            faults.append(("double", i if i is not None else free_pulse(), ms))
        elif kind == "double_ref":  # on the reference face, marked or not
            faults.append((str(rng.choice(["double", "double_ref"])), free_pulse(0), ms))
        elif kind == "glint":
            faults.append(("glint", i if i is not None else free_pulse(), rng.uniform()))
        elif kind == "glint_near":
            f = float(rng.uniform(0, 1e-3))
            faults.append(("glint", i if i is not None else free_pulse(),
                           f if rng.random() < 0.5 else 1 - f))
        elif kind == "missing":
            faults.append(("missing", i if i is not None else free_pulse(), 0))
        elif kind == "missing_ref":
            faults.append(("missing", free_pulse(0), 0))
        elif kind == "ref_fail":
            faults.append(("ref_fail", free_pulse(0), 0))
        else:
            faults.append((str(kind), i if i is not None else free_pulse(), 0))

    for _ in range(int(rng.integers(3, 7))):
        one()
    # A burst: faults on consecutive pulses.
    i0 = free_pulse()
    for k in range(int(rng.integers(2, 4))):
        used.add(i0 + k)
        one(i0 + k)
    # Half the runs on an unsteady table (locked ripple + wander; no autocollimator latency,
    # whose product with a locked ripple is a real bias only both directions remove).
    unsteady = rng.random() < 0.5
    return GonioSpec(revolutions=REVS, rev_per_s=rate, direction=int(rng.choice([-1, 1])),
                     faults=tuple(faults), arm_face=int(rng.integers(0, N_FACES)),
                     stop_pulses=stop, ripple=0.02 if unsteady else 0.0,
                     wander=0.01 if unsteady else 0.0, latency_s=0.0 if unsteady else 5e-6,
                     seed=seed)


def run_plan(seed: int, tmp_path) -> tuple[float, int, int, list]:
    """The faulty log of ``seed``: worst |error|/u, faults injected, listed, the unlisted
    ones."""
    spec = fault_plan(seed)
    sim = simulate(spec)
    p = write_log(sim, tmp_path / f"f{seed}.csv")
    run = measure_log(p, N_FACES, spec.latitude_deg * DEG, direction=spec.direction)
    truth = np.array(sim["truth"]["angles_rad"])
    worst = float(np.max(np.abs(run.angles.angles_rad - truth) / run.angles.u_rad))
    ex = run.summary.exclusions
    rows = {line - 2 for lines in ex.lines.values() for line in lines}
    # A communication drop-out (a 'lost_row' fault) excludes the revolution it broke whole,
    # listed at the drop-out's line: a fault inside that revolution enters no angle and is
    # covered by that listing (the rows to the next reference mark: at most N_FACES + 1).
    drops = [line - 2 for reason, lines in ex.lines.items() if reason == R_DROPOUT
             for line in lines]
    injected = sim["truth"]["faults"]
    unlisted = [f for f in injected if not rows & {f["row"] - 1, f["row"], f["row"] + 1}
                and not any(d <= f["row"] <= d + N_FACES + 1 for d in drops)]
    return worst, len(injected), len(injected) - len(unlisted), unlisted


@pytest.mark.parametrize("seed", range(6))
def test_faults_never_bias_and_are_all_listed(seed, tmp_path):
    worst, injected, listed, unlisted = run_plan(seed, tmp_path)
    assert worst < 4.0, fault_plan(seed)
    assert listed == injected, unlisted


def twin_errors(seed: int, tmp_path) -> np.ndarray:
    """The same log without its faults (same table, ring laser, jitter): its errors / u."""
    from dataclasses import replace

    spec = replace(fault_plan(seed), faults=())
    sim = simulate(spec)
    p = write_log(sim, tmp_path / f"c{seed}.csv")
    run = measure_log(p, N_FACES, spec.latitude_deg * DEG, direction=spec.direction)
    truth = np.array(sim["truth"]["angles_rad"])
    return (run.angles.angles_rad - truth) / run.angles.u_rad


@pytest.mark.slow
def test_faults_over_six_hundred_logs(tmp_path):
    """Every fault listed, and no angle of any of the 600 logs off by more than 4 u."""
    worst, injected, listed = [], 0, 0
    for seed in range(600):
        w, i, li, *_ = run_plan(seed, tmp_path)
        worst.append(w)
        injected += i
        listed += li
    print(f"worst |error|/u {max(worst):.2f}; faults listed {listed} / {injected}")
    assert listed == injected
    assert max(worst) < 4.0


@pytest.mark.slow
def test_fault_free_twins_within_four_u(tmp_path):
    """The fault-free twins of all 600 logs: no angle beyond 4 u (the batch-means u of these
    120-revolution logs put seeds 130 and 150 at 4.83 u and 4.64 u: 5-10 degrees of freedom),
    and the normalised errors' RMS within chi-square bounds (3 free angles a log)."""
    from scipy.stats import chi2

    z = np.array([twin_errors(seed, tmp_path) for seed in range(600)])
    dof = 3 * len(z)
    lo, hi = (np.sqrt(chi2.ppf(p, dof) / dof) for p in (5e-4, 1 - 5e-4))
    rms = float(np.sqrt(np.mean(z**2)))
    print(f"worst |z| {np.max(np.abs(z)):.2f}, RMS {rms:.3f} (bounds {lo:.3f}-{hi:.3f})")
    assert np.max(np.abs(z)) < 4.0
    # u may be conservative (the quantisation floor of a nearly locked phase), not small.
    assert 0.8 < rms < hi


@pytest.mark.parametrize("seed", [130, 150])
def test_the_twins_batch_means_put_beyond_four_u(seed, tmp_path):
    """The two fault-free logs of the plan whose batch-means u (5-10 degrees of freedom)
    left an angle at 4.83 u and 4.64 u."""
    z = twin_errors(seed, tmp_path)
    assert np.max(np.abs(z)) < 4.0, z


@pytest.mark.parametrize("n_logs", [8, pytest.param(24, marks=pytest.mark.slow)])
def test_slow_unsteady_short_logs_normalised_errors(tmp_path, n_logs):
    """The regime where batch means failed: 120 revolutions of a slow (0.2-0.5 rev/s)
    unsteady table (ripple 2 % locked to the angle, wander 1 %), both directions. Over
    ``n_logs`` seeded clean logs (8 in the default run, 24 in the slow one) the normalised
    errors' RMS lies within the chi-square bounds of its 3 n_logs free angles (0.1 %,
    two-sided) and none is beyond 4 u."""
    from scipy.stats import chi2

    z = []
    for seed in range(n_logs):
        rng = np.random.default_rng(7000 + seed)
        spec = GonioSpec(revolutions=REVS, rev_per_s=float(rng.uniform(0.2, 0.5)),
                         direction=int(rng.choice([-1, 1])), ripple=0.02, wander=0.01,
                         latency_s=0.0, arm_face=int(rng.integers(0, N_FACES)),
                         stop_pulses=int(rng.integers(0, 4)), seed=7000 + seed)
        sim = simulate(spec)
        run = measure_log(write_log(sim, tmp_path / f"s{seed}.csv"), N_FACES,
                          spec.latitude_deg * DEG, direction=spec.direction)
        truth = np.array(sim["truth"]["angles_rad"])
        z.append((run.angles.angles_rad - truth) / run.angles.u_rad)
    z = np.array(z)
    dof = 3 * len(z)  # the closure: 3 free angles a log
    lo, hi = (np.sqrt(chi2.ppf(p, dof) / dof) for p in (5e-4, 1 - 5e-4))
    rms = float(np.sqrt(np.mean(z**2)))
    assert lo < rms < hi, (rms, lo, hi)
    assert np.max(np.abs(z)) < 4.0


def test_the_reported_double_trigger(tmp_path):
    """The issue's log: 3 missing and 2 spurious pulses (a glint mid-interval, a double
    trigger ~1 ms after a face), armed on a face other than the reference, stopped
    mid-revolution. The wrong pulse of the pair was kept: 330 u. Now the face pattern decides
    and the revolution is exact."""
    faults = (("missing", 90, 0), ("missing", 301, 0), ("missing", 555, 0),
              ("glint", 200, 0.5), ("double", 402, 1e-3))
    sim = simulate(GonioSpec(revolutions=200, faults=faults, arm_face=1, stop_pulses=2,
                             seed=7))
    p = write_log(sim, tmp_path / "issue.csv")
    run = measure_log(p, N_FACES, 50.45 * DEG)
    truth = np.array(sim["truth"]["angles_rad"])
    assert np.all(np.abs(run.angles.angles_rad - truth) < 4 * run.angles.u_rad)
    ex = run.summary.exclusions
    assert sum(ex.counts.values()) == 5
    assert run.angles.revolutions >= 200 - 1 - 3 - 1  # head, three missing, tail
    assert run.summary.armed_face == 1


def test_clean_logs_report_nothing(tmp_path):
    for seed in range(4):
        sim = simulate(GonioSpec(revolutions=150, rev_per_s=[0.2, 1, 3, 5][seed],
                                 arm_face=seed % 4, stop_pulses=seed, ripple=0.02,
                                 wander=0.01, seed=seed))
        s = read_revolutions(write_log(sim, tmp_path / f"c{seed}.csv"), N_FACES)
        assert not s.exclusions.counts, dict(s.exclusions.counts)
        assert s.excluded_revolutions == 0


def test_a_double_trigger_too_close_to_tell_excludes_its_revolution(tmp_path):
    """A second pulse 1 µs after a face (0.8 count at 1 rev/s) and a glint ~1 count before
    another: which pulse is the face cannot be known from the counts (nor from the times,
    which read the same instants): those revolutions are excluded and said so, not guessed."""
    from goniometry.exclusions import R_AMBIGUOUS

    faults = (("double", 101, 1e-6), ("glint", 202, 1 - 5e-6))
    sim = simulate(GonioSpec(revolutions=150, faults=faults, seed=3))
    run = measure_log(write_log(sim, tmp_path / "close.csv"), N_FACES, 50.45 * DEG)
    ex = run.summary.exclusions
    assert ex.counts[R_AMBIGUOUS] == 2
    rows = [line - 2 for line in ex.lines[R_AMBIGUOUS]]
    for f, r in zip(sim["truth"]["faults"], sorted(rows), strict=True):
        assert abs(f["row"] - r) <= 1
    assert run.summary.excluded_revolutions == 2
    truth = np.array(sim["truth"]["angles_rad"])
    assert np.all(np.abs(run.angles.angles_rad - truth) < 4 * run.angles.u_rad)


# ------------------------------------------------------------------ noise's tail in long logs

ARCSEC = np.pi / 180 / 3600


def test_the_noise_reach_grows_with_the_log_as_the_gaussian_tail_says():
    from scipy.stats import norm

    from goniometry.exclusions import SCREEN_SIGMA, TAIL_ALPHA, noise_reach

    assert noise_reach(10) == SCREEN_SIGMA  # a short log: the screen's 5 sigma
    for samples in (10**3, 10**5, 4 * 60000, 10**8):
        want = max(SCREEN_SIGMA, norm.isf(TAIL_ALPHA / 2 / samples))
        assert noise_reach(samples) == pytest.approx(want, rel=1e-9)
    assert 6.0 < noise_reach(4 * 60000) < 6.5


def _displace_pulse(path, row: int, counts: int) -> None:
    """Move the face pulse ending data row ``row`` (a non-reference face) by ``counts``
    (and its time by as much): the interval before it grows, the one after shrinks."""
    lines = path.read_text().splitlines()
    head, rows = lines[0], [r.split(",") for r in lines[1:]]
    assert rows[row][2] == "0"
    rate = float(rows[row][0]) / (float(rows[row][3]) - float(rows[row - 1][3]))  # counts/s
    rows[row][0] = str(int(rows[row][0]) + counts)
    rows[row + 1][0] = str(int(rows[row + 1][0]) - counts)
    rows[row][3] = f"{float(rows[row][3]) + counts / rate:.9f}"
    path.write_text("\n".join([head, *(",".join(r) for r in rows)]) + "\n")


def test_a_displaced_pulse_in_a_long_log_is_a_fault_and_warned(tmp_path):
    """The look-elsewhere reach only forgives what noise can do: a pulse moved by 20 sigma
    in a 20 000-revolution log is excluded as a fault, named by its line and warned of."""
    from align.warnings import gonio_warnings
    from goniometry.exclusions import R_TAIL

    sim = simulate(GonioSpec(revolutions=20000, jitter_rad=1 * ARCSEC, seed=5))
    p = write_log(sim, tmp_path / "long.csv")
    sigma = read_revolutions(p, N_FACES).sigma_counts
    row = 4 * 9000 + 1  # face 1's pulse in revolution ~9000
    _displace_pulse(p, row, round(20 * sigma))
    run = measure_log(p, N_FACES, 50.45 * DEG)
    ex = run.summary.exclusions
    faults = {why: lines for why, lines in ex.lines.items() if why != R_TAIL}
    assert faults and all(abs(lines[0] - (row + 2)) <= 1 for lines in faults.values()), faults
    assert ex.counts.get(R_TAIL, 0) <= 1  # the clean rest: at most the noise's own tail
    assert run.summary.excluded_revolutions >= 1
    assert any("pulse faults" in w for w in gonio_warnings(run))


@pytest.mark.slow
def test_long_clean_jittery_logs_are_never_warned_of_pulse_faults(tmp_path):
    """30 clean 60 000-revolution logs with 3" autocollimator jitter (sigma ~2.4 counts):
    the noise passes 5 sigma somewhere in about half of them (the revolution is excluded and
    listed as the noise's tail), yet no log is warned of pulse faults and every angle stays
    within 4 u of the truth."""
    from align.warnings import gonio_warnings
    from goniometry.exclusions import R_TAIL

    tails = 0
    for seed in range(30):
        sim = simulate(GonioSpec(revolutions=60000, jitter_rad=3 * ARCSEC, seed=1000 + seed))
        p = write_log(sim, tmp_path / f"l{seed}.csv")
        run = measure_log(p, N_FACES, 50.45 * DEG)
        ex = run.summary.exclusions.counts
        assert set(ex) <= {R_TAIL}, dict(ex)
        tails += ex.get(R_TAIL, 0)
        assert not [w for w in gonio_warnings(run) if "pulse faults" in w]
        truth = np.array(sim["truth"]["angles_rad"])
        assert np.all(np.abs(run.angles.angles_rad - truth) < 4 * run.angles.u_rad)
        p.unlink()
    assert tails >= 3  # the case this guards was exercised (expected ~17)


@pytest.mark.parametrize("seed", range(16))
def test_one_mislabelled_counter_is_one_row(seed, tmp_path):
    """One row's counter id flipped (in the head before the first reference mark too, with
    and without times, both directions): three equal ids in a row, and only the middle one
    is wrong — exactly that row is listed (before: it and the next, 14 of 16 logs)."""
    rng = np.random.default_rng(3000 + seed)
    i = int(rng.integers(1, 4)) if seed % 4 == 0 else int(rng.integers(8, 60 * 4 - 8))
    spec = GonioSpec(revolutions=60, rev_per_s=float(rng.uniform(0.3, 3)),
                     direction=int(rng.choice([-1, 1])), arm_face=int(rng.integers(0, 4)),
                     faults=(("counter_swap", i, 0),), seed=seed, with_time=seed % 3 != 0)
    sim = simulate(spec)
    run = measure_log(write_log(sim, tmp_path / "s.csv"), N_FACES, spec.latitude_deg * DEG,
                      direction=spec.direction)
    ex = run.summary.exclusions.lines
    listed = sorted(ex.get(R_LABEL, []) + ex.get(R_LOST, []))
    assert listed == [f["row"] + 2 for f in sim["truth"]["faults"]], dict(ex)
