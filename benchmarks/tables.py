"""Reading a static-pose table of 10⁶ rows through the one table reader (what
``align calibrate`` does), with the share of the duplicate-row check, against numpy's
``loadtxt`` (the obvious alternative, which checks nothing); and a table without a time
(quantised counts read with ``--rate``), where the copy rule searches in full.

Usage: ``python3 benchmarks/tables.py [ROWS] [--markdown PATH]`` (default 10⁶). Best of 3,
fresh file in a temporary folder. ``--markdown``: also a generated page
(:mod:`benchpage`; ``docs/perf/tables.md``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import benchpage
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from align.calibration import STATIC  # noqa: E402
from axisbase.repeats import check_repeats  # noqa: E402
from axisbase.table import read_table  # noqa: E402


def best(fn, n: int = 3) -> float:
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rows", nargs="?", type=int, default=10**6)
    args = ap.parse_args()
    n = args.rows
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "static.csv"
        with open(p, "w") as f:
            f.write("pose,ux,uy,uz,t\n")
            np.savetxt(f, np.column_stack([np.arange(n) // 1000, rng.normal(0, 1, (n, 3)),
                                           np.arange(n) / 100]),
                       delimiter=",", fmt=["%d", "%.9e", "%.9e", "%.9e", "%.2f"])
        tab = read_table(p, STATIC)
        t_read = best(lambda: read_table(p, STATIC))
        t_rep = best(lambda: check_repeats(tab))
        t_np = best(lambda: np.loadtxt(p, delimiter=",", skiprows=1), 1)
        # Without a time (--rate): the copy rule's full search (axisbase.repeats), on
        # quantised counts (rows that repeat by chance).
        q = Path(d) / "untimed.csv"
        with open(q, "w") as f:
            f.write("ux,uy,uz\n")
            np.savetxt(f, np.round(rng.normal(0, 3, (n, 3))), delimiter=",", fmt="%d")
        tab_u = read_table(q, STATIC, rate_hz=100.0)
        u_read = best(lambda: read_table(q, STATIC, rate_hz=100.0))
        u_rep = best(lambda: check_repeats(tab_u))
    print("| reader | rows | time [s] (best of 3) | ratio |")
    print("|---|---|---|---|")
    print(f"| `axisbase.table.read_table` (checked) | {n} | {t_read:.3f} | 1.0 |")
    print(f"| … of which the duplicate-row check | {n} | {t_rep:.3f} | {t_rep / t_read:.2f} |")
    print(f"| `np.loadtxt` (no checks) | {n} | {t_np:.2f} | {t_np / t_read:.1f} |")
    print(f"| `read_table`, no time (`--rate`), quantised counts | {n} | {u_read:.3f} | 1.0 |")
    print(f"| … of which the duplicate-row check | {n} | {u_rep:.3f} | {u_rep / u_read:.2f} |")

if __name__ == "__main__":
    benchpage.run(main, "Reading tables: the one reader against numpy")
