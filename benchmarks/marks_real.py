"""Scribe-mark stage on real photographs: CPU time per photo, against OpenCV's LSD.

Run:  python3 benchmarks/marks_real.py [--save FILE] [--against FILE] [--markdown FILE]
      (needs ../shared/data/real)

Every JPEG of ``opencv-chessboard`` and ``opencv-lines`` (640x480 chessboards, a building,
the ChArUco boards; none holds a scribe mark, so each is a busy scene the stage must get
through, saying why its lines are not trusted) goes through ``align.measure_file`` (decode,
detect, measure, residual loop, lens terms) and through OpenCV's line segment detector on
the same pixels, each timed once on one core (``time.process_time``). A first call on a
synthetic 640x480 frame is left out (imports, scipy.signal's on first use, per-shape
tables: what ``python3 -X importtime -m align marks`` shows as the import share). Prints per
photo the CPU time, the marks measured and those refused (each with its reason in the
JSON), LSD's time and the ratio, and issue 18's target (a real 640x480 photo <= 1 s CPU
without imports). ``benchmarks/marks.py --speed`` prints the same table after its synthetic
figures. ``--save`` keeps every photo's results (``MarkResult.to_dict``); ``--against`` a
file saved with another checkout's code on PYTHONPATH says which photos' results differ
(a speed change keeps them all).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import benchpage

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from align.marks import measure_file, measure_image  # noqa: E402
from synth import ImageSpec, MarkSpec, render_marks  # noqa: E402

cv2.setNumThreads(1)
REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
FOLDERS = ("opencv-chessboard", "opencv-lines")
TARGET_S = 1.0
"""Issue 18, item 7: CPU per real 640x480 photo, imports left out [s]."""


def real_photos() -> list[Path]:
    """The real photographs timed (empty when ../shared/data/real is absent)."""
    return sorted(p for f in FOLDERS if (REAL / f).is_dir() for p in (REAL / f).glob("*.jpg"))


def lsd_segments(path: Path) -> int:
    """OpenCV's line segment detector on the photo's grey pixels: the segments found."""
    img8 = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    segs = cv2.createLineSegmentDetector().detect(img8)[0]
    return 0 if segs is None else len(segs)


def real_speed(photos: list[Path] | None = None, save: str | None = None,
               against: str | None = None) -> None:
    """CPU time per real photo, this tool end to end against OpenCV's LSD (see the module);
    ``save``/``against``: every photo's results kept / compared with a saved file's."""
    photos = real_photos() if photos is None else photos
    print("\n== CPU time per real photograph (../shared/data/real), one core ==")
    if not photos:
        print(f"{REAL} is absent: no real photographs to time")
        return
    # First-call costs (imports on first use) left out, on a synthetic frame: a photo's own
    # warm-up would fill the caches keyed by its data (the loop's periodogram).
    measure_image(render_marks(ImageSpec(marks=(MarkSpec(0.4, 9.3, 300.0, 4.0),), width=640,
                                         height=480, seed=0), with_crlb=False).image)
    lsd_segments(photos[0])
    print(f"{'photo':>35s} {'size':>9s} {'align s':>8s} {'measured':>8s} {'refused':>7s} "
          f"{'LSD ms':>7s} {'segs':>5s} {'ratio':>6s}")
    ours, theirs = [], []
    results = {}
    for p in photos:
        t0 = time.process_time()
        res = measure_file(p)
        t1 = time.process_time()
        # Each result names its photo by path; the photo named from its folder instead, so
        # that two checkouts (each finding ../shared its own way) compare equal.
        key = f"{p.parent.name}/{p.name}"
        results[key] = json.loads(json.dumps([r.to_dict() for r in res])
                                  .replace(json.dumps(str(p))[1:-1], key))
        n_seg = lsd_segments(p)
        t2 = time.process_time()
        ours.append(t1 - t0)
        theirs.append(t2 - t1)
        h, w = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE).shape
        found = sum(r.found for r in res)
        print(f"{p.parent.name + '/' + p.name:>35s} {w:>4d}x{h:<4d} {t1 - t0:8.2f} "
              f"{found:8d} {len(res) - found:7d} {1e3 * (t2 - t1):7.1f} "
              f"{n_seg:5d} {(t1 - t0) / max(t2 - t1, 1e-9):6.0f}")
    over = [p.name for p, t in zip(photos, ours, strict=True) if t > TARGET_S]
    print(f"median {np.median(ours):.2f} s (range {min(ours):.2f}-{max(ours):.2f}) over "
          f"{len(photos)} photos; LSD median {1e3 * np.median(theirs):.1f} ms")
    print(f"target: each real photo <= {TARGET_S:.0f} s CPU without imports: "
          + ("met" if not over else f"NOT met ({len(over)} of {len(photos)} over)"))
    if save:
        Path(save).write_text(json.dumps(results))
    if against:
        other = json.loads(Path(against).read_text())
        # (compared as JSON text: a NaN equals itself there)
        differ = [k for k in results if json.dumps(results[k], sort_keys=True)
                  != json.dumps(other.get(k), sort_keys=True)]
        print(f"results against {against}: {len(results) - len(differ)} of {len(results)} "
              "photos identical" + (f"; differ: {', '.join(differ)}" if differ else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--save", help="keep every photo's results in this JSON file")
    ap.add_argument("--against", help="compare with results saved by --save")
    args = ap.parse_args(sys.argv[1:])
    real_speed(save=args.save, against=args.against)


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: time per real photograph")
