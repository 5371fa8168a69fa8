"""synth.ruled: a ruled scale with truth, reproducible, every graduation inside the frame."""

from __future__ import annotations

import numpy as np

from synth.ruled import RuledSpec, random_ruled, render_ruled


def test_ruled_truth_pitch_kinds_and_bits():
    r = render_ruled(RuledSpec(width=800, height=600, pitch_px=50.0, bits=12, seed=2))
    assert r.image.dtype == np.uint16 and r.image.max() <= 4095  # 12-bit data, 16-bit words
    lines = r.truth.lines
    assert len(lines) >= 10
    # Neighbours one pitch apart across the lines, every 5th medium and every 10th long.
    a = r.truth.line_angle_rad
    n = np.array([np.sin(a), np.cos(a)])
    q = np.array([np.array(g.centre_xy_px) @ n for g in lines])
    idx = np.array([g.index for g in lines])
    assert np.allclose(np.diff(q) / np.diff(idx), 50.0)
    for g in lines:
        assert g.kind == ("long" if g.index % 10 == 0 else "medium" if g.index % 5 == 0
                          else "short")
        half = np.array([(r.truth.width - 1) / 2, (r.truth.height - 1) / 2])
        u = np.array([np.cos(g.angle_rad), -np.sin(g.angle_rad)])
        for end in (np.array(g.centre_xy_px) + s * g.length_px / 2 * u for s in (-1, 1)):
            assert np.all(np.abs(end) < half)
    # The groove is dark where the truth says: the image darker on the line than beside it.
    g = lines[len(lines) // 2]
    x, y = np.rint(np.array(g.centre_xy_px) + half).astype(int)
    assert r.image[y, x] < r.image[y, x + 12] - 3 * r.truth.noise_dn_background


def test_ruled_reproducible_and_tilt_recorded():
    s = random_ruled(4, width=640, height=480)
    assert s == random_ruled(4, width=640, height=480)
    a, b = render_ruled(s), render_ruled(s)
    assert np.array_equal(a.image, b.image)
    t = render_ruled(RuledSpec(width=640, height=480, pitch_px=60, tilt=(0, 0.01), seed=1))
    tilted = [g for g in t.truth.lines if g.index == t.truth.tilted]
    assert len(tilted) == 1 and np.isclose(tilted[0].angle_rad, np.pi / 2 + 0.01 - np.pi)


def test_tilted_graduation_in_its_own_place_across_the_wrap():
    """A graduation near 90 deg tilted past it (angle wrapped to near -90 deg) stays where it
    was (the wrap flips the normal: offset and position along it flip with it)."""
    spec = RuledSpec(width=640, height=480, pitch_px=80.0, tilt=(1, np.deg2rad(1.0)),
                     dust=0, dust_on_lines=0, numerals=False, logo=False, seed=3)
    t = render_ruled(spec).truth
    xs = sorted(g.centre_xy_px[0] for g in t.lines)
    assert np.allclose(np.diff(xs), 80.0)


def test_ruler_of_two_tick_lengths():
    """A ruler's two tick lengths (a long one every 5th, the short ones between: medium and
    long alike) at a 24 px pitch in a 400 x 300 frame: two lengths in the truth, the long
    ticks every 5th, and 90 px from their common baseline only the long ones dark."""
    r = render_ruled(RuledSpec(width=400, height=300, pitch_px=24.0,
                               lengths_px=(70.0, 110.0, 110.0), numerals=False, logo=False,
                               dust=0, dust_on_lines=0, seed=4))
    lines = r.truth.lines
    assert len(lines) >= 12
    assert sorted({g.length_px for g in lines}) == [70.0, 110.0]
    for g in lines:
        assert (g.length_px == 110.0) == (g.index % 5 == 0)
    # 90 px along the ticks from their common baseline: only the long ones reach.
    half = np.array([(r.truth.width - 1) / 2, (r.truth.height - 1) / 2])
    for g in lines[len(lines) // 2 - 3: len(lines) // 2 + 3]:
        u = np.array([np.cos(g.angle_rad), -np.sin(g.angle_rad)])
        x, y = np.rint(np.array(g.centre_xy_px) + (90.0 - g.length_px / 2) * u + half
                       ).astype(int)
        beside = float(r.image[y, x + 12])
        dark = r.image[y, x] < beside - 3 * r.truth.noise_dn_background
        assert dark == (g.length_px == 110.0), (g.index, r.image[y, x], beside)
