"""The camera stage's results on a fixed set of images, to compare two checkouts' code.

Run:  python3 benchmarks/marks_fingerprint.py [--save FILE] [--against FILE] [--quick]

Renders the speed benchmark's images (``benchmarks/marks.py --speed``: 640x480 and 5 MP,
distinct seeds) and 1024x768 frames that take the stage's other paths (texture, vignetting
with dust, column and row fixed-pattern noise, oriented stripes, an 8-bit JPEG, two crossing
marks, a bowed mark under a barrel lens), measures each with ``align.measure_image`` and
prints one fingerprint of every result (``MarkResult.to_dict``, sha256 of the sorted JSON).
``--save`` keeps the results; ``--against`` a file saved by another checkout's code
(``PYTHONPATH=../main-checkout python3 benchmarks/marks_fingerprint.py --save main.json``) says
how many results are bit-identical and, where they are not, the largest angle change in
units of u, the largest relative change of u, and every decision that differs (found,
ok, flags, effects, warnings: any value that is not a float). A text that differs only in
decimal numbers written in it (a fitted k1 in a note) is a float in words, listed apart and
not a decision; a count written in a text (a whole number) that differs is a decision. A
speed change that is not bit-identical is accepted when angles move <= 0.05 u and no
decision differs.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import sys
from pathlib import Path

# One BLAS thread, as marks_real.py: the thread count changes the last bits of a sum,
# and two checkouts compared bit for bit must run alike.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import benchpage  # noqa: E402
import numpy as np  # noqa: E402
from marks import spec_for  # noqa: E402  (the speed benchmark's images)

from align.marks import measure_image  # noqa: E402
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks  # noqa: E402

ANGLE_TOL_U = 0.05
"""Largest angle change [u] a change that is not bit-identical may make."""


def _speed_set(quick: bool) -> list[tuple[str, ImageSpec]]:
    """The speed benchmark's fresh images (see ``marks.fresh_images``)."""
    out = []
    for size, length, n in (((640, 480), 300.0, 4 if quick else 9),
                            ((2592, 1944), 2000.0, 1 if quick else 3)):
        for k in range(n):
            out.append((f"speed {size[0]}x{size[1]} #{k}",
                        spec_for(23.0 + 1.7 * k, 4.0, 30, 1 + k, size=size, length=length)))
    return out


def _paths_set(quick: bool) -> list[tuple[str, ImageSpec]]:
    """1024x768 frames through the stage's other paths, two seeds each (one when quick)."""
    fw = full_well_for_snr(30, -0.6)
    one = (MarkSpec(np.deg2rad(12.0), 20.0, 600.0, 4.0),)
    two = (MarkSpec(np.deg2rad(8.0), 0.0, 700.0, 4.0), MarkSpec(np.deg2rad(97.0), 40.0, 500.0, 4.0))
    bowed = (MarkSpec(np.deg2rad(3.0), 250.0, 800.0, 4.0),)
    kinds = {
        "texture": dict(marks=one, texture=0.02),
        "vignetting + dust": dict(marks=one, vignetting=0.25, dust=12, dust_on_mark=3),
        "column + row FPN": dict(marks=one, column_fpn=0.015, row_fpn=0.01),
        "oriented stripes": dict(marks=one, stripes=0.03, stripes_period_px=24.0),
        "jpeg 8-bit": dict(marks=one, bits=8, jpeg_quality=85),
        "two crossing": dict(marks=two),
        "bowed, barrel lens": dict(marks=bowed, camera=CameraGeometry(k1=-0.15)),
    }
    out = []
    for name, kw in kinds.items():
        for seed in range(1 if quick else 2):
            out.append((f"{name} s{seed}", ImageSpec(width=1024, height=768, blur_px=1.2,
                                                     full_well_e=fw, seed=100 + seed, **kw)))
    return out


