"""Kinked marks (issue 18): two 200 px straight strokes sharing an end point at 5 and 8 deg.

Run:  python3 benchmarks/kinked_marks.py [--seeds 10]
Before/after: ``PYTHONPATH=/path/to/other/checkout python3 benchmarks/kinked_marks.py`` runs
that checkout's pipeline on the same scenes (its path comes first).

Per image: the marks reported, each mark's error against the nearer stroke over its u, and
the document's ``ok``; the lens declared absent (``LensRanges.none()``), as the tests call it.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
from pathlib import Path

sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from align import LensRanges, measure_image  # noqa: E402
from align.documents import marks_document  # noqa: E402
from synth import render_marks  # noqa: E402

# The scenes from this checkout's synth (synth imports nothing from the pipeline, so another
# checkout's pipeline first on PYTHONPATH measures the same scenes).
_here = Path(__file__).resolve().parents[1] / "synth" / "scenes.py"
_spec = importlib.util.spec_from_file_location("_kink_scenes", _here)
_mod = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_mod)
kink_spec = _mod.kinked_pair


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    args = ap.parse_args()
    zs, oks, counts = [], [], []
    for seed in range(args.seeds):
        for kink in (5.0, 8.0):
            spec, truth = kink_spec(seed, kink)
            res = [r for r in measure_image(render_marks(spec, with_crlb=False).image,
                                            ranges=LensRanges.none()) if r.found]
            counts.append(len(res))
            oks.append(marks_document(res, {}, [])["ok"])
            zs += [min(abs(r.angle_rad - a) for a in truth) / r.angle_u_rad for r in res]
    z = np.array(zs)
    print(f"images {len(oks)}, marks per image {sorted(set(counts))}, |err|/u median "
          f"{np.median(z):.2f} max {z.max():.1f}, > 3 u {int((z > 3).sum())}/{z.size}, "
          f"ok {sum(oks)}/{len(oks)}")


if __name__ == "__main__":
    main()
