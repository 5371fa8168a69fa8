"""synth.occlusion: opaque particles and ink over grooves (replace the surface, blur conserves
light)."""

from __future__ import annotations

import numpy as np

from synth.marks import ImageSpec, MarkSpec, _mark_band, mark_coverage
from synth.occlusion import disk, occlude, sharp_reflectance, strokes
from synth.optics import CameraGeometry


def _scene(h=80, w=80, blur=1.0):
    """A vertical groove through the middle of the frame, rendered as synth.marks does."""
    m = MarkSpec(np.pi / 2, 0.0, 60.0, 4.0, 0.0, "box", -0.6)
    spec = ImageSpec(marks=(m,), width=w, height=h, blur_px=blur)
    refl = np.ones((h, w))
    r, c = _mark_band(spec, m, 7 * blur + 3)
    refl[r, c] += m.contrast * mark_coverage(spec, m, r, c)
    return refl, m


def test_black_particle_hides_the_groove_under_it():
    refl, m = _scene()
    occlude(refl, [disk(0.0, 30.0, 8.0, level=0.0)], [m], blur_px=1.0)
    # Within the particle (away from its blurred rim) nothing is seen: groove or not.
    assert abs(refl[69, 39]) < 0.02 and abs(refl[69, 44]) < 0.02
    # Far from it the scene is untouched.
    assert refl[10, 10] == 1.0


def test_light_removed_equals_what_the_particle_covers():
    """Blur moves light, never makes it: the sum over the frame of the change equals
    o * integral of M (b - R) over the particle (R sharp, sampled finely)."""
    refl, m = _scene(blur=1.5)
    before = refl.copy()
    r, level, o = 6.0, 1.6, 0.8
    occlude(refl, [disk(0.5, 28.0, r, level=level, opacity=o)], [m], blur_px=1.5)
    xs = np.arange(-10, 10, 0.02)
    X, Y = np.meshgrid(xs + 0.5, xs + 28.0)
    inside = np.hypot(X - 0.5, Y - 28.0) <= r
    expect = o * np.sum(inside * (level - sharp_reflectance([m], CameraGeometry(), X, Y))) \
        * 0.02**2
    assert np.isclose((refl - before).sum(), expect, rtol=0.01)


def test_transparent_ink_changes_nothing_and_ink_crosses_a_groove():
    refl, m = _scene(blur=0.5)
    before = refl.copy()
    occlude(refl, [strokes([(np.array([-10.0, 0.0]), np.array([10.0, 0.0]))], 3.0,
                           opacity=0.0)], [m], blur_px=0.5)
    assert np.array_equal(refl, before)
    assert refl[40, 40] < 0.5  # the groove
    occlude(refl, [strokes([(np.array([-10.0, 0.0]), np.array([10.0, 0.0]))], 3.0,
                           level=0.05)], [m], blur_px=0.5)
    # Where the bar crosses the groove the ink's level is seen, not the groove's.
    assert abs(refl[40, 40] - 0.05) < 0.05 and abs(refl[40, 34] - 0.05) < 0.05

