"""imaging.median: np.median's number to the bit, in its place on the measurement's paths."""

import numpy as np
import pytest

from imaging.median import median, median_inplace


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_same_number_as_np_median(dtype):
    rng = np.random.default_rng(7)
    for n in [1, 2, 3, 4, 5, 10, 11, 256, 257, 4001]:
        for draw in range(20):
            x = (rng.standard_normal(n) * 10.0 ** rng.integers(-6, 6)).astype(dtype)
            if draw % 4 == 1:  # ties: a quantised image's levels
                x = np.round(x * 4).astype(dtype)
            if draw % 4 == 2 and n > 1:  # NaN anywhere makes the median NaN
                x[rng.integers(0, n)] = np.nan
            want = np.median(x)
            kept = x.copy()
            got = median(x)
            assert np.array_equal(x, kept, equal_nan=True)  # (median leaves its input)
            assert np.array_equal(got, want, equal_nan=True) and got.dtype == want.dtype
            assert np.array_equal(median_inplace(x.copy()), want, equal_nan=True)


def test_other_inputs_are_np_medians():
    for x in (np.arange(7), np.arange(8), np.ones((3, 4)), [3.0, 1.0, 2.0, 10.0]):
        assert np.array_equal(median(x), np.median(x))
        assert np.asarray(median(x)).dtype == np.median(x).dtype
    with pytest.warns(RuntimeWarning):
        assert np.isnan(median(np.empty(0)))
