"""The band fit stopped at its step cap against the same fit run to convergence, on renders
with known truth: is the angle a photo gets hostage to where the fit stops?

The band fit (:func:`imaging.profile.fit_profile`) stops at 25 accepted Levenberg–Marquardt
steps; on a groove narrower than its blur it is still crawling along the width–blur valley
there. Each render is measured twice by the whole pipeline (``align.marks.measure_image``),
once as shipped and once with the cap raised to ``--converged`` steps, and each angle
compared with the truth: error / u (z) for both, and the shift between them in u.

Run: ``PYTHONPATH=. python3 benchmarks/band_convergence.py [--count N] [--sweeps narrow]``,
or ``--photos`` for the real photos (no truth: how far each result moves).
"""

from __future__ import annotations

import argparse
import glob
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import imaging.profile as prof
from align.lens import LensRanges
from align.marks import measure_image
from imaging import ImageInputError, measure_marks
from imaging.detect import wrap_angle
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks
from synth.scenes import SIZES, random_scene


@dataclass(frozen=True)
class _Line:
    """A line fit's angle and its u [rad] (the fields _match reads)."""

    angle_rad: float
    angle_u_rad: float


def _set_cap(cap: int) -> None:
    """The band fit's step cap for what follows (read at each fit)."""
    prof.BAND_FIT_STEPS = cap


def _match(res, truth):
    """(error, u) of each true mark's detection (nearest direction within 1 deg), or None."""
    out = []
    for t in truth.marks:
        best = None
        for r in res:
            da = wrap_angle(r.angle_rad - t.image_angle_rad)
            if abs(da) < np.deg2rad(1) and (best is None or abs(da) < abs(best[0])):
                best = (da, r.angle_u_rad)
        out.append(best)
    return out


def _both(spec, caps, **kw):
    """Each cap's [(error, u) per true mark] for one render, and its CPU time [s]."""
    s = render_marks(spec, with_crlb=False)
    img = s.image.astype(float)
    rows, cpu = [], []
    for cap in caps:
        _set_cap(cap)
        t = time.process_time()
        if kw.get("line"):
            # The line fit alone (imaging.measure_marks), its u the pixels' only: no lens,
            # JPEG or loop terms, which on an undeclared lens dwarf it.
            try:
                found = measure_marks(img)
            except ImageInputError:  # none found: a miss, counted as such
                found = []
            res = [_Line(m.line.angle_rad, m.line.angle_u_rad)
                   for m in found if not isinstance(m, Exception)]
        else:
            res = [r for r in measure_image(img, "render", **kw) if r.found]
        cpu.append(time.process_time() - t)
        rows.append(_match(res, s.truth))
    return rows, cpu


def _narrow(seed: int) -> ImageSpec:
    """A groove narrower than its blur (1-2.5 px under 3-5 px), as on the real photos,
    at a random angle in a 640x480 frame; SNR 40-80 (fainter ones are not detected)."""
    rng = np.random.default_rng(10_000 + seed)
    mark = MarkSpec(rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(-100, 100),
                    rng.uniform(200, 350), rng.uniform(1.0, 2.5),
                    contrast=-rng.uniform(0.6, 0.9))
    return ImageSpec(marks=(mark,), width=640, height=480, seed=seed,
                     blur_px=rng.uniform(3.0, 5.0),
                     full_well_e=full_well_for_snr(rng.uniform(40, 80), -0.6))


def _measure_like(seed: int) -> ImageSpec:
    """tests/imaging/test_measure.py's sweep: a 500 px, 4 px mark at SNR 20."""
    return ImageSpec(marks=(MarkSpec(np.deg2rad(12.0 + 5 * seed), 12.3, 500.0, 4.0),),
                     width=800, height=600, full_well_e=full_well_for_snr(20, -0.6), seed=seed)


def _held_out(seed: int) -> ImageSpec:
    """tests/align/test_lens_crlb.py's held-out mark (k1 -0.3)."""
    rng = np.random.default_rng(seed)
    mark = MarkSpec(rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(-150, 150), 300.0, 4.0,
                    centre_t_px=rng.uniform(-80, 80))
    return ImageSpec(marks=(mark,), width=640, height=480, seed=seed, supersample=4,
                     camera=CameraGeometry(focal_px=1024.0, k1=-0.3),
                     full_well_e=full_well_for_snr(40, -0.6))


def _effects(d: dict) -> str:
    """A saved result's effects and flags, short."""
    names = [e["name"] for e in d.get("effects") or []]
    if d.get("uncertainty_inflation", 1.0) != 1.0:
        names.append(f"x{d['uncertainty_inflation']:.2f}")
    return ",".join(names) or "-"


