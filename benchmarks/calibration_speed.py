"""CPU time of one calibration (the ML stage, the residual loop, the widening) on a tumble.

Run:  python3 benchmarks/calibration_speed.py [TUMBLE.csv] [--repeat 10] [--profile]

TUMBLE.csv: ``pose,ux,uy,uz,t`` samples (default: the demo's tumble, written to a temporary
folder by ``align synth session --seed 1``). The poses are the per-pose means of the file's
samples (the same for every version of the calibration), so the time is the calibration's
alone, not the reader's or the import's. To time another version (e.g. main's before the
effects, 53a6fe6), put its ``align`` on PYTHONPATH: the script puts this tree's root after
PYTHONPATH's entries (and before an installed copy).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import benchpage
import numpy as np

# This tree before any installed copy, after PYTHONPATH's entries (another version put there
# wins).
sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

from align.calibration import calibrate, poses_from_samples  # noqa: E402


def demo_tumble() -> Path:
    """The demo session's tumble (``align synth session --seed 1``) in a temporary folder."""
    folder = Path(tempfile.mkdtemp(prefix="align-speed-")) / "session"
    subprocess.run([sys.executable, "-m", "align", "synth", "session", str(folder), "--seed",
                    "1"], check=True, capture_output=True)
    return folder / "tumble.csv"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tumble", nargs="?")
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--sign", type=float, default=-1.0, help="the scale factors' sign")
    ap.add_argument("--profile", action="store_true")
    a = ap.parse_args()
    path = Path(a.tumble) if a.tumble else demo_tumble()
    d = np.loadtxt(path, delimiter=",", skiprows=1)
    poses = poses_from_samples(d[:, 0].astype(int), d[:, 1:4], d[:, 4])
    signs = (a.sign,) * 3
    calibrate(poses, signs)  # warm caches (imports, first calls)
    times = []
    for _ in range(a.repeat):
        t0 = time.process_time()
        cal = calibrate(poses, signs)
        times.append(time.process_time() - t0)
    print(f"{path}: {len(poses.u)} poses; calibrate: median {np.median(times) * 1e3:.0f} ms CPU "
          f"(min {min(times) * 1e3:.0f}, {a.repeat} runs); effects "
          f"{[e.name for e in cal.loop.effects]}")
    if a.profile:
        cProfile.runctx("calibrate(poses, signs)", globals(), locals(), "/tmp/calibrate.prof")
        pstats.Stats("/tmp/calibrate.prof").sort_stats("cumulative").print_stats(25)


if __name__ == "__main__":
    benchpage.run(main, "Calibration: CPU time of one calibration")
