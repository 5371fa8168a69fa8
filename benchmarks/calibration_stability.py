"""A scale factor cycling with the room (issue 19): |err|/u with and without the declared
stability, on the paper's 14 poses and on the 28-pose plan.

Run:  python3 benchmarks/calibration_stability.py [--seeds 5] [--ppm 0 20 100]

synth's triad with ``scale_cycle`` 1e-4 (±100 ppm, 15 min period, a random phase), poses held
60 s with 30 s turns; truth: the scale factors at the run's mean scale, beta, biases. Per
pose set and declared stability: per seed, the effects the loop added, whether it flagged
structure, and the largest |err|/u over the nine parameters.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import benchpage

sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from align.calibration import calibrate  # noqa: E402
from align.calibration.plan import plan  # noqa: E402
from tests.align.test_calibration_stability import _cycled, _z  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--ppm", type=float, nargs="*", default=[0.0, 20.0, 100.0])
    a = ap.parse_args()
    for name, up in (("paper 14", None), ("plan 28", tuple(map(tuple, plan(28).up)))):
        for ppm in a.ppm:
            rows = []
            for seed in range(a.seeds):
                tr, poses, truth = _cycled(seed, up)
                cal = calibrate(poses, np.sign(tr.k), scale_stability_ppm=ppm)
                rows.append((tuple(e.name for e in cal.loop.effects),
                             cal.loop.unexplained_structure, float(np.abs(_z(cal, truth)).max())))
            zmax = [r[2] for r in rows]
            print(f"{name}, declared {ppm:g} ppm: max |z| per seed "
                  f"{' '.join(f'{z:.2f}' for z in zmax)} (worst {max(zmax):.2f}); structure "
                  f"flagged {sum(r[1] for r in rows)}/{len(rows)}; effects "
                  f"{[r[0] for r in rows if r[0]] or 'none'}", flush=True)


if __name__ == "__main__":
    benchpage.run(main, "Calibration: a scale factor cycling with the room")
