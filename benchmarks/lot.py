"""A production lot: ``align run`` over 200 synthetic sessions, on 1 and 2 local worker
processes and on a 2-worker Dask ``LocalCluster``.

Run:  python3 benchmarks/lot.py [--sessions 200] [--distinct 20] [--bad 2] [--repeat 1]
      [--report]

Each configuration is the command a user runs, end to end in a fresh process
(``align run S1 … S200 --json OUT --calibration OUT [--jobs N | --scheduler ADDRESS]``),
timed by wall clock; the Dask cluster is started beforehand (as a site's cluster would be)
and its start-up is printed apart. ``--distinct`` seeded sessions are synthesised
(``synth.session``) and copied to make up the lot (each copy costs a full run: nothing is
cached); ``--bad`` of them have their counter log removed, so they fail (a failing session
must not stop the others). Printed per configuration: wall time, seconds per session, the
speed-up over one local process, and the sessions done / failed as the command reports them
(``--repeat``: the configurations run in turn, the median wall time is printed).
The per-session cost on one core is the 1-process wall time over the lot size (it includes
the command's start-up, spread over the lot).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import benchpage

ROOT = Path(__file__).resolve().parents[1]
# The command, the cluster's workers and this process import this checkout.
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
ENV = dict(os.environ)
sys.path.insert(0, str(ROOT))  # the scheduler, in this process, unpickles the tasks too


def _synth(args: tuple[str, int]) -> str:
    from synth.session import SessionSpec, write_session

    folder, seed = args
    write_session(folder, SessionSpec(seed=seed))
    return folder


def make_lot(work: Path, n: int, distinct: int, bad: int) -> list[str]:
    src = work / "distinct"
    todo = [(str(src / f"seed{s}"), 5000 + s) for s in range(distinct)
            if not (src / f"seed{s}" / "session.toml").is_file()]
    if todo:
        with ProcessPoolExecutor(2) as pool:
            list(pool.map(_synth, todo))
    lot = work / "lot"
    if lot.exists():
        shutil.rmtree(lot)
    out = []
    for k in range(n):
        dst = lot / f"unit{k:04d}"
        shutil.copytree(src / f"seed{k % distinct}", dst)
        if k < bad:
            (dst / "gonio.csv").unlink()
        out.append(str(dst))
    return out


def run(sessions: list[str], out: Path, extra: list[str], report: bool) -> dict:
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "align", "run", *sessions, "--json", str(out),
           "--calibration", str(out), *extra] + (["--report", str(out)] if report else [])
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=ENV, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    m = re.search(r"(\d+) of (\d+) sessions done(?:, (\d+) failed)?", p.stdout)
    if m is None:
        raise SystemExit(f"{' '.join(extra)}: no summary (exit {p.returncode}):\n{p.stderr}")
    return {"wall": wall, "done": int(m[1]), "total": int(m[2]), "failed": int(m[3] or 0),
            "exit": p.returncode, "files": len(list(out.iterdir()))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sessions", type=int, default=200)
    ap.add_argument("--distinct", type=int, default=20)
    ap.add_argument("--bad", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1, help="runs of each configuration "
                    "(interleaved; the median is printed)")
    ap.add_argument("--report", action="store_true", help="also write an HTML report each")
    ap.add_argument("--workdir", help="keep the synthetic sessions here (default: temp)")
    a = ap.parse_args()
    work = Path(a.workdir) if a.workdir else Path(tempfile.mkdtemp(prefix="align-lot-"))
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    sessions = make_lot(work, a.sessions, a.distinct, a.bad)
    print(f"{len(sessions)} sessions ({a.distinct} distinct seeds, {a.bad} made to fail) in "
          f"{work} ({time.perf_counter() - t0:.0f} s to make); outputs: JSON + calibration"
          + (" + report" if a.report else "") + f"; {os.cpu_count()} cores")
    from distributed import LocalCluster

    t0 = time.perf_counter()
    runs: dict[str, list[dict]] = {}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        print(f"Dask LocalCluster up in {time.perf_counter() - t0:.1f} s (not included)")
        configs = (("local, 1 process", ["--jobs", "1"]),
                   ("local, 2 processes", ["--jobs", "2"]),
                   ("Dask LocalCluster, 2 workers", ["--scheduler", cluster.scheduler_address]))
        for rep in range(a.repeat):  # interleaved: a change of load hits every configuration
            for name, extra in configs:
                r = run(sessions, work / "out", extra, a.report)
                runs.setdefault(name, []).append(r)
                print(f"  [{rep + 1}/{a.repeat}] {name}: {r['wall']:.0f} s", flush=True)
    rows = {name: dict(rs[0], wall=statistics.median(r["wall"] for r in rs),
                       walls=[r["wall"] for r in rs]) for name, rs in runs.items()}
    base = rows["local, 1 process"]["wall"]
    print(f"load average (1, 5, 15 min) at the end: {os.getloadavg()}")
    print(f"\n{'configuration':32s} {'wall [s]':>9s} {'s/session':>10s} {'speed-up':>9s} "
          f"{'done':>5s} {'failed':>7s} {'exit':>5s} {'files':>6s}")
    for name, r in rows.items():
        print(f"{name:32s} {r['wall']:9.1f} {r['wall'] / r['total']:10.2f} "
              f"{base / r['wall']:9.2f} {r['done']:5d} {r['failed']:7d} {r['exit']:5d} "
              f"{r['files']:6d}" + (f"   runs: {', '.join(f'{w:.0f}' for w in r['walls'])}"
                                    if len(r["walls"]) > 1 else ""))
    if not a.workdir:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    benchpage.run(main, "A production lot: local pool and Dask")
