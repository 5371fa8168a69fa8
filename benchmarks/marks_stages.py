"""Scribe marks: CPU time per stage of the camera stage's detect + measure, per image size.

Run:  python3 benchmarks/marks_stages.py [--images N] [--sizes vga,5mp]
      PYTHONPATH=/path/to/other/checkout python3 benchmarks/marks_stages.py   (its code)

The speed benchmark's images (``benchmarks/marks.py --speed``: 640x480 with a 300-px mark,
2592x1944 with a 2000-px mark, distinct seeds), each measured once by
``imaging.measure_marks`` with the stages' functions wrapped to add up their CPU time
(``time.process_time``; a nested stage is also inside its parent's figure). Prints the
median over the images of each stage [ms], and the whole call's. Two checkouts compared:
run it with each one's root first on PYTHONPATH, interleaved (a shared host's load moves
every figure by ~10 %: compare runs made one after the other, several times).
"""

from __future__ import annotations

import argparse
import os
import time
from collections import defaultdict

import benchpage

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from marks import fresh_images  # noqa: E402 (the speed benchmark's images)

import imaging  # noqa: E402
import imaging.centres as centres  # noqa: E402
import imaging.detect as detect  # noqa: E402
import imaging.measure as measure  # noqa: E402

cv2.setNumThreads(1)

SIZES = {"vga": ((640, 480), 300.0), "5mp": ((2592, 1944), 2000.0)}
"""Frame size and mark length per size name (those of ``marks.py --speed``)."""

STAGES = (
    (measure, "detect_lines", "detection (+ confirmation)"),
    (detect, "ridge_response", "  ridge filter"),
    (detect, "confirm_candidates", "  confirmation"),
    (measure, "band_indices", "bands of the lines"),
    (measure, "find_oriented", "oriented stripes"),
    (measure, "find_stripes", "row/column stripes"),
    (measure, "measure_candidate", "measurement of the marks"),
    (measure, "fit_profile", "  band profile fit"),
    (measure, "sample_centres", "  centres (both passes)"),
    (centres, "_band", "    band pixels"),
    (centres, "texture_model", "    texture replicas"),
    (centres, "fit_shape", "    groove shape"),
    (measure, "extent_look", "  groove ends looked at"),
    (measure, "runs_on_stretch", "  ends' obstruction check"),
    (measure, "crossing_skip", "  crossings"),
)
"""(module, name, label): the functions timed, by the name the caller looks them up by."""


def _wrap(acc: dict[str, float]) -> None:
    """Each stage's function replaced, in its caller's namespace, by one that adds its CPU
    time to ``acc[label]``."""
    for mod, name, label in STAGES:
        f = getattr(mod, name)

        def timed(*a, _f=f, _label=label, **k):
            t0 = time.process_time()
            try:
                return _f(*a, **k)
            finally:
                acc[_label] += time.process_time() - t0

        setattr(mod, name, timed)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--images", type=int, default=9, help="fresh images per size (median)")
    ap.add_argument("--sizes", default="vga,5mp", help="comma-separated: vga, 5mp")
    args = ap.parse_args()
    print(f"code: {os.path.dirname(os.path.dirname(os.path.abspath(imaging.__file__)))}")
    acc: dict[str, float] = defaultdict(float)
    _wrap(acc)
    for key in args.sizes.split(","):
        size, length = SIZES[key]
        imaging.measure_marks(fresh_images(size, length, 1, first_seed=0)[0])  # first call
        per: dict[str, list[float]] = defaultdict(list)
        for img in fresh_images(size, length, args.images):
            acc.clear()
            t0 = time.process_time()
            imaging.measure_marks(img)
            per["detect + measure (whole call)"].append(time.process_time() - t0)
            for _, _, label in STAGES:
                per[label].append(acc[label])
        print(f"\n== {size[0]}x{size[1]}, {length:.0f}-px mark: CPU ms per image, median over "
              f"{args.images} images ==")
        for label, v in per.items():
            print(f"{label:<32s} {1e3 * float(np.median(v)):7.1f}")


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: CPU per stage")
