"""Whole-revolution drop-outs in logs without times: what the tool sees, and what they cost.

Seeded logs (``tests/goniometry/stitch_cases.py``: 120 revolutions, 0.2-5 rev/s, half on an
unsteady table, jitter 0.05-0.4″) each lose 4-20 rows (1-5 whole revolutions, anywhere), and
are measured with their drop-out-free twins, every other one with ``--latitude`` (without
times it is not applied). Prints for the stitched logs and the twins the RMS and largest
|error|/u over the angles, the share of logs whose drop-out is named (R_DROPOUT), and the
share whose floors leave the phase path (type A "batch means (floors off the phase path)").
``--root`` runs the pipeline of another checkout (e.g. main, for "before").

Run: ``python3 benchmarks/gonio_stitched.py [--root /path/to/main] [--logs 60]``
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
    ap.add_argument("--logs", type=int, default=60)
    a = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from synth.gonio import ARCSEC, write_log
    from tests.goniometry.stitch_cases import N_FACES, stitched_case

    for m in [m for m in sys.modules if m.split(".")[0] in ("align", "goniometry", "axisbase")]:
        del sys.modules[m]
    sys.path.insert(0, a.root)
    from align.gonio import measure_log

    z = {"stitched": [], "twin": []}
    err = {"stitched": [], "twin": []}
    named = {"stitched": 0, "twin": 0}
    off = {"stitched": 0, "twin": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(a.logs):
            spec, twin, cut, k, r0 = stitched_case(seed)
            lat = spec.latitude_deg * DEG if seed % 2 else None
            for key, sim in (("stitched", cut), ("twin", twin)):
                run = measure_log(write_log(sim, Path(tmp) / f"{key}{seed}.csv"), N_FACES,
                                  lat, direction=spec.direction)
                truth = np.array(sim["truth"]["angles_rad"])
                z[key].append((run.angles.angles_rad - truth) / run.angles.u_rad)
                err[key].append(run.angles.angles_rad - truth)
                named[key] += any("drop-out" in r for r in run.summary.exclusions.counts)
                off[key] += "off the phase path" in run.angles.type_a_method
    print(f"{a.root}: {a.logs} logs without times, 4-20 rows (whole revolutions) lost")
    print("| logs | RMS error [″] | RMS abs(error)/u | max abs(error)/u | drop-out named | "
          "floors off path |")
    print("| --- | --- | --- | --- | --- | --- |")
    for key in ("stitched", "twin"):
        v = np.array(z[key])
        e = np.sqrt(np.mean(np.array(err[key]) ** 2)) / ARCSEC
        print(f"| {key} | {e:.3f} | {np.sqrt(np.mean(v**2)):.3f} | {np.abs(v).max():.2f} | "
              f"{named[key]}/{a.logs} | {off[key]}/{a.logs} |")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: whole-revolution drop-outs without times")
