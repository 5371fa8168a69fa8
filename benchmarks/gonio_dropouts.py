"""Whole-revolution drop-outs, stitched or excluded: angles against truth and the twin log.

40 logs of 120 revolutions with times, measured with ``--latitude``, 0.5-2 rev/s, a 2 %
speed ripple and 1 % wander; 4, 8 or 12 rows (whole revolutions) lost somewhere in each.
Prints the RMS error [″] of the drop-out logs and of their drop-out-free twins, and the RMS
and worst |error|/u of the drop-out logs. ``--root`` runs the pipeline of another checkout
(e.g. main, to see the stitched "before"); the logs come from this checkout's synth (which
imports nothing from the pipeline).

Run: ``python3 benchmarks/gonio_dropouts.py [--root /path/to/main] [--logs 40]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import benchpage
import numpy as np

from axisbase.units import DEG

HERE = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(HERE), help="checkout whose pipeline measures")
    ap.add_argument("--logs", type=int, default=40)
    a = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from synth.gonio import ARCSEC, GonioSpec, drop_out, simulate, write_log

    for m in [m for m in sys.modules if m.split(".")[0] in ("align", "goniometry", "axisbase")]:
        del sys.modules[m]
    sys.path.insert(0, a.root)
    from align.gonio import measure_log

    err, twin, z = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(a.logs):
            rng = np.random.default_rng(5000 + seed)
            spec = GonioSpec(revolutions=120, rev_per_s=float(rng.uniform(0.5, 2)), seed=seed,
                             ripple=0.02, wander=0.01, latency_s=0.0)
            sim = simulate(spec)
            truth = np.array(sim["truth"]["angles_rad"])
            k, r0 = int(rng.choice([4, 8, 12])), int(rng.integers(20, 400))
            for s, out in ((drop_out(sim, r0, k), err), (sim, twin)):
                p = write_log(s, Path(tmp) / f"{seed}_{len(out)}_{s is sim}.csv")
                run = measure_log(p, 4, spec.latitude_deg * DEG, direction=spec.direction)
                out.append(run.angles.angles_rad - truth)
                if s is not sim:
                    z.append(out[-1] / run.angles.u_rad)
    e, t, z = np.array(err), np.array(twin), np.array(z)
    print(f"{a.root}: drop-out logs RMS error {np.sqrt(np.mean(e**2)) / ARCSEC:.3f}″ (twins "
          f"{np.sqrt(np.mean(t**2)) / ARCSEC:.3f}″), RMS |error|/u {np.sqrt(np.mean(z**2)):.2f}, "
          f"max {np.abs(z).max():.2f}")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: whole-revolution drop-outs")
