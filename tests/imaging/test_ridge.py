"""The coarse search's ridge filter helpers: the MAD its threshold takes."""

from __future__ import annotations

import numpy as np

from imaging.ridge import median_abs_deviation


def test_median_abs_deviation_is_numpys_bit_for_bit():
    """One selection per median gives float(np.median(np.abs(a - np.median(a)))) exactly:
    odd and even counts, ties, float32 and float64, strided 2-D views (the search's
    every-third sample of its response), NaN anywhere (NaN, as numpy's)."""
    rng = np.random.default_rng(18)
    for k in range(300):
        shape = (int(rng.integers(1, 60)), int(rng.integers(1, 60)))
        a = rng.normal(rng.uniform(-50, 50), rng.uniform(1e-3, 1e3), size=shape)
        if k % 3 == 0:
            a = np.round(a)  # ties
        a = a.astype(np.float32 if k % 2 else np.float64)
        view = a[::int(rng.integers(1, 4)), ::int(rng.integers(1, 4))]
        if k % 29 == 0:
            view = view.copy()
            view.flat[int(rng.integers(view.size))] = np.nan
        want = float(np.median(np.abs(view - np.median(view))))
        got = median_abs_deviation(view)
        assert got == want or (np.isnan(want) and np.isnan(got)), (k, got, want)
