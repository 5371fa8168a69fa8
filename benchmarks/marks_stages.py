"""Scribe marks: CPU time per stage of the camera stage's detect + measure, per image size.

Run:  python3 benchmarks/marks_stages.py [--images N] [--sizes vga,5mp] [--real]
      PYTHONPATH=/path/to/other/checkout python3 benchmarks/marks_stages.py   (its code)

The speed benchmark's images (``benchmarks/marks.py --speed``: 640x480 with a 300-px mark,
2592x1944 with a 2000-px mark, distinct seeds), each measured once by
``imaging.measure_marks`` with the stages' functions wrapped to add up their CPU time
(``time.process_time``; a nested stage is also inside its parent's figure). Prints the
median over the images of each stage [ms], and the whole call's. Two checkouts compared:
run it with each one's root first on PYTHONPATH, interleaved (a shared host's load moves
every figure by ~10 %: compare runs made one after the other, several times).

``--real``: each real photograph of ``benchmarks/marks_real.py`` (../shared/data/real) once
through ``align.measure_file`` (what ``align marks`` runs: decode, detect, measure, shadow
edges, the frame's lens, the residual loop), with the stages of :data:`REAL_STAGES` timed
the same way: per photo the whole call and each stage [s] (issue 18's target: each photo
<= 1 s CPU without imports; a first call on a synthetic frame is left out, as there). The
residual loop's row holds the JPEG term (:func:`imaging.jpeg_turn.jpeg_turn_estimate`, its
noisy draws' centres), computed when the loop first reads it: on the real photos most of
that row, the loop's own fits (``run_loop``) a few ms a mark.
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
from marks_real import real_photos  # noqa: E402

import align.mark_shadow as mark_shadow  # noqa: E402
import align.marks as marks  # noqa: E402
import imaging  # noqa: E402
import imaging.centres as centres  # noqa: E402
import imaging.detect as detect  # noqa: E402
import imaging.jpeg_turn as jpeg_turn  # noqa: E402
import imaging.measure as measure  # noqa: E402
import imaging.oriented as oriented  # noqa: E402
from align.marks import measure_file, measure_image  # noqa: E402
from synth import ImageSpec, MarkSpec, render_marks  # noqa: E402

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
    (measure, "centres_stretch", "  ends' obstruction check"),
    (measure, "crossing_skip", "  crossings"),
)
"""(module, name, label): the functions timed, by the name the caller looks them up by."""

REAL_STAGES = (
    (marks, "measure_frame", "detect + measure"),
    (measure, "detect_lines", "  detection (all passes)"),
    (measure, "find_oriented", "  oriented stripes"),
    (oriented, "_fit", "    their frequency fits"),
    (measure, "find_stripes", "  row/column stripes"),
    (measure, "measure_candidate", "  measurement (all calls)"),
    (measure, "fit_profile", "    band profile fits"),
    (measure, "_with_background_u", "    again with the stripes back"),
    (mark_shadow, "shadow_free", "shadow edges' fits"),
    (mark_shadow, "measure_candidate", "marks again under an edge"),
    (marks, "camera_lens", "the frame's lens"),
    (marks, "finish_mark", "residual loop (per mark)"),
    (marks, "run_loop", "  the loop's fits"),
    (jpeg_turn, "jpeg_turn_estimate", "  JPEG term's draws"),
)
"""(module, name, label) timed per real photograph (``--real``)."""


def _wrap(acc: dict[str, float], stages: tuple = STAGES) -> None:
    """Each stage's function replaced, in its caller's namespace, by one that adds its CPU
    time to ``acc[label]``."""
    for mod, name, label in stages:
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
    ap.add_argument("--real", action="store_true",
                    help="the real photographs instead (../shared/data/real), per stage")
    args = ap.parse_args()
    acc: dict[str, float] = defaultdict(float)
    if args.real:
        return real_stages(acc)
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


def real_stages(acc: dict[str, float]) -> None:
    """Per real photograph: CPU [s] of ``align.measure_file`` and of each of
    :data:`REAL_STAGES` (see the module)."""
    photos = real_photos()
    if not photos:
        print("../shared/data/real is absent: no real photographs to time")
        return
    _wrap(acc, REAL_STAGES)
    measure_image(render_marks(ImageSpec(marks=(MarkSpec(0.4, 9.3, 300.0, 4.0),), width=640,
                                         height=480, seed=0), with_crlb=False).image)
    labels = ["whole call"] + [label.strip() for _, _, label in REAL_STAGES]
    print(f"\n== CPU s per real photograph, one core, per stage (a nested stage is also in "
          f"its parent's figure) ==\n| photo | {' | '.join(labels)} |\n"
          f"|---|{'---:|' * len(labels)}")
    for p in photos:
        acc.clear()
        t0 = time.process_time()
        measure_file(p)
        whole = time.process_time() - t0
        cells = [whole] + [acc[label] for _, _, label in REAL_STAGES]
        print(f"| {p.parent.name}/{p.name} | " + " | ".join(f"{v:.3f}" for v in cells) + " |")


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: CPU per stage")
