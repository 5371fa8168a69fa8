"""Laser goniometry: false fault warnings on long clean logs (the noise's own tail).

Run:  python3 benchmarks/gonio_tails.py [--logs 30] [--revolutions 60000] [--jitter 3]

Seeded clean logs (no pulse fault) of many revolutions with autocollimator jitter: how many
revolutions the 5-sigma screen excludes, how they are listed (a pulse fault, or the noise's
tail in a log this long) and how many logs ``align`` would warn of pulse faults. A clean log
should be warned of none; what the screen excludes at 5 sigma is listed either way.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import benchpage
import numpy as np

from axisbase.units import DEG

ARCSEC = np.pi / 180 / 3600


def main() -> None:
    from align.gonio import measure_log
    from align.warnings import gonio_warnings
    from synth.gonio import GonioSpec, simulate, write_log

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=30)
    ap.add_argument("--revolutions", type=int, default=60000)
    ap.add_argument("--jitter", type=float, default=3.0, help="autocollimator jitter [arcsec]")
    a = ap.parse_args()
    why: Counter = Counter()
    warned = 0
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        for seed in range(a.logs):
            sim = simulate(GonioSpec(revolutions=a.revolutions, jitter_rad=a.jitter * ARCSEC,
                                     seed=1000 + seed))
            p = write_log(sim, Path(d) / f"l{seed}.csv")
            run = measure_log(p, 4, 50.45 * DEG)
            why.update(run.summary.exclusions.counts)
            warned += any("pulse faults" in w for w in gonio_warnings(run))
            p.unlink()
    print(f"{a.logs} clean logs x {a.revolutions} revolutions, jitter {a.jitter}\" "
          f"({time.perf_counter() - t0:.0f} s)")
    for reason, n in why.items():
        print(f"  {n} x {reason}")
    print(f"logs warned of pulse faults: {warned} of {a.logs}")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: false fault warnings on long clean logs")
