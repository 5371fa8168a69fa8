"""Two marks crossing at a shallow angle (issue 18): never merged into a phantom, never a
confident wrong number.

Two straight 300 px grooves (synth, physical render, SNR 50) cross at 3-30 deg, in both
marks' middles or near the end of one. Each true mark is found once with its angle within
3 u, or the crossing is refused by a failed entry that names the pixel region; no reported
line matches no true mark. A report matches a true mark when its direction is within 0.3 deg
and its line within 3 px + the groove width of it (a fused ridge between two marks crossing
at 3 deg lies 1.5 deg from each).
"""

from __future__ import annotations

import numpy as np
import pytest

from align import LensRanges, measure_image
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error

LENGTH_PX = 300.0
WIDTH_PX = 4.0


def crossing_scene(delta_deg: float, where: str, seed: int) -> ImageSpec:
    """Two marks crossing at ``delta_deg`` within 30 px of the centre of a 640 x 480 frame;
    ``where``: "middle" (both marks' middles) or "end" (40 % of the length from one mark's
    middle, i.e. 30 px from its end; anywhere in the middle 40 % of the other)."""
    r = np.random.default_rng(seed)
    a1 = np.deg2rad(r.uniform(-60, 60))
    a2 = a1 + np.deg2rad(delta_deg) * r.choice([-1, 1])
    p = r.uniform(-30, 30, 2)  # the crossing point [px from the centre, x right, y down]
    shares = (0.0, 0.0) if where == "middle" else (0.4, r.uniform(-0.2, 0.2))
    marks = []
    for a, share in ((a1, shares[0]), (a2, shares[1])):
        u = np.array([np.cos(a), -np.sin(a)])
        n = np.array([np.sin(a), np.cos(a)])
        shift = share * LENGTH_PX * r.choice([-1, 1])
        marks.append(MarkSpec(a, float(p @ n), LENGTH_PX, WIDTH_PX,
                              centre_t_px=float(p @ u - shift)))
    return ImageSpec(marks=tuple(marks), width=640, height=480,
                     full_well_e=full_well_for_snr(50, -0.6), seed=seed)


def judge(spec: ImageSpec) -> tuple[list[int], list[float], int, list[str]]:
    """(times each true mark was reported, z of the reports that match one, reports that
    match none, errors of the failed entries)."""
    img = render_marks(spec, with_crlb=False).image.astype(float)
    res = measure_image(img, "x.png", ranges=LensRanges.none())
    hits, zs, phantoms = [0] * len(spec.marks), [], 0
    for r in (r for r in res if r.found):
        matched = False
        for k, t in enumerate(spec.marks):
            da = angle_error(r.angle_rad, t.angle_rad)
            off = -r.offset_px if abs(r.angle_rad - t.angle_rad) > np.pi / 2 else r.offset_px
            if abs(da) < np.deg2rad(0.3) and abs(off - t.offset_px) < 3 + WIDTH_PX:
                hits[k] += 1
                zs.append(float(da / r.angle_u_rad))
                matched = True
                break
        phantoms += not matched
    return hits, zs, phantoms, [r.error for r in res if not r.found]


def check(spec: ImageSpec) -> None:
    hits, zs, phantoms, errors = judge(spec)
    assert phantoms == 0, (hits, zs, errors)
    assert max(hits) <= 1, hits  # never the same mark twice
    assert all(abs(z) <= 3.0 for z in zs), zs
    if min(hits) == 0:  # a mark not reported: the crossing is refused, naming its pixels
        assert errors and all("pixel (x" in e and "cannot be measured apart" in e
                              for e in errors), errors


@pytest.mark.parametrize("delta_deg,where,seed", [(12.0, "end", 1001), (8.0, "middle", 1000)])
def test_crossing_marks_both_measured_with_the_crossing_left_out(delta_deg, where, seed):
    spec = crossing_scene(delta_deg, where, seed)
    img = render_marks(spec, with_crlb=False).image.astype(float)
    res = measure_image(img, "x.png", ranges=LensRanges.none())
    assert len(res) == 2 and all(r.found for r in res), [r.error for r in res]
    # (near one mark's end the crossing may lie beyond that mark's measured stretch)
    assert any(any("crossing with mark" in n and "px excluded" in n for n in r.notes)
               for r in res), [r.notes for r in res]
    check(spec)


def test_marks_crossing_at_3_deg_are_refused_naming_the_region():
    """At 3 deg two 300 px grooves lie within each other's profile window over their whole
    length: no number, a failed entry (the result is then not ok)."""
    spec = crossing_scene(3.0, "middle", 1000)
    hits, zs, phantoms, errors = judge(spec)
    assert hits == [0, 0] and phantoms == 0 and errors, (hits, zs, errors)
    check(spec)


@pytest.mark.slow
@pytest.mark.parametrize("where", ["middle", "end"])
@pytest.mark.parametrize("delta_deg", [3.0, 5.0, 8.0, 12.0, 20.0, 30.0])
def test_crossings_over_seeds(delta_deg, where):
    for seed in range(2000, 2006):
        check(crossing_scene(delta_deg, where, seed))
