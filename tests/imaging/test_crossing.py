"""imaging.crossing: two crossing lines told apart from one, two grooves from one, and the
stretch one mark's groove lies in the other's window."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from imaging.crossing import (
    crossing_stretch,
    double_groove,
    double_grooves,
    fused_crossing,
    split_two_lines,
)


def _line_pixels(angle_deg, length, shift=(0.0, 0.0), bow=0.0):
    """Integer pixels of a 1 px wide ridge (x right, y down), optionally bowed (sagitta)."""
    a = np.deg2rad(angle_deg)
    s = np.arange(-length / 2, length / 2 + 1)
    u, n = np.array([np.cos(a), -np.sin(a)]), np.array([np.sin(a), np.cos(a)])
    e = bow * (1 - (2 * s / length) ** 2)
    return np.unique(np.rint(np.asarray(shift) + s[:, None] * u + e[:, None] * n), axis=0)


@pytest.mark.parametrize("delta", [6.0, 10.0, 25.0])
def test_two_crossing_ridges_are_split_into_their_lines(delta):
    pts = np.vstack([_line_pixels(20, 120, (100, 100)), _line_pixels(20 + delta, 120, (100, 100))])
    two = split_two_lines(pts, min_piece=6.0)
    assert two is not None
    got = sorted(np.rad2deg(np.arctan2(-(np.linalg.eigh(np.cov(p.T))[1][1, 1]),
                                       np.linalg.eigh(np.cov(p.T))[1][0, 1])) % 180 for p in two)
    assert got == pytest.approx([20, 20 + delta], abs=1.0)


@pytest.mark.parametrize("bow", [0.0, 2.0, 4.0])
def test_one_straight_or_bowed_ridge_is_not_split(bow):
    assert split_two_lines(_line_pixels(15, 150, (80, 80), bow), min_piece=6.0) is None


def _grooves(centres, e, depth=1000.0, sigma=1.5, bg=3000.0):
    return bg - sum(depth * np.exp(-0.5 * ((e - c) / sigma) ** 2) for c in centres)


def test_double_groove_finds_two_and_not_one():
    e = np.arange(-20.0, 21.0)
    rng = np.random.default_rng(3)
    noise = 10.0
    two = _grooves([-5.0, 4.0], e) + rng.normal(0, noise, e.size)
    one = _grooves([0.5], e, sigma=2.5) + rng.normal(0, noise, e.size)
    assert double_groove(two, e, True, noise, 2.5) == (-5.0, 4.0)
    assert double_groove(one, e, True, noise, 2.5) is None
    # bright grooves the same way
    assert double_groove(2 * 3000 - two, e, False, noise, 2.5) == (-5.0, 4.0)


def test_fused_ridge_is_where_grooves_straddle_the_line():
    straddle = [(t, (-0.05 * abs(t) - 2, 0.05 * abs(t) + 2)) for t in (-100, -60, 60, 100)]
    beside = [(t, (0.0, 0.1 * t)) for t in (40, 80, 120)]  # a true mark: one groove on it
    # the widest place whose grooves are close enough to make one ridge (5 half-widths)
    assert fused_crossing(straddle + [(0, None)], 2.5) == (-60, pytest.approx(10.0))
    assert fused_crossing(beside + [(0, None)], 2.5) is None
    # two neighbours 28 px apart either side (a scale's lines, a speck beside a line's end)
    apart = [(t, (-14.0, 14.0)) for t in (-40, 0, 40)]
    assert fused_crossing(apart, 2.5) is None


def test_crossing_stretch_is_the_window_over_sin_angle():
    c = SimpleNamespace(angle_rad=0.0, offset_px=0.0, t_start_px=-150.0, t_end_px=150.0)
    a = np.deg2rad(10.0)
    o = SimpleNamespace(angle_rad=a, offset_px=0.0, t_start_px=-150.0, t_end_px=150.0)
    t0, t1, at = crossing_stretch(c, o, 12.0)
    half = 12.0 / np.sin(a) * np.cos(a)  # o within 12 px of c's line, projected on c
    assert (t0, t1) == pytest.approx((-half, half), rel=1e-9)
    assert at == pytest.approx([0.0, 0.0], abs=1e-9)
    # o ending 80 px before the crossing: nothing, unless its groove may run on (extend)
    short = SimpleNamespace(angle_rad=a, offset_px=0.0, t_start_px=80.0, t_end_px=150.0)
    assert crossing_stretch(c, short, 12.0) is None
    assert crossing_stretch(c, short, 12.0, extend=True) is not None
    parallel = SimpleNamespace(angle_rad=0.001, offset_px=5.0, t_start_px=-150.0, t_end_px=150.0)
    assert crossing_stretch(c, parallel, 12.0) is None


def test_two_graduations_of_one_diameter_do_not_cross():
    """Two pieces of nearly one line (a dial's graduations on one diameter, their coarse
    angles 1.5 deg apart), the dial's centre between them: not a crossing, even though the
    lines meet (found on a dial of 10 graduations, which refused one as crossing another).
    The same geometry with the other piece ending at this one (a 3 deg crossing whose ridge
    was lost where the two fuse) still is one."""
    c = SimpleNamespace(angle_rad=np.deg2rad(-0.48), offset_px=-23.7, t_start_px=-208.0,
                        t_end_px=-120.0)
    far = SimpleNamespace(angle_rad=np.deg2rad(1.05), offset_px=-27.5, t_start_px=86.0,
                          t_end_px=208.0)
    assert crossing_stretch(c, far, 12.9, extend=True) is None
    c2 = SimpleNamespace(angle_rad=np.deg2rad(-11.25), offset_px=27.1, t_start_px=-131.0,
                         t_end_px=121.0)
    near = SimpleNamespace(angle_rad=np.deg2rad(-9.12), offset_px=27.8, t_start_px=151.0,
                           t_end_px=263.0)
    assert crossing_stretch(c2, near, 12.9, extend=True) is not None


def test_double_grooves_gives_double_groove_of_every_row():
    """The blocks' test at once (imaging.crossing.double_grooves) answers as
    double_groove does row by row: one groove or two, dark or bright, with a NaN in a row,
    and with whole-DN values (ties between neighbours, the peaks' >= / > matter)."""
    rng = np.random.default_rng(7)
    e = np.arange(-20.0, 21.0)
    found = rows = 0
    for trial in range(300):
        prof = rng.normal(1000.0, 3.0, (12, e.size))
        prof -= rng.uniform(0, 60) * np.exp(-0.5 * ((e - rng.uniform(-3, 3)) / 1.5) ** 2)
        if trial % 2:  # a second groove beside the first
            prof -= rng.uniform(0, 60) * np.exp(-0.5 * ((e - rng.uniform(-12, 12)) / 1.5) ** 2)
        if trial % 5 == 0:
            prof[rng.integers(12), rng.integers(e.size)] = np.nan
        if trial % 3 == 0:
            prof = np.round(prof)
        dark = trial % 4 < 2
        if not dark:
            prof = 2000.0 - prof
        one = [double_groove(p, e, dark, 1.0, 2.5) for p in prof]
        assert double_grooves(prof, e, dark, 1.0, 2.5) == one
        found += sum(g is not None for g in one)
        rows += len(one)
    assert 0.1 * rows < found < 0.9 * rows  # both answers are exercised
