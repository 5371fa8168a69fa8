"""Start-up time of the ``align`` command (what a user waits for on ``align --help``).

Fresh processes, median (and best) of N runs each:

* ``align --help`` and ``align gonio --help`` as shipped (heavy imports deferred into the
  command functions);
* the obvious alternative: the same help after importing the pipeline eagerly, as the CLI did
  before (numpy, scipy, pyarrow, OpenCV, matplotlib through align.session/marks/plots).

Usage: ``python3 benchmarks/cli_startup.py [N] [--markdown PATH]`` (default 7). On a loaded
host the figures vary; the ratio within one run is the figure to quote. ``--markdown``: also
a generated page (:mod:`benchpage`; ``docs/perf/cli_startup.md``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import benchpage

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
EAGER = ("import align.session, align.marks, align.plots, align.calibration, align.gonio; "
         "import sys; sys.argv = ['align', '--help']; from align.cli import main; main()")


def timed(cmd: list[str], n: int) -> tuple[float, float]:
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        subprocess.run(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       check=False)
        out.append(time.perf_counter() - t0)
    return statistics.median(out), min(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("n", nargs="?", type=int, default=7, help="runs of each command")
    args = ap.parse_args()
    n = args.n
    py = sys.executable
    rows = [("align --help", [py, "-m", "align", "--help"]),
            ("align gonio --help", [py, "-m", "align", "gonio", "--help"]),
            ("align --version", [py, "-m", "align", "--version"]),
            ("bare python3 -c pass", [py, "-c", "pass"]),
            ("eager imports + --help (the old way)", [py, "-c", EAGER])]
    res = {name: timed(cmd, n) for name, cmd in rows}
    print("| command | median [ms] | best [ms] |")
    print("|---|---|---|")
    for name, (med, best) in res.items():
        print(f"| `{name}` | {med * 1000:.0f} | {best * 1000:.0f} |")
    ratio = res["eager imports + --help (the old way)"][0] / res["align --help"][0]
    print(f"\neager / deferred (median): {ratio:.1f}x, {n} fresh processes each; target: "
          "align --help < 500 ms")

if __name__ == "__main__":
    benchpage.run(main, "Start-up time of the align command")
