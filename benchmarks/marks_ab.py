"""Scribe marks: two checkouts' versions of some functions, alternated image by image in one
process (paired CPU differences that a loaded host does not drown).

Run:  python3 benchmarks/marks_ab.py --other ../main-checkout --swap imaging.centres._conditioned
      [--swap module.function ...] [--sizes vga,5mp] [--images N] [--rounds R]
      [--photos FILE ...]

Each ``--swap`` names a function of this checkout (``module.function``); the other
checkout's version is loaded from its own file of that module (under a private name: the
rest of its imports are this checkout's) and put wherever this one's is referenced (every
loaded module holding the same function object, so a caller that imported it by name sees
the swap; ``module.Class.method``: the other's method put on this checkout's class). The
speed benchmark's images (``benchmarks/marks.py --speed``) go through
``imaging.measure_marks`` once per version per round, the order of the two alternating
round by round, each call timed (``time.process_time``), and each swapped function's own
CPU added up per version. Prints the medians, the median of the paired differences
(this - other) and of their ratios, and each function's CPU per image. ``--photos``: the
given image files instead, each through ``align.measure_file`` (the whole mark stage, the
frame's lens included), the same alternation, figures per photo.

Why: on the shared 2-core host (load 10-14 while other sessions test) two processes run one
after the other differ by +-15 ms per 5 MP call whatever their code, so a change of 1-2 ms
needs ~100 pairs that way; the same images through both versions in one process, a call
apart, see the same load and show it in a few.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path

import benchpage

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from marks import fresh_images  # noqa: E402 (the speed benchmark's images)
from marks_stages import SIZES  # noqa: E402

import imaging  # noqa: E402

cv2.setNumThreads(1)


def _split(dotted: str) -> tuple[str, str | None, str]:
    """``module.function`` or ``module.Class.method`` as (module, class or None, name)."""
    mod, name = dotted.rsplit(".", 1)
    try:
        importlib.import_module(mod)
        return mod, None, name
    except ModuleNotFoundError:
        mod, cls = mod.rsplit(".", 1)
        return mod, cls, name


def _other_function(root: Path, dotted: str):
    """``module.function`` (or ``module.Class.method``) as the checkout at ``root`` defines
    it."""
    mod, cls, name = _split(dotted)
    path = root / (mod.replace(".", "/") + ".py")
    alias = f"_ab_other_{mod.replace('.', '_')}"
    if alias not in sys.modules:
        spec = importlib.util.spec_from_file_location(alias, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[alias] = module  # (dataclasses look their module up by name)
        spec.loader.exec_module(module)
    owner = sys.modules[alias] if cls is None else getattr(sys.modules[alias], cls)
    return owner.__dict__[name]


def _holders(f) -> list[tuple[object, str]]:
    """(module, attribute) of every loaded module that holds the function object ``f``."""
    out = []
    for m in list(sys.modules.values()):
        for k, v in list(getattr(m, "__dict__", {}).items()):
            if v is f:
                out.append((m, k))
    return out


def _quartiles(x: np.ndarray, fmt: str) -> str:
    """The first and third quartiles of ``x``, formatted: the pairs' spread."""
    q1, q3 = np.percentile(x, [25, 75])
    return f"{q1:{fmt}} to {q3:{fmt}}"


