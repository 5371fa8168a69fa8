"""Effects the triad model may lack (issue 19): |err|/u, effect found, false alarms.

Run:  python3 benchmarks/calibration_effects.py [--seeds 20] [--control 100] [--poses paper|plan]
      [--scale-stability-ppm 20]  (the term ``align calibrate`` adds without a temperature
      column; without the flag, none, as the library)

Per class of tests/align/effects_cases.py (each effect rendered by synth in the sensor's
physics) over seeded tumbles: the RMS and max over seeds and the nine parameters of
|err| / u (scale factors, beta, biases), the fraction of seeds where the loop found the
class's effect, where it reported unexplained structure and where u was widened, and the
median and max over seeds and parameters of u over its noise-only value; and on the clean
control over --control seeds, the fraction with any effect (false effects) or with structure
(false structure flags).

``paper``: the seed paper's 14 cube poses in its order; ``plan``: ``align calibrate --plan 28``.
To measure another version of the calibration (e.g. main's), put its ``align`` first on
PYTHONPATH: the script puts this tree's root after PYTHONPATH's entries (and before an
installed copy), so PYTHONPATH's wins.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from pathlib import Path

import benchpage

# This tree before any installed copy, after PYTHONPATH's entries (another version put there
# wins).
sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

from tests.align.effects_cases import CLASSES, sweep  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--control", type=int, default=100)
    ap.add_argument("--poses", choices=("paper", "plan"), default="paper")
    ap.add_argument("--only", nargs="*", default=list(CLASSES))
    ap.add_argument("--scale-stability-ppm", type=float, default=None,
                    help="declare this scale stability (align calibrate's default without a "
                    "temperature column: 20); default: none (the library's)")
    a = ap.parse_args()
    up = None
    if a.poses == "plan":
        from align.calibration.plan import plan

        up = plan(28).up
    print(f"poses: {a.poses}; |err|/u over {a.seeds} seeds x 9 parameters")
    print(f"{'class':13s} {'RMS':>7s} {'max':>8s} {'found':>6s} {'struct':>7s} "
          f"{'widened':>8s} {'u/u_noise med':>13s} {'max':>8s} {'s':>6s}  "
          "effects added (most common)")
    for name in a.only:
        t0 = time.time()
        n = a.control if name == "clean" else a.seeds
        r = sweep(name, range(n), up=up, stability=a.scale_stability_ppm)
        found = f"{r['any_effect']:.0%}*" if name == "clean" else f"{r['found']:.0%}"
        print(f"{name:13s} {r['rms']:7.2f} {r['max']:8.2f} {found:>6s} {r['structure']:7.0%} "
              f"{r['widened']:8.0%} {r['u_ratio_median']:13.3g} {r['u_ratio_max']:8.3g} "
              f"{time.time() - t0:6.1f}  "
              f"{Counter(r['effects']).most_common(3)}", flush=True)
    print("* clean: the fraction of seeds with any effect added (false effects)")


if __name__ == "__main__":
    benchpage.run(main, "Calibration: effects the triad model may lack")
