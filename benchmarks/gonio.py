"""Laser goniometry: accuracy against truth and the quantisation limit, and streaming speed.

Run:  python3 benchmarks/gonio.py [--logs 50] [--pulses 1000000,10000000]

1. Over seeded clean logs (200 revolutions, 1 rev/s, jitter 0.1"): normalised errors of every
   face angle (RMS should be ~1) and the stated uncertainty against the quantisation limit
   q/sqrt(6)/sqrt(R).
   With pulse times and a steady table, the same logs through the pulse-time estimator
   (--steady-table): normalised errors, u against the jitter limit sqrt(2) sigma_j / sqrt(R),
   and the gain over the counts.
2. End to end, what the user runs: ``align gonio LOG --faces ref,z,y,x`` (no latitude: the
   loop runs) against ``pyarrow.csv.read_csv`` of the same file, each in fresh processes
   (imports included, interpreter start-up excluded), paired and interleaved; the ratio of
   the two and the peak RSS, for log lengths that show whether memory grows.
   ``--logs 0 --pulses 1e7,3e7`` runs only this part, ``--pulses 0`` only the first.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import benchpage
import numpy as np

ARCSEC = np.pi / 180 / 3600


def accuracy(n_logs: int) -> None:
    from align.gonio import measure_log
    from goniometry import face_angles, read_revolutions
    from synth.gonio import GonioSpec, simulate, write_log

    z, ratio, zt, rt, gain = [], [], [], [], []
    with tempfile.TemporaryDirectory() as d:
        for seed in range(n_logs):
            sim = simulate(GonioSpec(revolutions=200, seed=seed))
            p = write_log(sim, Path(d) / f"l{seed}.csv")
            fa = face_angles(read_revolutions(p, 4))
            truth = np.array(sim["truth"]["angles_rad"])
            z.append((fa.angles_rad - truth) / fa.u_rad)
            limit = 2 * np.pi / fa.counts_per_rev / np.sqrt(6) / np.sqrt(fa.revolutions)
            ratio.append(fa.u_rad / limit)
            run = measure_log(p, 4, steady_table=True)
            if run.timing_used:
                zt.append((run.angles.angles_rad - truth) / run.angles.u_rad)
                jit = GonioSpec().jitter_rad * np.sqrt(2) / np.sqrt(run.angles.revolutions)
                rt.append(run.angles.u_rad / jit)
                gain.append(fa.u_rad / run.angles.u_rad)
    z, ratio = np.array(z), np.array(ratio)
    print(f"== {n_logs} clean logs, 200 revolutions each ==")
    print(f"normalised errors: RMS {np.sqrt(np.mean(z**2)):.3f}, mean {z.mean():+.3f} "
          f"({z.size} angles)")
    limit = 1.696 / np.sqrt(6) / np.sqrt(200)
    print(f"stated u / (q/sqrt6/sqrtR): median {np.median(ratio):.2f}, 95th percentile "
          f"{np.percentile(ratio, 95):.2f} (q = 1.696\", limit {limit:.3f}\")")
    zt = np.array(zt)
    print(f"pulse times (--steady-table): used on {len(zt)} of {n_logs} logs; normalised errors "
          f"RMS {np.sqrt(np.mean(zt**2)):.3f}; u / jitter limit median {np.median(rt):.2f}; "
          f"u(counts) / u(times) median {np.median(gain):.1f}")


def _peak_rss_mb() -> float:
    """This process's own peak RSS. Not ru_maxrss: Linux carries that across fork+exec, so a
    child would report the parent's peak (here: the parent that generated the log)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _child(what: str, path: str) -> None:
    """One timed run in a fresh process, from before its imports (the interpreter's own
    start-up excluded): ``cli`` is exactly what ``align gonio LOG --faces ...`` runs;
    ``read_csv`` is pyarrow's whole-file reader on the same file."""
    t0 = time.perf_counter()
    if what == "cli":
        import contextlib
        import io

        from align.cli import main

        with contextlib.redirect_stdout(io.StringIO()):
            code = main(["gonio", path, "--faces", "ref,z,y,x"])
        assert code == 0, code
    else:
        import pyarrow.csv as pacsv

        pacsv.read_csv(path)
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)  # all threads (interpreter start-up too)
    print(json.dumps({"seconds": time.perf_counter() - t0, "rss_mb": _peak_rss_mb(),
                      "cpu_s": ru.ru_utime + ru.ru_stime}))


def write_big_log(path: Path, n: int) -> None:
    """A steady-table log of n pulses with 10 MHz time stamps, written in blocks by pyarrow
    (numpy.savetxt takes minutes at 1e8 rows)."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(0)
    pattern = np.array([191178, 190871, 191274, 191033])
    with pacsv.CSVWriter(path, pa.schema([("count", pa.int64()), ("counter", pa.int8()),
                                          ("ref", pa.int8()), ("t", pa.float64())])) as w:
        for s in range(0, n, 1 << 20):
            i = np.arange(s, min(n, s + (1 << 20)))
            t = np.round((i + 1) * 0.25 + rng.normal(0, 1e-7, i.size), 7)
            w.write(pa.table({"count": pattern[i % 4] + rng.integers(0, 2, i.size),
                              "counter": (i % 2 + 1).astype(np.int8),
                              "ref": (i % 4 == 3).astype(np.int8), "t": t}))


def throughput(lengths: list[int], repeats: int = 3) -> None:
    print("\n== one pass at parse speed: 'align gonio LOG --faces ref,z,y,x' vs "
          "pyarrow.csv.read_csv, fresh processes, imports included, interpreter start-up "
          "excluded ==")
    with tempfile.TemporaryDirectory() as d:
        for n in lengths:
            p = Path(d) / f"log{n}.csv"
            write_big_log(p, n)
            runs: dict[str, list] = {"cli": [], "read_csv": []}
            for _ in range(repeats):  # interleaved: this shared machine's speed varies
                for what in runs:
                    out = subprocess.run([sys.executable, __file__, "--child", what, str(p)],
                                         check=True, capture_output=True, text=True)
                    runs[what].append(json.loads(out.stdout.strip().splitlines()[-1]))
            cli = float(np.median([r["seconds"] for r in runs["cli"]]))
            rc = float(np.median([r["seconds"] for r in runs["read_csv"]]))
            ratio = np.median([a["seconds"] / b["seconds"]
                               for a, b in zip(runs["cli"], runs["read_csv"], strict=True)])
            cpu = {k: float(np.median([r["cpu_s"] for r in v])) for k, v in runs.items()}
            print(f"{n:>10d} rows ({p.stat().st_size / 1e6:.0f} MB): align gonio {cli:6.2f} s "
                  f"({n / cli / 1e6:.2f} M rows/s), read_csv {rc:6.2f} s; ratio {ratio:.2f} "
                  f"(median of {repeats} paired runs); CPU (all threads) align gonio "
                  f"{cpu['cli']:.2f} s, read_csv {cpu['read_csv']:.2f} s; peak RSS align gonio "
                  f"{max(r['rss_mb'] for r in runs['cli']):.0f} MB, read_csv "
                  f"{max(r['rss_mb'] for r in runs['read_csv']):.0f} MB")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", type=int, default=50)
    ap.add_argument("--pulses", default="1000000,10000000")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=2, metavar=("WHAT", "LOG"))
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    if args.logs:
        accuracy(args.logs)
    lengths = [int(float(v)) for v in args.pulses.split(",") if float(v) > 0]
    if lengths:
        throughput(lengths, args.repeats)


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: accuracy and streaming speed")
