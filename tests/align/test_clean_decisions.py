"""Statistics of the decisions: over clean synthetic sessions, the rate of false structure
flags, false effects, refusals (and, in the fusion, a source named) per stage stays within
the 1 % target at the default alpha. With N sessions, a stage whose true rate is 1 % shows
more than B of them with probability below 1e-3 (binomial): B = 3 of 40."""

from __future__ import annotations

import pytest
from scipy.stats import binom

from align.session import load_session, run_session
from align.session.decisions import STAGES, decisions
from synth.session import SessionSpec, write_session

SESSIONS = 40


@pytest.mark.slow
def test_clean_sessions_raise_few_false_alarms_per_stage(tmp_path):
    bound = int(binom.isf(1e-3, SESSIONS, 0.01))  # P(count > bound | 1 %) < 1e-3
    counts: dict[tuple[str, str], int] = {}
    for k in range(SESSIONS):
        d = tmp_path / f"s{k}"
        write_session(d, SessionSpec(seed=31000 + k))
        for stage, got in decisions(run_session(load_session(d))).items():
            for what, flag in got.items():
                counts[stage, what] = counts.get((stage, what), 0) + int(flag)
    print({f"{s} {w}": c for (s, w), c in counts.items()}, f"bound {bound} of {SESSIONS}")
    assert {s for s, _ in counts} == set(STAGES)
    over = {k: c for k, c in counts.items() if c > bound}
    assert not over, (over, bound)
