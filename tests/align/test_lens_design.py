"""The lens solver's design cache (align.lens_design): the leave-one-out solves share it."""

from __future__ import annotations

import numpy as np

from align.lens_design import LineGeometry, _DesignCache
from imaging.lens import distort_points

R = 400.0
"""Half-diagonal [px] of a 640x480 frame."""


def _lines(seed: int) -> list[LineGeometry]:
    """Five straight 200 px marks across a 640x480 frame through a k1 = -0.1 lens (centres
    with 0.05 px white noise)."""
    rng = np.random.default_rng(seed)
    lam = np.zeros(7)
    lam[0] = -0.1
    out = []
    for x, y, a in ((-180, -130, 10), (170, 120, 70), (200, -100, -30), (-150, 140, -60),
                    (0, 0, 45)):
        a = np.radians(a)
        q = np.array([x, y]) + np.outer(np.linspace(-100, 100, 200), [np.cos(a), -np.sin(a)])
        raw = distort_points(q, lam, R) + rng.normal(0, 0.05, q.shape)
        out.append(LineGeometry(raw, np.full(len(q), 0.05), None))
    return out


def test_a_cache_without_one_line_gives_each_other_line_its_own_design():
    """``without(k)``'s line i is the parent's line i (i < k) or i + 1: a design computed
    through the parent is found under the right line (keyed by the parent's index, not
    the subset's), and a design computed first through the subset is the fresh cache's.
    Keyed by the subset's index, line 1 of ``without(0)`` would read line 1's design."""
    lines = _lines(3)
    lam = np.array([-0.08, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    parent = _DesignCache(lines, R)
    parent.all(lam)
    for k in (0, 2, 4):
        sub = parent.without(k)
        fresh = _DesignCache([ln for i, ln in enumerate(lines) if i != k], R)
        assert len(sub.lines) == len(lines) - 1
        for lm in (lam, np.zeros(7)):  # shared (from the parent) and new (from the subset)
            for a, b in zip(sub.all(lm), fresh.all(lm), strict=True):
                assert a.angle == b.angle
                np.testing.assert_array_equal(a.G, b.G)
                np.testing.assert_array_equal(a.z, b.z)
    # ... and what the subsets computed at zero is the parent's line for line.
    for a, b in zip(parent.all(np.zeros(7)), _DesignCache(lines, R).all(np.zeros(7)),
                    strict=True):
        assert a.angle == b.angle
