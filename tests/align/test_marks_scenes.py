"""Random scenes (synth.scenes): marks found anywhere, no gross errors, nothing extra.

Criteria of issue 9: >= 99.5 % of marks found, no |error| > 5 u, no border or clutter
reported as a mark (<= 0.5 % extra). A detection matches a true mark when its direction is
within 1 deg (or 5 u: a lens-limited angle) and its line within 5 px + the groove width of
the truth (pinhole image).
"""

from __future__ import annotations

import numpy as np
import pytest

from align.marks import measure_image
from synth import render_marks
from synth.scenes import SIZES, random_scene
from tests.conftest import angle_error


def _score(seeds, sizes=SIZES, weights=None):
    n_true = n_found = 0
    gross, extra, missed = [], [], []
    for seed in seeds:
        spec = (random_scene(seed, sizes) if weights is None
                else random_scene(seed, sizes, weights))
        s = render_marks(spec, with_crlb=False)
        res = [r for r in measure_image(s.image.astype(float), f"scene {seed}") if r.found]
        used = set()
        for t in s.truth.marks:
            n_true += 1
            for i, r in enumerate(res):
                if i in used:
                    continue
                da = angle_error(r.angle_rad, t.image_angle_rad)
                flip = abs(r.angle_rad - t.image_angle_rad) > np.pi / 2
                off = -r.offset_px if flip else r.offset_px
                # (Within 1 deg, or 5 u of a lens-limited angle: a short mark with k1 fitted
                # free has u ~0.8 deg, and a line 1.3 u off is found, not missed.)
                if (abs(da) < max(np.deg2rad(1), 5 * r.angle_u_rad)
                        and abs(off - t.image_offset_px) < 5 + t.width_px):
                    used.add(i)
                    n_found += 1
                    if abs(da) > 5 * r.angle_u_rad:
                        gross.append((seed, da / r.angle_u_rad))
                    break
            else:
                missed.append(seed)
        extra += [seed] * (len(res) - len(used))
    return n_true, n_found, gross, extra, missed


@pytest.mark.slow
def test_sixteen_small_random_scenes():
    sizes = SIZES[:4]  # up to 1280 x 1024: a few seconds
    n_true, n_found, gross, extra, missed = _score(range(16), sizes, (1, 1, 1, 1))
    assert n_true >= 16
    assert n_found == n_true, f"missed in scenes {missed}"
    assert not gross and not extra, (gross, extra)


@pytest.mark.slow
def test_two_hundred_random_scenes():
    n_true, n_found, gross, extra, missed = _score(range(200))
    print(f"{n_found}/{n_true} found, gross {gross}, extra in {extra}, missed in {missed}")
    assert n_found >= 0.995 * n_true, f"missed in scenes {missed}"
    assert not gross
    assert len(extra) <= 0.005 * n_true, f"extra marks in scenes {extra}"
