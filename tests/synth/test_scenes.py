"""synth.scenes: reproducible random scenes whose marks lie inside the frame."""

from __future__ import annotations

import numpy as np

from synth import render_marks
from synth.scenes import MIN_MARK_PX, SIZES, random_scene


def test_scenes_are_reproducible_and_marks_inside_the_frame():
    assert random_scene(3) == random_scene(3)
    near_axis = 0
    n = 0
    for seed in range(300):
        spec = random_scene(seed)
        assert (spec.width, spec.height) in SIZES and spec.bits in (8, 12, 16)
        assert len(spec.marks) <= 3
        for m in spec.marks:
            n += 1
            assert m.length_px >= MIN_MARK_PX
            u = np.array([np.cos(m.angle_rad), -np.sin(m.angle_rad)])
            mid = np.array(m.centre_xy())
            for end in (mid - m.length_px / 2 * u, mid + m.length_px / 2 * u):
                assert abs(end[0]) < (spec.width - 1) / 2 and abs(end[1]) < (spec.height - 1) / 2
            a = abs(np.rad2deg(m.angle_rad))
            near_axis += a < 1 or a > 89
    # Half the marks near the axes (30 % + 20 % by construction, binomial spread).
    assert 0.4 < near_axis / n < 0.6


def test_twelve_bit_and_padding():
    spec = random_scene(0, sizes=((320, 240),), weights=(1.0,))
    from dataclasses import replace

    s = render_marks(replace(spec, bits=12, padding_px=3), with_crlb=False)
    assert s.image.dtype == np.uint16 and s.image.max() <= 4095
    assert not s.image[:3].any() and not s.image[:, -3:].any()