def run(quick: bool) -> dict[str, list[dict]]:
    """Every image's results (``MarkResult.to_dict`` each), by image name."""
    results = {}
    for name, spec in (*_speed_set(quick), *_paths_set(quick)):
        img = render_marks(spec, with_crlb=False).image.astype(float)
        results[name] = [r.to_dict() for r in measure_image(img, name=name)]
    return json.loads(json.dumps(results, default=_plain))  # as a saved file reads back


def _plain(v: object) -> object:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not serialisable: {type(v).__name__}")


def fingerprint(results: dict) -> str:
    return hashlib.sha256(json.dumps(results, sort_keys=True).encode()).hexdigest()[:8]


def _leaves(d: object, path: str = ""):
    if isinstance(d, dict):
        for k in sorted(d):
            yield from _leaves(d[k], f"{path}.{k}")
    elif isinstance(d, list):
        yield f"{path}#len", len(d)
        for i, v in enumerate(d):
            yield from _leaves(v, f"{path}[{i}]")
    else:
        yield path, d


_DECIMAL = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+)(?:e[-+]?\d+)?|[-+]?\d+e[-+]?\d+")


def _decimals_only(a: object, b: object) -> bool:
    """Whether two texts differ only in the decimal numbers written in them (the same
    words, the same whole numbers)."""
    return (isinstance(a, str) and isinstance(b, str) and a != b
            and _DECIMAL.sub("#", a) == _DECIMAL.sub("#", b))


def compare(ours: dict, theirs: dict) -> bool:
    """Print how ``ours`` differs from ``theirs``; True when within the tolerance."""
    same = moved = 0
    worst_u, worst_du, decisions, worded = 0.0, 0.0, [], []
    names = [n for n in theirs if n in ours]  # (--quick against a full run: its subset)
    for name in names:
        a, b = ours[name], theirs[name]
        if a == b:
            same += 1
            continue
        moved += 1
        la, lb = dict(_leaves(a)), dict(_leaves(b))
        for key in sorted(set(la) | set(lb)):
            va, vb = la.get(key), lb.get(key)
            floats = all(isinstance(v, float) for v in (va, vb))
            if _decimals_only(va, vb):
                worded.append(f"{name}{key}: {vb!r} -> {va!r}")
            elif not floats and va != vb:
                decisions.append(f"{name}{key}: {vb!r} -> {va!r}")
        for i, (ra, rb) in enumerate(zip(a, b, strict=False)):
            if ra.get("found") and rb.get("found"):
                du = abs(ra["angle_rad"] - rb["angle_rad"]) / rb["angle_u_rad"]
                worst_u = max(worst_u, du)
                worst_du = max(worst_du, abs(ra["angle_u_rad"] / rb["angle_u_rad"] - 1))
                print(f"  {name} mark {i}: angle moved {du:.2e} u, u by {worst_du:.1e} "
                      "(relative)")
    print(f"against the saved results: {same} of {len(names)} images bit-identical, "
          f"{moved} differ; largest angle change {worst_u:.2e} u (tolerance {ANGLE_TOL_U}), "
          f"largest relative change of u {worst_du:.1e}; decisions that differ: "
          f"{len(decisions)}; texts differing only in decimal numbers: {len(worded)}")
    for d in decisions[:20]:
        print("  " + d)
    for d in worded[:20]:
        print("  (numbers only) " + d)
    return worst_u <= ANGLE_TOL_U and not decisions and set(ours) <= set(theirs)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--save", type=Path, help="write the results (JSON) here")
    ap.add_argument("--against", type=Path, help="results saved by another checkout")
    ap.add_argument("--quick", action="store_true", help="fewer images")
    args = ap.parse_args()
    results = run(args.quick)
    print(f"{len(results)} images, {sum(len(v) for v in results.values())} results; "
          f"fingerprint {fingerprint(results)}")
    if args.save:
        args.save.write_text(json.dumps(results, sort_keys=True))
    if args.against and not compare(results, json.loads(args.against.read_text())):
        sys.exit(1)


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: results fingerprint")
