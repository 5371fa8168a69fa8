"""What one session costs inside a batch: ``align run S --json X [--report R]`` on one
synthetic session, in one warm process (start-up excluded, as in a batch worker), and where
the time goes.

Run:  python3 benchmarks/session_cost.py [--runs 5] [--seed 5]

Printed: the median (and best) CPU time and wall time per session of the JSON-only run and
of the run with the HTML report — CPU time is the figure to quote on a shared host (wall
time counts the other users' load too) — and, from one cProfile run of each, the share of
the time per package (own time of its functions: ``imaging``, ``align.marks``,
``align.loop``, matplotlib, numpy/scipy, ...).
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import io
import pstats
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import benchpage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from align.cli import main as align  # noqa: E402
from synth.session import SessionSpec, write_session  # noqa: E402

GROUPS = (("/imaging/", "imaging (mark detection, centres)"),
          ("/align/marks", "align.marks"), ("/align/loop/", "align.loop (residual loops)"),
          ("/align/fusion/", "align.fusion"), ("/align/calibration/", "align.calibration"),
          ("/goniometry/", "goniometry"), ("/align/", "align (other)"),
          ("/axisbase/", "axisbase (tables, output)"), ("matplotlib", "matplotlib (report)"),
          ("PIL", "PIL (PNG encoding)"), ("/scipy/", "scipy"), ("/numpy/", "numpy"),
          ("cv2", "OpenCV"))


def _group(filename: str, name: str) -> str:
    if filename == "~":  # built-ins: name them by their module where the name says
        for key, label in (("numpy", "numpy"), ("ImagingEncoder", "PIL (PNG encoding)"),
                           ("ft2font", "matplotlib (report)"), ("cv2", "OpenCV"),
                           ("_agg", "matplotlib (report)"), ("scipy", "scipy")):
            if key in name:
                return label
        return "built-ins (C: OpenCV, numpy, hashing, ...)"
    for key, label in GROUPS:
        if key in filename:
            return label
    return "other"


def shares(prof: cProfile.Profile) -> list[tuple[str, float]]:
    st = pstats.Stats(prof)
    acc: dict[str, float] = defaultdict(float)
    for (filename, _, name), (_, _, tottime, _, _) in st.stats.items():  # type: ignore[attr-defined]
        acc[_group(filename, name)] += tottime
    total = sum(acc.values())
    return sorted(((k, v / total) for k, v in acc.items()), key=lambda kv: -kv[1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seed", type=int, default=5)
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="align-cost-"))
    session = work / "session"
    write_session(session, SessionSpec(seed=a.seed))
    k = [0]

    def run(report: bool) -> None:
        k[0] += 1
        argv = ["run", str(session), "--json", str(work / f"r{k[0]}.json"), "-q"]
        if report:
            argv += ["--report", str(work / f"r{k[0]}.html")]
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            align(argv)

    for report in (False, True):
        run(report)  # imports and caches warm, as in a batch worker after its first session
        wall, cpu = [], []
        for _ in range(a.runs):
            t0, c0 = time.perf_counter(), time.process_time()
            run(report)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        prof = cProfile.Profile()
        prof.enable()
        run(report)
        prof.disable()
        what = "align run --json --report" if report else "align run --json"
        print(f"{what}: CPU {statistics.median(cpu):.2f} s median (best {min(cpu):.2f}), "
              f"wall {statistics.median(wall):.2f} s median (best {min(wall):.2f}) per "
              f"session, {a.runs} runs")
        for label, f in shares(prof)[:8]:
            print(f"    {f * 100:5.1f} %  {label}")


if __name__ == "__main__":
    benchpage.run(main, "What one session costs in a batch")
