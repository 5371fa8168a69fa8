"""Laser goniometry: is u honest on short logs? Normalised errors z = (angle - truth) / u by
regime over the seeded logs of the fault-injection plan (tests/goniometry/test_faults.py:
120 revolutions, 0.2-5 rev/s, half on an unsteady table — 2 % ripple locked to the angle and
1 % wander — both directions, latitude given).

Run:  python3 benchmarks/gonio_u.py [--logs 600] [--faulty]

Without ``--faulty`` the fault-free twins (the same table, ring laser and jitter); with it
the logs with their faults. Prints, per regime: angles, RMS z, counts beyond 3 and 4 u, the
worst |z| and the median u over the quantisation limit q / sqrt(6) / sqrt(R); then which
Type A method the logs used and the worst logs. About 0.15 s a log.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path

import benchpage
import numpy as np

from axisbase.units import DEG

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "goniometry"))


def scan(n_logs: int, faulty: bool) -> list[dict]:
    from test_faults import N_FACES, fault_plan

    from align.gonio import measure_log
    from synth.gonio import simulate, write_log

    rows = []
    with tempfile.TemporaryDirectory() as d:
        for seed in range(n_logs):
            spec = fault_plan(seed)
            if not faulty:
                spec = replace(spec, faults=())
            sim = simulate(spec)
            p = write_log(sim, Path(d) / f"l{seed}.csv")
            run = measure_log(p, N_FACES, spec.latitude_deg * DEG, direction=spec.direction)
            p.unlink()
            fa = run.angles
            truth = np.array(sim["truth"]["angles_rad"])
            limit = fa.quantum_rad / np.sqrt(6) / np.sqrt(fa.revolutions)
            rows.append({"seed": seed, "rate": spec.rev_per_s, "unsteady": spec.ripple > 0,
                         "direction": spec.direction, "z": (fa.angles_rad - truth) / fa.u_rad,
                         "u_lim": fa.u_rad / limit,
                         # (getattr: the script also runs on versions before these fields)
                         "method": getattr(fa, "type_a_method", "batch means"),
                         "jitter": getattr(fa, "jitter_counts", float("nan"))})
    return rows


def show(name: str, sel: list[dict]) -> None:
    if not sel:
        return
    z = np.concatenate([r["z"] for r in sel])
    ul = np.concatenate([r["u_lim"] for r in sel])
    print(f"{name:26s} {len(sel):5d} {z.size:6d} {np.sqrt(np.mean(z**2)):7.3f} "
          f"{np.sum(abs(z) > 3):5d} {np.sum(abs(z) > 4):5d} {abs(z).max():7.2f} "
          f"{np.median(ul):9.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", type=int, default=600)
    ap.add_argument("--faulty", action="store_true", help="the logs with their faults")
    a = ap.parse_args()
    rows = scan(a.logs, a.faulty)
    kind = "faulty logs" if a.faulty else "fault-free twins"
    print(f"== {a.logs} {kind} of the fault plan ==")
    print(f"{'regime':26s} {'logs':>5s} {'angles':>6s} {'RMS z':>7s} {'>3u':>5s} {'>4u':>5s} "
          f"{'max|z|':>7s} {'med u/lim':>9s}")
    show("all", rows)
    for unsteady in (False, True):
        for lo, hi in ((0.2, 0.5), (0.5, 1.5), (1.5, 5.01)):
            show(f"{'unsteady' if unsteady else 'steady'} {lo}-{hi:g} rev/s",
                 [r for r in rows if r["unsteady"] == unsteady and lo <= r["rate"] < hi])
    for d in (-1, 1):
        show(f"direction {d:+d}", [r for r in rows if r["direction"] == d])
    print("Type A method (logs):", dict(Counter(r["method"] for r in rows)))
    for r in sorted(rows, key=lambda r: -np.max(np.abs(r["z"])))[:5]:
        print(f"  seed {r['seed']}: {r['rate']:.2f} rev/s, "
              f"{'unsteady' if r['unsteady'] else 'steady'}, z {np.round(r['z'], 2)}, "
              f"{r['method']}, jitter {r['jitter']:.3f} count")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: is u honest on short logs?")
