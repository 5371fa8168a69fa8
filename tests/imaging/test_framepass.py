"""imaging.framepass: the frame's one pass gives what its separate passes give, to the bit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import imaging.measure as measure
from imaging import measure_frame
from imaging.detect import default_min_length, search_factor
from imaging.framepass import frame_pass
from imaging.oriented import oriented_square, square_slices
from imaging.stripes import sampled_rows
from tests.conftest import mark_image


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
    rows, cols = np.concatenate(sampled_rows(img)), np.concatenate(sampled_rows(img.T))
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


def test_the_one_pass_changes_no_result_in_either_memory_order(monkeypatch):
    """A frame measured with the one pass and with the separate passes (the pass switched
    off) gives the same results to the bit, row-major and column-major (a transposed
    array's layout: the row/column test then samples its rows in runs along the 2200 px
    side, and the pass must take those same rows)."""
    s = mark_image(17.0, seed=3, length_px=300.0, size=(640, 2200))
    for img in (s.image.astype(float), np.asfortranarray(s.image.astype(float))):
        one = measure_frame(img)
        with monkeypatch.context() as m:
            m.setattr(measure, "stage_pass", lambda *a: None)
            apart = measure_frame(img)
        assert one.items[0].line.angle_rad == apart.items[0].line.angle_rad
        assert one.items[0].line.angle_u_rad == apart.items[0].line.angle_u_rad
        assert [x.p_value for x in one.stripes] == [x.p_value for x in apart.stripes]
        assert one.oriented.ratio == apart.oriented.ratio and one.notes == apart.notes
