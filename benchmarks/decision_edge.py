"""The real photos' marks measured twice with an imperceptibly different input: how far does
each angle move, in units of the larger of the two u?

Two perturbations: the band fit's step cap 25 against 1000 (``--caps``), and the band fit's
width moved by -0.1 and +0.1 px before the centres are read (``--width``). A move beyond 1
means one of the two results is outside its u: the loop's decisions on the edge of their
tests (``align/mark_choice.py``) are what this checks.

Run: ``PYTHONPATH=. python3 benchmarks/decision_edge.py [--caps | --width] [--part i/n]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
from pathlib import Path

import imaging.measure as meas
import imaging.profile as prof
from align.marks import measure_file

_FIT = meas.fit_profile
_DW = [0.0]


def _fit_profile(*a, **k):
    """The band fit, its width moved by the perturbation under test [px]."""
    pf = _FIT(*a, **k)
    return dataclasses.replace(pf, width_px=pf.width_px + _DW[0]) if _DW[0] else pf


def _run(path: str, cap: int, dw: float) -> dict:
    prof.BAND_FIT_STEPS, _DW[0] = cap, dw
    return {r.index: r for r in measure_file(path) if r.found}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", action="store_true", help="width -+0.1 px (default: caps)")
    ap.add_argument("--part", default="0/1", help="photos i::n (to split the run)")
    args = ap.parse_args()
    meas.fit_profile = _fit_profile
    i, n = (int(x) for x in args.part.split("/"))
    rows = []
    for p in sorted(glob.glob("/work/shared/data/real/opencv-*/*.jpg"))[i::n]:
        base = _run(p, 25, 0.0)
        others = [_run(p, 25, -0.1), _run(p, 25, 0.1)] if args.width else [_run(p, 1000, 0.0)]
        for o in others:
            for k, a in base.items():
                b = o.get(k)
                if b is not None:
                    d = (b.angle_rad - a.angle_rad) / max(a.angle_u_rad, b.angle_u_rad)
                    rows.append((abs(d), Path(p).name, k, d, b.angle_u_rad / a.angle_u_rad))
    rows.sort(reverse=True)
    for _, name, k, d, r in rows[:8]:
        print(f"{name:14} {k:2d} move {d:+.2f} (larger u)  u ratio {r:.2f}")
    print(f"{len(rows)} comparisons, {sum(x[0] > 1 for x in rows)} beyond 1")


if __name__ == "__main__":
    main()
