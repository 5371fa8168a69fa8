"""imaging.framepass: the frame's one pass gives what its separate passes give, to the bit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from imaging.detect import default_min_length, search_factor
from imaging.framepass import frame_pass
from imaging.oriented import oriented_square, square_slices
from imaging.stripes import sampled_rows


@pytest.mark.parametrize("shape", [(1030, 1500), (1025, 1100), (101, 2100), (2000, 700)])
@pytest.mark.parametrize("kind", ["whole", "fraction", "nan"])
def test_one_pass_gives_the_separate_passes_results(shape, kind):
    """The maximum, the search's block means, the oriented test's square (float32 only when
    it holds every pixel exactly) and the row/column test's sampled rows and columns as the
    frame's own passes give them: whole 12-bit
    pixels, a tenth inside the square (the square stays float64), a NaN (the maximum is
    NaN, the square float64); frames whose rows and columns are not multiples of the
    block factor, and one whose square is contiguous (700 px wide: tested as it is)."""
    rng = np.random.default_rng(shape[0] + len(kind))
    img = np.round(rng.random(shape) * 4095)
    if kind == "fraction":
        img[shape[0] // 2, shape[1] // 2] += 0.1  # (not a float32 value)
    elif kind == "nan":
        img[shape[0] // 2 + 3, shape[1] // 2 - 5] = np.nan
    f = search_factor(shape, default_min_length(shape))
    assert 1 < f <= min(shape)
    rows = np.concatenate(sampled_rows(shape, False))
    cols = np.concatenate(sampled_rows(shape[::-1], True))
    mx, means, copy32, row_v, col_v = frame_pass(img, f, square_slices(shape), rows, cols)
    # the row/column test's samples as its own gathers cast them
    assert np.array_equal(row_v, img[rows].astype(np.float32), equal_nan=True)
    assert np.array_equal(col_v, img[:, cols].T.astype(np.float32), equal_nan=True)
    hs, ws = shape[0] // f, shape[1] // f
    ref = cv2.resize(img[:hs * f, :ws * f], (ws, hs), interpolation=cv2.INTER_AREA)
    assert np.array_equal(means, ref, equal_nan=True)
    assert mx == float(img.max()) or (kind == "nan" and np.isnan(mx))
    square, alone = oriented_square(img, 4095.0, copy32), oriented_square(img, 4095.0)
    assert square.dtype == alone.dtype and np.array_equal(square, alone, equal_nan=True)
    assert (square.dtype == np.float32) == (kind == "whole" and shape[1] > 1024)
