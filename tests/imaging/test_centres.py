"""Segment fits of the groove's centres (imaging.centres): which segments are solved."""

from __future__ import annotations

import numpy as np

from imaging.centres import RCOND, _conditioned


def _normal(J: np.ndarray) -> np.ndarray:
    return J.T @ J


def test_a_nearly_singular_segment_is_not_solved_whatever_the_rounding():
    """A segment whose centre and contrast columns are the same to 1e-9 (its pixels on one
    flank: the two not separated) has det(N) > 0 by rounding, or < 0, depending on noise of
    1e-14 in its pixels: the old test (det > 0) flipped with it. Its reciprocal condition
    (~1e-18) is far below RCOND, so it is refused under every such perturbation; a
    well-posed segment (independent columns) is solved under all of them."""
    rng = np.random.default_rng(1)
    x = np.linspace(-1, 1, 60)
    base = np.column_stack([x, x * (1 + 1e-9 * x**2), np.ones_like(x), x**2])
    good = np.column_stack([np.tanh(3 * x), np.exp(-x**2), np.ones_like(x), x])
    dets = []
    for _ in range(20):
        noise = 1 + 1e-14 * rng.standard_normal(base.shape)
        N = np.stack([_normal(base * noise), _normal(good * noise)])
        dets.append(np.linalg.det(N[0]) > 0)
        assert _conditioned(N).tolist() == [False, True]
    assert set(dets) == {True, False}  # rounding alone decided the old test here


def test_rcond_is_scale_free():
    """The test reads the matrix at unit diagonal: the columns' units (px, DN, DN/px) or a
    contrast of 1e4 DN do not decide it."""
    x = np.linspace(-1, 1, 60)
    J = np.column_stack([np.tanh(3 * x), np.exp(-x**2), np.ones_like(x), x])
    N = _normal(J)
    D = np.diag([1e4, 1e-3, 1.0, 50.0])
    assert _conditioned(np.stack([N, D @ N @ D])).tolist() == [True, True]
    assert 0 < RCOND < 1e-6