def photos(caps) -> None:
    """Each real photo's marks at both caps: the angle's move in u (after and before the
    residual loop), u's ratio, the band fit's width/blur, and the loop's effects."""
    from align.marks import measure_file
    paths = sorted(glob.glob("/work/shared/data/real/opencv-*/*.jpg"))
    print(f"{'photo':14} {'#':>2} {'d/u':>6} {'pre-loop':>8} {'u ratio':>7} "
          f"{'width px':>11} {'blur px':>9}  effects (cap -> converged)")
    for p in paths:
        runs = []
        for cap in caps:
            _set_cap(cap)
            runs.append([r.to_dict() for r in measure_file(p)])
        for a, b in zip(*runs, strict=False):  # (the count may differ: said below)
            if not (a["found"] and b["found"]):
                if a["found"] != b["found"]:
                    print(f"{Path(p).name:14} {a['index']:2d} found {a['found']} -> {b['found']}")
                continue
            u = a["angle_u_rad"]
            print(f"{Path(p).name:14} {a['index']:2d} "
                  f"{(b['angle_rad'] - a['angle_rad']) / u:+6.2f} "
                  f"{(b['angle_before_loop_rad'] - a['angle_before_loop_rad']) / u:+8.2f} "
                  f"{b['angle_u_rad'] / u:7.2f} {a['width_px']:5.1f}>{b['width_px']:5.1f} "
                  f"{a['blur_px']:4.1f}>{b['blur_px']:4.1f}  {_effects(a)} -> {_effects(b)}",
                  flush=True)
        if len(runs[0]) != len(runs[1]):
            print(f"{Path(p).name:14} marks {len(runs[0])} -> {len(runs[1])}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--converged", type=int, default=1000, help="the raised cap [steps]")
    ap.add_argument("--count", type=int, help="renders per sweep (default 40/16/40/16)")
    ap.add_argument("--sweeps", default="narrow,narrow_line,measure,measure_line,held_out,scenes")
    ap.add_argument("--photos", action="store_true",
                    help="the real photos (../shared/data/real) instead: no truth, the moves")
    a = ap.parse_args()
    if a.photos:
        photos((25, a.converged))
        return
    n = a.count
    k1 = LensRanges(k1=0.3, k2=0.0, p=0.0, aspect=0.0, pp_px=0.0)
    sweeps = {
        "narrow": (lambda i: _narrow(i), n or 40, {}),
        "narrow_line": (lambda i: _narrow(i), n or 40, {"line": True}),
        "measure": (lambda i: _measure_like(i), n or 16, {}),
        "measure_line": (lambda i: _measure_like(i), n or 16, {"line": True}),
        "held_out": (lambda i: _held_out(i), n or 40, {"ranges": k1, "expect_one": True}),
        "scenes": (lambda i: random_scene(i, SIZES[:4], (1, 1, 1, 1)), n or 16, {}),
    }
    caps = (25, a.converged)
    print(f"{'sweep':9} {'marks':>5} {'cap':>5} {'RMS z':>6} {'max|z|':>6} {'|z|>3':>5} "
          f"{'CPU s':>6}  shift between the two [u]: RMS, max")
    for name in a.sweeps.split(","):
        make, count, kw = sweeps[name]
        z = {c: [] for c in caps}
        ev = {c: [] for c in caps}  # CPU s per render
        shift = []
        for i in range(count):
            rows, cpu = _both(make(i), caps, **kw)
            for c, r, e in zip(caps, rows, cpu, strict=True):
                z[c] += [np.nan if m is None else m[0] / m[1] for m in r]
                ev[c].append(e)
            shift += [np.nan if p is None or q is None else (q[0] - p[0]) / p[1]
                      for p, q in zip(rows[0], rows[1], strict=True)]
        for c in caps:
            zz = np.array(z[c])
            ok = zz[np.isfinite(zz)]
            print(f"{name:9} {ok.size:5d} {c:5d} {np.sqrt(np.mean(ok**2)):6.2f} "
                  f"{np.max(np.abs(ok)):6.2f} {np.sum(np.abs(ok) > 3):5d} "
                  f"{np.sum(ev[c]):6.1f}"
                  + (f"  {np.sqrt(np.nanmean(np.square(shift))):.3f}, "
                     f"{np.nanmax(np.abs(shift)):.3f}" if c == caps[1] else ""), flush=True)


if __name__ == "__main__":
    main()
