"""interp_uniform: np.interp's values to the last bit on an np.arange grid."""

from __future__ import annotations

import numpy as np

from axisbase.interp import interp_uniform, uniform_slopes


def test_the_same_bits_as_np_interp():
    """Random points, the grid's own points, its ends, beyond it, NaN: left and right 0."""
    rng = np.random.default_rng(3)
    for lo, hi, step in ((-12.3, 12.3, 0.004), (-1.0, 2.0, 0.1), (0.0, 5.0, 0.25)):
        grid = np.arange(lo, hi + step / 2, step)
        f, g = np.sin(grid) * np.exp(-grid**2 / 50), np.cos(3 * grid)
        e = np.concatenate([rng.uniform(lo - 1, hi + 1, 20000), grid, grid[[0, -1]],
                            [lo - step, grid[-1] + 1e-12, np.nan, np.inf, -np.inf]])
        got = interp_uniform(e, grid, (f, g))
        for v, want in zip(got, (f, g), strict=True):
            assert np.array_equal(v, np.interp(e, grid, want, left=0.0, right=0.0),
                                  equal_nan=True)
        # A table's slopes kept by the caller: the same bits, inside the grid and not.
        for pts in (e, rng.uniform(lo, hi - step, 5000)):
            kept = interp_uniform(pts, grid, (f, g), uniform_slopes(grid, (f, g)))
            for v, want in zip(kept, (f, g), strict=True):
                assert np.array_equal(v, np.interp(pts, grid, want, left=0.0, right=0.0),
                                      equal_nan=True)


def test_the_shape_of_the_points_is_kept():
    grid = np.arange(0.0, 1.0, 0.01)
    e = np.linspace(-0.2, 1.2, 24).reshape(2, 3, 4)
    (v,) = interp_uniform(e, grid, (grid,))
    assert v.shape == (2, 3, 4) and np.array_equal(v, np.interp(e, grid, grid, 0.0, 0.0))
