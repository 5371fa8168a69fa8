"""Statistics of the decisions (issue 19, point 5): over clean inputs each stage's false
"structure" flags, false effects, widenings, refusals and faults stay within 1 % at the
default alpha (1e-3), per stage, run on its own inputs; and with the same thresholds each
stage still finds a real effect of moderate size (positive controls).

Each stage's test counts the decisions over N seeded clean cases, prints the rows of the
table in ``docs/decisions.md`` (count/N, rate, one-sided 95 % Clopper-Pearson upper bound)
and fails when a count exceeds what a true rate of 1 % shows with probability below 1e-3
(one-sided binomial; the false-fail probability of each decision's check). With N = 300 that
is more than 10 events; 0 of 300 bounds the rate below 1.0 % (95 %).

Reproduce the table: ``python3 -m pytest -q -s -m slow tests/align/test_decision_rates.py``.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from align.calibration import calibrate
from align.fusion.observations import LEVEL, TILT
from align.session import load_session, run_session
from align.session.decisions import STAGES, alarm_limit, decisions
from axisbase.units import ARCSEC
from synth.tumble import TumbleSpec, tumble
from tests.align import decision_cases as dc
from tests.align.effects_cases import EXPECTED, poses_of, triad_of
from tests.align.newcomer_cases import write_session as write_newcomer

N_CHEAP = 300
"""Clean cases of each input kind of a cheap stage (0 events: rate < 1.0 % at 95 %)."""


def _bools(d: dict) -> dict[str, bool]:
    return {k: v for k, v in d.items() if isinstance(v, bool)}


def test_alarm_limit_is_the_binomial_quantile():
    """The count limit: a 1 % rate exceeds it with probability < 1e-3, and only just."""
    from scipy.stats import binom

    for n in (40, 100, 300, 1000):
        k = alarm_limit(n)
        assert binom.sf(k, n, 0.01) < 1e-3 <= binom.sf(k - 1, n, 0.01)
    assert alarm_limit(300) == 10


@pytest.mark.slow
def test_calibration_false_alarms(tmp_path):
    kinds = {
        "14 cube poses (means)": lambda s: dc.calibration_poses(s),
        "28-pose plan (means)": lambda s: dc.calibration_poses(s, "plan28"),
        "14 poses, per-sample file": lambda s: dc.calibration_samples(s, tmp_path),
        "continuous recording, detected": lambda s: dc.calibration_recording(s, tmp_path),
    }
    over = {}
    for k, (inputs, run) in enumerate(kinds.items()):
        t = dc.tally("calibration", inputs, run, range(40000 + 1000 * k,
                                                        40000 + 1000 * k + N_CHEAP))
        over.update({(inputs, d): c for d, c in t.over().items()})
    assert not over, over


@pytest.mark.slow
def test_calibration_finds_the_effects_of_issue_19():
    """Positive control: on the 28-pose plan each effect of issue 19 (K_xy 300 µg/g²,
    hysteresis 50 µg, a 100 ppm scale drift over the run) is added in >= 90 % of seeds."""
    for name in ("cross", "hysteresis", "scale_drift"):
        expected, found = EXPECTED[name], 0
        for seed in range(10):
            tr = triad_of(name)
            d = tumble(TumbleSpec(triad=tr, seed=seed, up=dc.PLAN28))
            cal = calibrate(poses_of(d), np.sign(tr.k))
            found += expected in [e.name for e in cal.loop.effects]
        print(f"| calibration | 28-pose plan, {name} | {expected} added | {found}/10 |")
        assert found >= 9, (name, found)


N_GONIO_LOOP = 1000
"""Clean logs without --latitude (the revolution loop runs: structure and effect decisions).
300 bounded a rate seen once or twice only below 1.6-2.1 % (95 %); 1000 (0.1 s of CPU a log)
bound up to 4 events below 1 %. Measured (seeds 50000-50999): structure 3/1000 (95 % upper
0.77 %), effect 5/1000 (upper 1.05 %: just above 1 %; docs/false-alarms.md)."""


@pytest.mark.slow
def test_goniometer_false_alarms(tmp_path):
    over, z = {}, []
    for lat in (True, False):
        def run(s, lat=lat):
            out = dc.gonio_log(s, tmp_path, lat)
            z.append(out["z_max"])
            return _bools(out)

        inputs = "120 rev, " + ("--latitude" if lat else "no latitude")
        n = N_CHEAP if lat else N_GONIO_LOOP
        t = dc.tally("goniometer", inputs, run, range(50000 + 1000 * lat,
                                                       50000 + 1000 * lat + n))
        over.update({(inputs, d): c for d, c in t.over().items()})
    # The angles on clean logs: the largest of 4 |error|/u per log above 3.5 for a N(0,1)
    # error 0.19 % of logs; allow 1 %.
    print(f"goniometer: largest |error|/u of a log > 3.5 in {np.mean(np.array(z) > 3.5):.2%}")
    assert not over, over
    assert np.mean(np.array(z) > 3.5) <= 0.01


@pytest.mark.slow
def test_goniometer_finds_dropouts(tmp_path):
    """Positive control (issue 19, point 3): 3-20 rows lost anywhere in the log (the
    reference face's row included), with and without --latitude: the revolutions are
    excluded (fault found) and the angles stay within their u."""
    found, z = 0, []
    n = 40
    for k in range(n):
        rows = 3 + k % 18
        out = dc.gonio_log(60000 + k, tmp_path, latitude=bool(k % 2), dropout=rows)
        found += out["fault found"]
        z.append(out["z_max"])
    print(f"| goniometer | drop-out of 3-20 rows | fault found | {found}/{n} | "
          f"max \\|error\\|/u {max(z):.2f} |")
    assert found >= 0.9 * n and max(z) < 4.5


@pytest.mark.slow
def test_marks_false_alarms():
    over = {}
    for lens, n in ((False, N_CHEAP), (True, 120)):
        inputs = "declared lens" if lens else "no lens"
        t = dc.tally("marks", inputs, lambda s, lens=lens: _bools(dc.mark_image(s, lens)),
                     range(70000 + 1000 * lens, 70000 + 1000 * lens + n))
        # lens-limited: the declared lens's u against its limit, not a test on the image.
        over.update({(inputs, d): c for d, c in t.over(exempt=("lens-limited",)).items()})
    assert not over, over


@pytest.mark.slow
def test_marks_find_a_bend():
    """Positive control: a mark bowed by 2 px (no lens) is called bent in >= 90 %."""
    found = sum(dc.mark_image(s, bow_px=2.0)["bend"] for s in range(80000, 80020))
    print(f"| marks | bowed 2 px, no lens | bend added | {found}/20 |")
    assert found >= 18


@pytest.mark.slow
def test_fusion_false_alarms(tmp_path):
    """Whole clean sessions (every stage's decisions in a session, the fusion end to end),
    and draws of their observations around the declared model (the fusion's decisions)."""
    sessions = [dc.session(31000 + k, tmp_path) for k in range(12)]
    whole = {st: dc.Tally(st, "whole session") for st in STAGES}
    for _, res in sessions:
        for st, got in decisions(res).items():
            whole[st].add(got)
    for t in whole.values():
        print("\n".join(t.rows()))
    over = {(t.stage, d): c for t in whole.values() for d, c in t.over().items()}
    assert not over, over
    cases = [dc.fusion_case(s, res) for s, res in sessions]
    t = dc.tally("fusion", "observations drawn with their u (12 sessions)",
                 lambda k: dc.fusion_draw(cases[k % len(cases)], k), range(408))
    assert not t.over(), t.counts


@pytest.mark.slow
def test_fusion_finds_level_and_creep(tmp_path):
    """Positive controls (issue 19, point 4): a platform 30″ out of level is found as the
    levelling effect; a 30″ creep between the images and the static readings names the
    sources that disagree."""
    level = creep = 0
    for k in range(3):
        _, res = dc.session(700 + k, tmp_path, {"platform_level_x": 30.0,
                                                "platform_level_y": -20.0})
        level += LEVEL in [e.name for e in res.fusion.loop.effects]
        _, res = dc.session(710 + k, tmp_path, {"creep_y": 30.0 * (-1) ** k})
        d = res.fusion.disagreement
        creep += d is not None and {d.source, *d.also} == {"camera", "platform static"}
    print(f"| fusion | 30″ out of level | {LEVEL} added | {level}/3 |")
    print(f"| fusion | 30″ creep about Y | camera and static named | {creep}/3 |")
    assert level == 3 and creep == 3


N_NEWCOMER = 300
"""Whole sessions written as a newcomer does (each ~0.1 s of CPU beside the file writing)."""


@pytest.mark.slow
def test_newcomer_sessions_false_alarms(tmp_path):
    """Clean sessions from the docs alone (``tests/align/newcomer_cases.py``: readings in
    counts, 20 samples a pose, 60 revolutions): every stage's decisions and the session's
    not-ok, over N_NEWCOMER seeds, within 1 % (more than 10 of 300 fails). Before the
    fusion took the poses' 20-sample u as estimated (19 dof), 20-sample poses gave it false
    table tilts and periodogram flags (docs/false-alarms.md)."""
    whole = {st: dc.Tally(st, "newcomer session") for st in STAGES}
    session = dc.Tally("session", "newcomer session")
    for k in range(N_NEWCOMER):
        d = tmp_path / f"n{k}"
        write_newcomer(d, 19000 + k)
        res = run_session(load_session(d))
        for st, got in decisions(res).items():
            whole[st].add(got)
        session.add({"not ok": not res.ok})
        shutil.rmtree(d)
    for t in (*whole.values(), session):
        print("\n".join(t.rows()))
    over = {(t.stage, d): c for t in (*whole.values(), session) for d, c in t.over().items()}
    assert not over, over


@pytest.mark.slow
def test_newcomer_sessions_find_a_table_tilt(tmp_path):
    """Positive control with the same thresholds: a table axis tilted by (12″, −8″) (the
    levelled poses' gravity turning with the table; ~1.9″ u a component) is found in 10 of
    10 sessions, each component within 4 u of the truth."""
    found = 0
    for k in range(10):
        d = tmp_path / f"t{k}"
        write_newcomer(d, 19500 + k, tilt_arcsec=(12.0, -8.0))
        loop = run_session(load_session(d)).fusion.loop
        if TILT in [e.name for e in loop.effects]:
            comp = {c: (v, u) for c, v, u in loop.after.components[TILT]}
            found += all(abs(comp[c][0] / ARCSEC - t) <= 4 * comp[c][1] / ARCSEC
                         for c, t in (("x", 12.0), ("y", -8.0)))
    print(f"| fusion | newcomer session, table tilt (12″, −8″) | {TILT} added | {found}/10 |")
    assert found == 10
