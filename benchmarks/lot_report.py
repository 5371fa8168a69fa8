"""`align lot` over 10⁴ session results, end to end (the command a user runs: reading and
checking every file, the statistics, the HTML report, the CSV and the JSON), against a plain
`json.load` loop over the same files measured in the same run.

The results are made from one real session result (a synthetic session run by `align run`,
or the file given with --template) by `synth.lot`: the six angles, the session name and the
metadata change; by default the per-observation and per-stage blocks are left out (small
valid results, ~8 kB); with --full every file keeps them and is as large as a real one
(~40 kB).

    python3 benchmarks/lot_report.py [--n 10000] [--repeat 3] [--full] [--template R.json]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import benchpage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from synth.lot import ARCSEC_RAD, lot_results  # noqa: E402


def _template(work: Path) -> dict:
    session = work / "unit"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    subprocess.run([sys.executable, "-m", "align", "synth", "session", str(session),
                    "--seed", "5", "-q"], check=True, env=env, stdout=subprocess.DEVNULL)
    out = work / "template.json"
    # exit 2 would be a template not ok: a lot of such units has nothing in its statistics
    subprocess.run([sys.executable, "-m", "align", "run", str(session), "--json", str(out),
                    "-q"], check=True, env=env, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="result files")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs (median reported)")
    ap.add_argument("--template", help="a real session result to perturb")
    ap.add_argument("--full", action="store_true",
                    help="keep every block of the real result (files of real size)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="lotbench") as tmp:
        work = Path(tmp)
        template = (json.loads(Path(args.template).read_text()) if args.template
                    else _template(work))
        results, _ = lot_results(
            template, args.n, seed=13, sigma_rad=1.5 * ARCSEC_RAD,
            shifts={args.n // 3: (1, 6.0)},
            metadata={"camera": ["A", "B", "C"], "table": ["T1", "T2"],
                      "operator": ["kim", "lee", "ann", "bo"]},
            start=dt.datetime(2026, 1, 5, 6, 0), small=not args.full)
        folder = work / "results"
        folder.mkdir()
        for d in results:
            (folder / f"{d['session']}.json").write_text(json.dumps(d, indent=2))
        files = sorted(folder.iterdir())
        size = sum(p.stat().st_size for p in files)
        print(f"{len(files)} result files, {size / 1e6:.0f} MB ({size / len(files) / 1e3:.0f} "
              "kB each)")
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        t_lot, t_json, cpu_lot = [], [], []
        for k in range(args.repeat):
            # The obvious alternative: a loop that loads each result and keeps its E.
            t0 = time.perf_counter()
            kept = []
            for p in files:
                with open(p, "rb") as f:
                    kept.append(json.load(f)["misalignment_rad"])
            t_json.append(time.perf_counter() - t0)
            del kept
            out = work / f"run{k}"
            cmd = [sys.executable, "-m", "align", "lot", str(folder), "--report",
                   f"{out}.html", "--csv", f"{out}.csv", "--json", f"{out}.json",
                   "--tolerance-arcsec", "8", "-q"]
            c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            r = subprocess.run(cmd, env=env, capture_output=True, text=True)
            t_lot.append(time.perf_counter() - t0)
            c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu_lot.append(c1.ru_utime - c0.ru_utime + c1.ru_stime - c0.ru_stime)
            if r.returncode not in (0, 2) or not Path(f"{out}.html").is_file():
                print(r.stderr[-2000:])
                return 1
        doc = json.loads(Path(f"{out}.json").read_text())
        flagged = sorted({u for a in doc["angles"] for u in a["outside_limits"]})
        print(f"align lot (JSON + CSV + HTML, end to end): median {statistics.median(t_lot):.2f} s "
              f"(runs {', '.join(f'{t:.2f}' for t in t_lot)})")
        print(f"  its CPU time (user + sys):                median "
              f"{statistics.median(cpu_lot):.2f} s (runs {', '.join(f'{t:.2f}' for t in cpu_lot)})"
              f"; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(f"plain json.load loop (keeping E):           median "
              f"{statistics.median(t_json):.2f} s (runs {', '.join(f'{t:.2f}' for t in t_json)})")
        print(f"ratio align lot / json.load loop: "
              f"{statistics.median(t_lot) / statistics.median(t_json):.1f}")
        print(f"report {Path(f'{out}.html').stat().st_size / 1e6:.1f} MB; "
              f"{doc['n_in_statistics']} units in the statistics; run order {doc['run_order']};"
              f" units outside the control limits: {len(flagged)} "
              f"(the 6σ unit SN{args.n // 3:05d} among them: "
              f"{f'SN{args.n // 3:05d}' in flagged})")
        if args.n == 10_000:
            print("target ≤ 10 s for 10⁴ results: wall "
                  + ("met" if statistics.median(t_lot) <= 10 else "NOT met") + ", CPU time "
                  + ("met" if statistics.median(cpu_lot) <= 10 else "NOT met"))
    return 0


if __name__ == "__main__":
    benchpage.run(main, "align lot over many results")
