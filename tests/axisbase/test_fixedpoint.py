"""iterate_elementwise: the same bits as iterating the whole arrays, converged points left alone."""

from __future__ import annotations

import numpy as np

from axisbase.fixedpoint import iterate_elementwise


def _whole(step, start, iters):
    vals = [np.array(v, float).ravel() for v in start]
    at = np.arange(vals[0].size)
    for _ in range(iters):
        vals = list(step(at, *vals))
    return [v.reshape(np.shape(s)) for v, s in zip(vals, start, strict=True)]


def test_the_same_bits_as_every_step_on_the_whole_array():
    """Newton on a radial lens over a frame's points: most converge in ~5 steps, some
    alternate in the last bit to the end (both kinds are there), a NaN stays NaN."""
    rng = np.random.default_rng(5)
    rd = np.append(rng.uniform(0, 0.5, (300, 7)).ravel(), [np.nan, 0.0])
    k1, k2 = -0.2, 0.05

    def step(at, ru):
        r2 = ru * ru
        g = ru * (1 + k1 * r2 + k2 * r2 * r2) - rd[at]
        return (ru - g / (1 + 3 * k1 * r2 + 5 * k2 * r2 * r2),)

    (fast,) = iterate_elementwise(step, (rd,), 12)
    (slow,) = _whole(step, (rd,), 12)
    assert np.array_equal(fast, slow, equal_nan=True)
    (one_less,) = _whole(step, (rd,), 11)
    assert np.any(one_less != slow)  # some points still alternate: they took every step
    assert np.isnan(fast[-2]) and fast[-1] == 0.0


def test_two_coordinates_and_the_shape_kept():
    x0, y0 = np.linspace(-1, 1, 12).reshape(3, 4), np.linspace(0.5, -0.5, 12).reshape(3, 4)

    def step(at, x, y):
        return (x + y) / 2, np.sqrt(np.abs(x * y))  # (the arithmetic-geometric mean)

    fast = iterate_elementwise(step, (x0, y0), 30)
    slow = _whole(step, (x0, y0), 30)
    assert all(f.shape == (3, 4) and np.array_equal(f, s) for f, s in zip(fast, slow,
                                                                               strict=True))
