"""The lens solver's design cache (align.lens_design): the leave-one-out solves share it."""

from __future__ import annotations

import numpy as np
import pytest

from align.lens_design import LensFolds, LineGeometry, _DesignCache
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


def _correlated(line: LineGeometry, rho: float) -> LineGeometry:
    """The line with its centres' noise correlated (AR(1), ``rho``) as a mark's can be."""
    n = len(line.points)
    c = rho ** np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    return LineGeometry(line.points, line.sigma, np.linalg.cholesky(c))


def test_the_search_reads_every_line_as_its_own_design_does():
    """The exact test's search (``search``: all the lines at once, :mod:`align.lens_search`)
    gives each line's bow as its own design does (the same arithmetic in another order:
    rounding apart), for independent and correlated centres, a vertical mark (its angle on
    the wrap) and a lens off the centre; its slopes are the designs' bows' (central
    differences of whole designs, to their truncation); a folding lens is refused."""
    lines = _lines(5)
    vertical = np.column_stack([np.full(200, 60.0), np.linspace(-120, 120, 200)])
    lines = [lines[0], _correlated(lines[1], 0.6), lines[2], _correlated(lines[3], 0.3),
             LineGeometry(vertical + np.random.default_rng(1).normal(0, 0.05, (200, 2)),
                          np.full(200, 0.05), None)]
    lam = np.array([-0.12, 0.02, 3e-4, -2e-4, 1e-3, 12.0, -7.0])
    cache = _DesignCache(lines, R)
    ref = np.array([d.bow_z for d in cache.all(lam)])
    got = cache.search(lam).bow_z
    assert np.all(np.abs(got - ref) <= 1e-9 * np.maximum(np.abs(ref), 1.0)), (got, ref)
    # ... and the Gauss-Newton system the designs sum (a fit that only decides reads it).
    F, b, cost = cache.search(lam).normal
    ds = cache.all(lam)
    F_ref, b_ref = sum(d.G.T @ d.G for d in ds), sum(d.G.T @ d.z for d in ds)
    cost_ref = sum(float(d.z @ d.z) for d in ds)
    np.testing.assert_allclose(F, F_ref, rtol=1e-9, atol=1e-9 * np.abs(F_ref).max())
    np.testing.assert_allclose(b, b_ref, rtol=1e-9, atol=1e-9 * np.abs(b_ref).max())
    assert abs(cost - cost_ref) <= 1e-9 * cost_ref
    cols = [0, 1, 2, 3, 4, 5, 6]
    step = np.array([1e-4, 1e-4, 1e-6, 1e-6, 1e-5, 0.01, 0.01])
    fd = np.zeros((len(lines), len(cols)))
    for j in cols:
        e = np.zeros(7)
        e[j] = step[j]
        up = [d.bow_z for d in _DesignCache(lines, R).all(lam + e)]
        down = [d.bow_z for d in _DesignCache(lines, R).all(lam - e)]
        fd[:, j] = (np.array(up) - np.array(down)) / (2 * step[j])
    slope = cache.bow_jacobian(lam, cols)
    scale = np.abs(fd).max(axis=0)
    assert np.all(np.abs(slope - fd) <= 1e-5 * scale), (slope, fd)
    folds = np.array([-3.0, 0, 0, 0, 0, 0, 0])
    with pytest.raises(LensFolds):
        cache.search(folds)
