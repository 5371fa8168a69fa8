"""The goniometer loop's scale_drift decision: its null distribution and its power.

On clean logs (``tests/align/decision_cases.gonio_spec``: 120 revolutions at 0.5-2 rev/s, 2 %
ripple, 1 % wander, no latitude) the F-test of a trend in time on the declared fit, p per
log: the fraction below 1e-3, 1e-2, 0.05, 0.1 against a uniform's (issue 19: the tail is
heavier — the counter's floor/ceiling stretches). Then how often the loop adds scale_drift
on the same seeds with a ring-laser scale drift (synth's ``kappa_per_s``: the scale factor's
relative drift per second; until 2026-11-26 counts per revolution drifted at twice it),
given per revolution so that every speed sees the same drift per revolution, and on clean
logs.
Compare two trees: ``PYTHONPATH=../main-checkout python3 benchmarks/gonio_scale_drift.py``.

Run: ``python3 benchmarks/gonio_scale_drift.py [--n 1000] [--power-n 200]``
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import benchpage
import numpy as np

from align.gonio_loop import SCALE, RevolutionStage, candidates, loop_gonio
from align.loop.loop import f_test
from goniometry import kept_table, read_revolutions
from synth.gonio import simulate
from tests.align.decision_cases import gonio_spec


def _kept(spec):
    return kept_table(read_revolutions(dict(simulate(spec)["rows"]), 4))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1000, help="clean logs (seeds 50000-)")
    ap.add_argument("--power-n", type=int, default=200, help="logs per drift (seeds 90000-)")
    a, _ = ap.parse_known_args()
    p = []
    for s in range(50000, 50000 + a.n):
        st = RevolutionStage(*_kept(gonio_spec(s)))
        f0 = st.fit(())
        term = next(c for c in candidates(st) if c.name == SCALE).build(f0)
        p.append(f_test(f0, st.fit([term]), 1))
    p = np.array(p)
    print(f"clean logs: {a.n}; p of a trend in time on the declared fit")
    print("| p below | fraction | uniform |")
    print("| --- | --- | --- |")
    for q in (1e-3, 1e-2, 0.05, 0.1):
        print(f"| {q:g} | {np.mean(p < q):.2%} | {q:.2%} |")
    print("| kappa per revolution | logs | scale_drift added |")
    print("| --- | --- | --- |")
    for kappa in (0.0, 5e-9, 1e-8, 2e-8):
        found = 0
        for s in range(90000, 90000 + a.power_n):
            spec = gonio_spec(s)
            rep = loop_gonio(*_kept(replace(spec, kappa_per_s=kappa * spec.rev_per_s)))
            found += SCALE in [e.name for e in rep.effects]
        print(f"| {kappa:g} | {a.power_n} | {found} |")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: the scale_drift decision's null distribution and power")
