"""Scribe-mark checks on an independent user's generator (tests/align/test_independent_user3).

Run:  python3 benchmarks/marks_checks.py ROOT centre|offcentre|lay|rot

ROOT is a checkout of this project (``.``, or an older commit's tree for the "before"
figures; the generator is always read from this checkout's tests/). Prints:

* centre: 60 clean straight marks through (within 0.5 px of) the image centre: how many get
  a loop effect (a false radial_distortion), and the angle's z RMS;
* offcentre: 60 clean marks 60-150 px off the centre: the same;
* lay: 20 images with no mark, only a machining lay (2-4x the pixel noise): marks reported;
* rot: 8 marks, the same pixels rotated by 180 / 90 deg or mirrored left-right: the largest
  change of the angle (in u) and of u.
"""

from __future__ import annotations

import sys
from pathlib import Path

import benchpage
import numpy as np
from scipy.ndimage import gaussian_filter

HERE = Path(__file__).resolve().parents[1]


def _angle_z(m, truth_deg: float) -> float:
    err = (np.degrees(m.angle_rad) - truth_deg + 90) % 180 - 90
    return float(err / np.degrees(m.angle_u_rad))


def clean(measure_image, render_mark, through_centre: bool) -> str:
    n = flagged = 0
    z = []
    seeds = (4, 5, 6) if through_centre else (8,)
    for s in seeds:
        rng = np.random.default_rng(s)
        for i in range(20 if through_centre else 60):
            if through_centre:
                kw = dict(angle_deg=rng.uniform(-89, 90), length_px=300,
                          offset_px=rng.uniform(-0.5, 0.5), along_px=rng.uniform(-40, 40),
                          snr=rng.uniform(15, 80), width_px=rng.uniform(2, 7))
            else:
                kw = dict(angle_deg=rng.uniform(-89, 90), length_px=rng.uniform(200, 350),
                          offset_px=rng.choice([-1, 1]) * rng.uniform(60, 150),
                          snr=rng.uniform(15, 80), width_px=rng.uniform(2, 7),
                          texture=rng.choice([0, 0.01]))
            img, _ = render_mark(shape=(480, 640), seed=(1000 * s if through_centre else 5000)
                                 + i, **kw)
            m = measure_image(img)[0]
            n += 1
            flagged += bool(m.loop.effects)
            z.append(_angle_z(m, kw["angle_deg"]))
    where = "through the centre" if through_centre else ">= 60 px off the centre"
    return (f"{where}: {flagged}/{n} with an effect; angle z RMS "
            f"{np.sqrt(np.mean(np.square(z))):.2f}")


def lay(measure_image, render_mark) -> str:
    imgs = found = 0
    for amp in (0.01, 0.02):
        for seed in range(1, 11):
            sig = [(0.7, 25), (1.5, 60), (1.0, 40)][seed % 3]
            img = render_mark(shape=(480, 640), mark=False, seed=5)[0].astype(float)
            streaks = gaussian_filter(np.random.default_rng(seed).normal(size=img.shape), sig)
            img = np.clip(img + amp * 65535 * streaks / streaks.std(), 0, 65535)
            found += sum(m.found for m in measure_image(img.astype(np.uint16)))
            imgs += 1
    return f"machining lay, no mark: {found} marks reported over {imgs} images"


def rot(measure_image, render_mark) -> str:
    rng = np.random.default_rng(21)
    worst_a = worst_u = 0.0
    for i in range(8):
        img, _ = render_mark(shape=(480, 640), angle_deg=rng.uniform(-89, 90),
                             offset_px=rng.uniform(-120, 120), length_px=rng.uniform(150, 380),
                             texture=rng.choice([0, 0.01, 0.02]), seed=700 + i)
        a = measure_image(img)[0]
        for im, sign, turn in ((np.rot90(img, 2), 1, 0), (np.fliplr(img), -1, 0),
                               (np.rot90(img, 1), 1, 90)):
            b = measure_image(np.ascontiguousarray(im))[0]
            back = sign * (np.degrees(b.angle_rad) - turn)
            d = (back - np.degrees(a.angle_rad) + 90) % 180 - 90
            worst_a = max(worst_a, abs(d) / np.degrees(a.angle_u_rad))
            worst_u = max(worst_u, abs(b.angle_u_rad / a.angle_u_rad - 1))
    return (f"rot180/fliplr/rot90 over 8 marks: max |d angle| {worst_a:.2g} u, "
            f"max |d u| {100 * worst_u:.2g} %")


def main() -> None:
    root, what = Path(sys.argv[1]).resolve(), sys.argv[2]
    sys.path[:0] = [str(root), str(HERE)]
    from align.marks import measure_image
    from tests.align.test_independent_user3 import render_mark

    if what in ("centre", "offcentre"):
        print(clean(measure_image, render_mark, what == "centre"))
    elif what == "lay":
        print(lay(measure_image, render_mark))
    else:
        print(rot(measure_image, render_mark))


if __name__ == "__main__":
    benchpage.run(main, "Scribe marks: an independent user's generator")
