"""Reading a static-pose table of 10⁶ rows through the one table reader (what
``align calibrate`` does), with the share of the duplicate-row check, against numpy's
``loadtxt`` (the obvious alternative, which checks nothing).

Usage: ``python3 benchmarks/tables.py [ROWS] [--markdown PATH]`` (default 10⁶). Best of 3,
fresh file in a temporary folder. ``--markdown`` also writes the figures as a Markdown table
(``docs/generated/tables.md`` is included by the performance page of the docs).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

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
    ap.add_argument("--markdown", type=Path, help="also write the table to this Markdown file")
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
    print(f"{n} rows: read_table {t_read:.3f} s (of which the duplicate check {t_rep:.3f} s, "
          f"{100 * t_rep / t_read:.0f} %); np.loadtxt {t_np:.2f} s "
          f"({t_np / t_read:.1f}x slower, no checks)")
    if args.markdown:
        write_markdown(args.markdown, [
            "| reader | rows | time [s] (best of 3) | ratio |",
            "|---|---|---|---|",
            f"| `axisbase.table.read_table` (checked) | {n} | {t_read:.3f} | 1.0 |",
            f"| … of which the duplicate-row check | {n} | {t_rep:.3f} | "
            f"{t_rep / t_read:.2f} |",
            f"| `np.loadtxt` (no checks) | {n} | {t_np:.2f} | {t_np / t_read:.1f} |",
        ], "python3 benchmarks/tables.py --markdown docs/generated/tables.md")


def write_markdown(path: Path, rows: list[str], command: str) -> None:
    """The figures as a Markdown table with the date and the command that wrote them."""
    stamp = time.strftime("%Y-%m-%d", time.gmtime())
    path.write_text("\n".join(rows) + f"\n\nMeasured {stamp} by `{command}`; "
                    f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}.\n")


if __name__ == "__main__":
    main()
