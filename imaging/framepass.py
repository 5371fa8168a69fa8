"""One pass over a frame for what the camera stage reads of all of it.

A 5 MP float64 frame is 40 MB, far beyond the caches: its maximum (the full scale), the
coarse search's block means (:func:`imaging.detect.detect_lines_once`), the oriented test's
float32 square (:func:`imaging.oriented.oriented_square`) and the row/column test's sampled
rows and columns (:func:`imaging.stripes.sampled_rows`) each read it from memory again
(~1.5-2.5 ms a pass at 5 MP). Here each chunk of :data:`BLOCK_ROWS` rows is read once and
used for all of them while it is in cache; every result is the one its own pass gives, to
the bit (the block means of whole blocks depend on their own pixels only, a maximum is the
largest of its chunks' maxima, a float32 cast is elementwise, and the square's exactness
test, a sum of absolute differences that is 0 only when each is, splits by rows alike).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from imaging.detect import default_min_length, search_factor
from imaging.oriented import square_slices
from imaging.stripes import MIN_ROWS, sampled_rows

BLOCK_ROWS = 64
"""Frame rows per chunk (~1.3 MB of a 2592 px float64 frame: it stays in cache while used)."""


class FramePass(NamedTuple):
    """What :func:`frame_pass` read of a frame.

    Attributes
    ----------
    maximum : float
        The frame's maximum (NaN if it holds one) [DN].
    block_means : ndarray
        (h // f, w // f) float64 means of the whole f x f blocks, as OpenCV's INTER_AREA
        resize of the frame's divisible crop gives them [DN].
    copy32 : ndarray or None
        The square as float32 when that holds each of its pixels exactly; None when it does
        not, or the square is contiguous (a whole small frame: it is tested as it is).
    rows : ndarray
        The rows asked for, as float32 (len(rows), w) [DN].
    columns : ndarray
        The columns asked for, as float32 (len(columns), h): the transposed frame's rows.
    """

    maximum: float
    block_means: np.ndarray
    copy32: np.ndarray | None
    rows: np.ndarray
    columns: np.ndarray


def frame_pass(image: np.ndarray, f: int, square: tuple[slice, slice],
               rows: np.ndarray | None = None, columns: np.ndarray | None = None) -> FramePass:
    """A float64 frame's maximum, the f x f block means of its whole blocks, the float32
    copy of its ``square`` (rows, columns slices) and its ``rows`` and ``columns`` (sorted
    indices) as float32, in one pass over the frame (see the module).

    Parameters
    ----------
    image : ndarray
        The frame (2-D float64) [DN].
    f : int
        The block factor (>= 1; :func:`imaging.detect.search_factor`).
    square : tuple of slice
        The oriented test's square (:func:`imaging.oriented.square_slices`).
    rows, columns : ndarray, optional
        Sorted row and column indices to copy (none when not given).

    Returns
    -------
    FramePass
        The maximum, block means, square, rows and columns.
    """
    h, w = image.shape
    hs, ws = h // f, w // f
    means = np.empty((hs, ws))
    rs, cs = square
    want32 = not image[square].flags.c_contiguous
    copy32 = np.empty((rs.stop - rs.start, cs.stop - cs.start), np.float32)
    rows = np.empty(0, np.intp) if rows is None else np.asarray(rows)
    columns = np.empty(0, np.intp) if columns is None else np.asarray(columns)
    row_v = np.empty((rows.size, w), np.float32)
    col_v = np.empty((columns.size, h), np.float32)
    tops, l1 = [], 0.0
    step = f * max(1, BLOCK_ROWS // f)
    for r in range(0, h, step):
        chunk = image[r:r + step]
        e = r + chunk.shape[0]
        tops.append(chunk.max())
        n = max(0, min(chunk.shape[0], hs * f - r)) // f  # whole blocks' rows in this chunk
        if n:
            means[r // f:r // f + n] = cv2.resize(chunk[:n * f, :ws * f], (ws, n),
                                                  interpolation=cv2.INTER_AREA)
        a, b = max(r, rs.start), min(e, rs.stop)
        if want32 and a < b:
            part = image[a:b, cs]
            part32 = part.astype(np.float32)
            copy32[a - rs.start:b - rs.start] = part32
            l1 += cv2.norm(part, part32.astype(np.float64), cv2.NORM_L1)
        i, j = np.searchsorted(rows, (r, e))
        if i < j:
            row_v[i:j] = chunk[rows[i:j] - r]
        if columns.size:
            col_v[:, r:e] = chunk[:, columns].T
    return FramePass(float(np.max(tops)), means, copy32 if want32 and l1 == 0 else None,
                     row_v, col_v)


def stage_pass(image: np.ndarray, min_length_px: float | None) -> FramePass | None:
    """:func:`frame_pass` of a whole float64 frame with the stage's own choices: the coarse
    search's block factor for ``min_length_px`` (None: its default), the oriented test's
    square and the row/column test's samples (none when the frame is too small for that
    test); None when the search takes no block means (f = 1: a small frame, read once
    anyway)."""
    f = search_factor(image.shape, min_length_px if min_length_px is not None
                      else default_min_length(image.shape))
    if not 1 < f <= min(image.shape):
        return None
    sampled = min(image.shape) // 2 >= MIN_ROWS
    return frame_pass(image, f, square_slices(image.shape),
                      np.concatenate(sampled_rows(image)) if sampled else None,
                      np.concatenate(sampled_rows(image.T)) if sampled else None)
