"""synth.dial: graduations on radii of the centre asked, at the increment asked."""

from __future__ import annotations

import numpy as np

from synth.dial import DialSpec, render_dial


def test_dial_graduations_radial_from_the_centre():
    spec = DialSpec(centre_px=(12.0, -7.0), n_lines=12, increment_rad=np.deg2rad(30.0),
                    inner_px=60.0, width=480, height=480, dust=0, seed=1)
    s = render_dial(spec)
    c = np.array(spec.centre_px)
    for m, th in zip(s.truth.marks, spec.directions(), strict=True):
        n = np.array([np.sin(m.angle_rad), np.cos(m.angle_rad)])
        assert abs(c @ n - m.offset_px) < 1e-9  # the line passes through the centre
        mid = np.array(m.centre_xy_px)
        d = mid - c
        assert np.isclose(np.arctan2(-d[1], d[0]) % (2 * np.pi), th % (2 * np.pi))
    # The groove is dark where the truth puts the first graduation's middle.
    x, y = np.rint(np.array(s.truth.marks[0].centre_xy_px) + 239.5).astype(int)
    assert s.image[y, x] < s.image[240, 240]
