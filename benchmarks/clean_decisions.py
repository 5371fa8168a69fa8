"""False alarms of the decisions on clean synthetic sessions, per stage.

Over N clean sessions (``synth.session``, no effect put in), counts per stage
(calibration, goniometer, marks, fusion) how many sessions the stage

* flags with unexplained structure (the loop's residual test at the default alpha),
* adds an effect to (an effect the data do not have: a false effect),
* refuses (a stage error, or the fusion's gross disagreement),

and, for the fusion, how many name a disagreeing source. Prints one line per stage with the
rates and the 95 % upper bound of each (Clopper-Pearson). The target is <= 1 % per stage;
each stage on its own cheap inputs, with N large enough to show it:
``tests/align/test_decision_rates.py`` (docs/decisions.md).

Run: ``python3 benchmarks/clean_decisions.py --sessions 100 --seed0 20000`` (~8 s a session).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import benchpage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from align.session import load_session, run_session  # noqa: E402
from align.session.decisions import STAGES, decisions, upper95  # noqa: E402
from synth.session import SessionSpec, write_session  # noqa: E402


def run(sessions: int, seed0: int, folder: Path) -> dict[str, dict[str, int]]:
    counts = {s: {} for s in STAGES}
    for k in range(sessions):
        d = folder / f"s{k}"
        write_session(d, SessionSpec(seed=seed0 + k))
        for stage, got in decisions(run_session(load_session(d))).items():
            for what, flag in got.items():
                counts[stage][what] = counts[stage].get(what, 0) + int(flag)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sessions", type=int, default=100)
    ap.add_argument("--seed0", type=int, default=20000)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        counts = run(a.sessions, a.seed0, Path(tmp))
    n = a.sessions
    for stage in STAGES:
        print(f"{stage:12s} " + "; ".join(
            f"{what} {k}/{n} ({100 * k / n:.1f} %, 95 % upper {100 * upper95(k, n):.1f} %)"
            for what, k in counts[stage].items()))


if __name__ == "__main__":
    benchpage.run(main, "Decisions: false alarms on clean sessions")