def _timed(f, acc: dict, key: tuple):
    def g(*a, **k):
        t0 = time.process_time()
        try:
            return f(*a, **k)
        finally:
            acc[key] = acc.get(key, 0.0) + time.process_time() - t0
    return g


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--other", type=Path, required=True, help="the other checkout's root")
    ap.add_argument("--swap", action="append", required=True,
                    help="module.function of this checkout to compare (repeatable)")
    ap.add_argument("--sizes", default="5mp", help="comma-separated: vga, 5mp")
    ap.add_argument("--images", type=int, default=3, help="fresh images per size")
    ap.add_argument("--rounds", type=int, default=6, help="passes over the images")
    ap.add_argument("--photos", nargs="+", type=Path,
                    help="image files instead: each through align.measure_file (the whole "
                         "mark stage, the frame's lens included)")
    args = ap.parse_args()
    # The page's header says which checkout "this" is; the other is named as the user gave it.
    print(f"code: this checkout, other {args.other}; swapped: {', '.join(args.swap)}")
    acc: dict = {}
    versions = {"this": {}, "other": {}}
    # The other's functions first, then who holds each of this checkout's: the other's
    # modules imported this checkout's functions by name when loaded, and a swapped one that
    # calls another (the other's groove_ends calling _band) must call the other's too.
    others = {dotted: _other_function(args.other, dotted) for dotted in args.swap}
    for dotted in args.swap:
        mod, cls, name = _split(dotted)
        owner = importlib.import_module(mod)
        if cls is not None:  # a method: its class holds it
            owner = getattr(owner, cls)
        mine = owner.__dict__[name]
        holders = _holders(mine) if cls is None else [(owner, name)]
        versions["this"][dotted] = (holders, _timed(mine, acc, ("this", dotted)))
        versions["other"][dotted] = (holders, _timed(others[dotted], acc, ("other", dotted)))

    def use(tag: str) -> None:
        for holders, f in versions[tag].values():
            for m, k in holders:
                setattr(m, k, f)

    if args.photos:
        _photos(args, versions, use, acc)
        return
    for key in args.sizes.split(","):
        size, length = SIZES[key]
        imgs = fresh_images(size, length, args.images)
        for tag in versions:
            use(tag)
            imaging.measure_marks(fresh_images(size, length, 1, first_seed=0)[0])  # first call
        acc.clear()
        calls: dict[str, list[float]] = {"this": [], "other": []}
        for r in range(args.rounds):
            for img in imgs:
                for tag in (("this", "other") if r % 2 else ("other", "this")):
                    use(tag)
                    t0 = time.process_time()
                    imaging.measure_marks(img)
                    calls[tag].append(time.process_time() - t0)
        a, b = 1e3 * np.array(calls["this"]), 1e3 * np.array(calls["other"])
        n = a.size
        print(f"\n== {size[0]}x{size[1]}, {length:.0f}-px mark: {n} paired calls "
              f"({args.images} images x {args.rounds} rounds), CPU ms ==\n"
              f"detect + measure: this {np.median(a):.1f}, other {np.median(b):.1f}; paired "
              f"difference {np.median(a - b):+.1f} (median; quartiles "
              f"{_quartiles(a - b, '+.1f')}), "
              f"ratio {np.median(a / b):.3f} (quartiles {_quartiles(a / b, '.3f')})")
        for dotted in args.swap:
            print(f"  {dotted}: this {1e3 * acc.get(('this', dotted), 0.0) / n:.2f}, other "
                  f"{1e3 * acc.get(('other', dotted), 0.0) / n:.2f} per image")
    use("this")


def _photos(args, versions: dict, use, acc: dict) -> None:
    """``--photos``: each file through ``align.measure_file`` once per version per round,
    alternated as the synthetic images are; per photo the medians and the paired
    difference, and each swapped function's CPU."""
    from align.marks import measure_file
    for tag in versions:
        use(tag)
        measure_file(args.photos[0])  # first call
    acc.clear()
    calls: dict[tuple[str, Path], list[float]] = {}
    for r in range(args.rounds):
        for p in args.photos:
            for tag in (("this", "other") if r % 2 else ("other", "this")):
                use(tag)
                t0 = time.process_time()
                measure_file(p)
                calls.setdefault((tag, p), []).append(time.process_time() - t0)
    print(f"\n== {len(args.photos)} photos x {args.rounds} rounds, CPU ms per call ==")
    for p in args.photos:
        a, b = 1e3 * np.array(calls[("this", p)]), 1e3 * np.array(calls[("other", p)])
        print(f"{p.name:>24s}: this {np.median(a):7.1f}, other {np.median(b):7.1f}; paired "
              f"difference {np.median(a - b):+7.1f} (median), ratio {np.median(a / b):.3f}")
    n = len(args.photos) * args.rounds
    for dotted in args.swap:
        print(f"  {dotted}: this {1e3 * acc.get(('this', dotted), 0.0) / n:.2f}, other "
              f"{1e3 * acc.get(('other', dotted), 0.0) / n:.2f} ms per photo")
    use("this")


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: two checkouts' functions, paired in one process")
