"""Row and column fixed-pattern noise: stripes in the background, found and removed.

A sensor's column amplifiers (and row drivers) add an offset fixed per column (row): a
pattern of stripes of 1-2 % of a mark's contrast moves a near-vertical (near-horizontal)
mark's centres by the same amount all along it, and its angle as it drifts across columns.

The test (hand-written: no library tests an image for stripes). Away from the marks the
background is level + illumination + texture + noise + stripes. Each row's median is taken
out (it holds the row offsets and the vertical shading), each column's median over the top
half and over the bottom half of the rows is taken, and the slow horizontal shading is
removed from both profiles by a running median over :data:`WINDOW_PX` columns. Noise and
texture (whose lay is not along the columns) are independent between the two halves; a
column pattern is common to both. The test is the correlation of the two profiles (Fisher's
z, one-sided at :data:`ALPHA`): it needs no noise model, and clean backgrounds flag at alpha.

When found, the column offsets (the profile over all the rows, high-passed the same way)
are subtracted from the image, unless a mark's band covers a column whose offset the
background away from the marks does not give (a full-height mark): then the stripes stay and
the texture replicas (:mod:`imaging.texture`) carry them in u, as they do any background
pattern. Rows: the same on the transposed image, after the columns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.ndimage import median_filter

ALPHA = 1e-3
"""Level of the test for stripes along each axis (one false flag per 1000 clean images)."""
WINDOW_PX = 65
"""Running median that takes the slow shading out of a profile [px]: wide enough to keep
~90 % of a white pattern's variance, narrow enough to follow vignetting."""
MIN_ROWS = 16
"""Fewest background pixels along a column (row) for its offset to be estimated."""
GAP_PX = 48
"""Rows left out between the halves the test compares (a blob smaller than this is never in
both)."""
TEST_ROWS = 128
"""Rows (columns) per half used by the test (a sample keeps 5 MP cheap)."""

SHADING_STRIDE = 4
"""Every how many of the test's rows the slow column shading is estimated from."""
LEVEL_PX = 160
"""Pixels (at least; every k-th of the row) each row's level is taken from. The level is
common to the row: its error moves every column's value alike (the profiles' mean and slow
part take it out), so a sample serves as well as the whole row, whose sort cost most of the
test (the rows are 640-2592 px; the columns' 128-216)."""


RUN = 8
"""Adjacent rows (columns) per run of the sample when the test's rows are the frame's
columns (the row test) and are spread one in 8 or more: see :func:`_runs`."""


def _runs(lo: int, hi: int, step: int) -> np.ndarray:
    """About one in ``step`` of lo..hi-1, as runs of :data:`RUN` adjacent ones, a run every
    RUN x step.

    For the row test's sample of the frame's columns: one column in every ``step`` >= 8
    float64 pixels touched every cache line of each frame row (a whole 5 MP pass, ~3 ms of
    ~15 for both tests); runs read 1/step of it. The same test: each row's value in a half is
    the interquartile mean of the same number of its pixels, and its row offset is common
    to all of them, so with pixel noise independent from pixel to pixel the statistic has
    the same distribution, under no stripes and under stripes, whichever pixels of the row
    are taken (which the halves' disjointness, not the spacing, keeps independent). Only a
    texture correlated along the rows over a few pixels makes a run's pixels alike: a
    noisier row value, a little less power there, the false-alarm rate unchanged.
    """
    starts = np.arange(lo, hi, step * RUN)
    out = (starts[:, None] + np.arange(RUN)[None, :]).ravel()
    return out[out < hi]


@dataclass(frozen=True)
class Stripes:
    """Stripes along one axis of an image.

    ``axis``: "column" (vertical stripes, offsets per column) or "row"; ``p_value`` of the
    test that there are none; ``found``: p below :data:`ALPHA`; ``rms_dn``: the pattern's
    standard deviation [DN] (from the covariance of the two halves' profiles);
    ``offsets_dn``: the offsets subtracted (None: none were: not found, or a mark covers a
    column without background, ``reason``); ``offsets_var``: each removed offset's variance
    [DN^2] (the interquartile mean of n background pixels of noise sigma: 1.19 sigma^2 / n),
    which the centres' covariance carries (:func:`imaging.centres.sample_centres`): a mark
    leaves its own columns few background rows, and their offsets' errors are shared by
    every segment on them.

    Attributes
    ----------
    axis : str
        'column' or 'row'.
    p_value : float
        Of no stripes.
    found : bool
        p below :data:`ALPHA`.
    rms_dn : float
        The pattern's standard deviation [DN].
    offsets_dn : ndarray or None
        Offsets subtracted [DN].
    reason : str
        Why none were subtracted.
    offsets_var : ndarray or None
        Each removed offset's variance [DN^2].
    """

    axis: str
    p_value: float
    found: bool
    rms_dn: float = 0.0
    offsets_dn: np.ndarray | None = None
    reason: str = ""
    offsets_var: np.ndarray | None = None

    @property
    def removed(self) -> bool:
        return self.offsets_dn is not None


def _highpass(p: np.ndarray) -> np.ndarray:
    """The profile minus its running median over :data:`WINDOW_PX` (NaN stays NaN; gaps are
    bridged by interpolation for the median only)."""
    ok = np.isfinite(p)
    if ok.sum() < 2:
        return np.full_like(p, np.nan)
    x = np.arange(p.size)
    # A quadratic first: the running median is biased near the ends on a sloping profile
    # (its window is cut there), by the same amount in both halves (a false pattern).
    p = p - np.polyval(np.polyfit(x[ok], p[ok], 2), x)
    filled = np.interp(x, x[ok], p[ok])
    out = p - median_filter(filled, size=min(WINDOW_PX, p.size // 2 * 2 + 1), mode="nearest")
    out[~ok] = np.nan
    return out


def _column_median(a: np.ndarray, axis: int = 0) -> np.ndarray:
    """Interquartile mean of each column (``axis`` 0) or row (1) over its finite entries
    (NaN with fewer than MIN_ROWS): robust to dust and a label like the median, but not
    quantised like it (the median of 8-bit data moves in steps of 1/2 DN, and a pattern of
    1 DN was lost in them)."""
    if axis == 0:  # sorted as rows: numpy sorts a contiguous row ~2x faster than a column
        # (OpenCV's transpose is cache-blocked: ~3x numpy's copy of the transposed view)
        a = cv2.transpose(a) if a.dtype == np.float32 and a.size else np.ascontiguousarray(a.T)
    # Each row's finite count by OpenCV's row sum of the mask's bytes: np.count_nonzero
    # along an axis casts the booleans to intp and sums them (~10x the time).
    n = (cv2.reduce(np.isfinite(a).view(np.uint8), 1, cv2.REDUCE_SUM, dtype=cv2.CV_32S)
         .ravel().astype(np.intp) if a.size else np.zeros(a.shape[0], np.intp))
    rows, m = a.shape
    if m < MIN_ROWS or rows == 0:
        return np.full(rows, np.nan)
    s = np.sort(a, axis=1).ravel()  # each row's n finite entries first, NaN last
    lo, hi = n // 4, n - n // 4
    # Each row's sum over ranks lo..hi-1 in one pass: reduceat over (start, end) pairs of
    # the flat sorted array (every other sum is the gap between rows), accumulated in
    # float64; a row ending at the array's end needs no end index.
    at = np.empty(2 * rows, np.intp)
    at[0::2] = np.arange(rows) * m + lo
    at[1::2] = np.arange(rows) * m + hi
    total = np.add.reduceat(s, at if at[-1] < s.size else at[:-1], dtype=np.float64)[0::2]
    return np.where(n >= MIN_ROWS, total / np.maximum(hi - lo, 1), np.nan)


def _effective_n(a: np.ndarray, b: np.ndarray, lags: int = 32) -> float:
    """Independent pairs behind the correlation of two autocorrelated series (Bartlett's
    variance of r under independence: (1/n) sum_k rho_a(k) rho_b(k), Pyper & Peterman 1998).

    Texture whose lay crosses the columns at a shallow angle makes neighbouring columns'
    medians alike (each half's profile is smooth): with n columns counted as independent the
    test flagged 4 % of textured backgrounds at p < 0.01."""
    n = a.size

    def acf(x: np.ndarray) -> np.ndarray:
        return np.array([x[k:] @ x[:n - k] for k in range(lags + 1)]) / (x @ x)

    s = float(np.sum(acf(a)[1:] * acf(b)[1:]))
    return float(n / max(1.0 + 2.0 * s, 1.0))


def _rows(image: np.ndarray, mask: np.ndarray, rows: np.ndarray, full_scale: float,
          minus: np.ndarray | None, values: np.ndarray | None = None) -> np.ndarray:
    """Rows ``rows`` of the image as float32, NaN on the marks' bands and clipped pixels;
    ``minus``: offsets per row removed (the other axis's stripes); ``values``: those rows
    already cast to float32 (:func:`imaging.framepass.frame_pass`; changed here). Gathered
    once per test: on the transposed image (the row test) each row is a strided column of
    the frame, whose gathers cost most of that test at 5 MP."""
    if image.T.flags.c_contiguous and not image.flags.c_contiguous:
        # The row test's transposed frame: its rows are the frame's columns, gathered along
        # each of the frame's rows (one sequential read; strided per column cost ~20 % more),
        # the mask's alike. (Indexed, not np.take: 0.75 ms, not 4.4, for the runs of 5 MP.)
        # (The gathered columns cast as the transposed rows: a contiguous cast, ~0.6 ms less
        # than casting them as gathered; the mask's transposed by OpenCV, as bytes, so that
        # the masks below combine arrays of one layout.)
        v = image.T[:, rows].T.astype(np.float32) if values is None else values
        out = (cv2.transpose(np.take(mask.T, rows, axis=1).view(np.uint8)).view(bool)
               if mask.T.flags.c_contiguous else mask[rows])
    else:
        v = image[rows].astype(np.float32) if values is None else values
        out = mask[rows]
    out |= v <= 0  # (out is a copy either way)
    out |= v >= full_scale
    np.copyto(v, np.nan, where=out)
    if minus is not None:
        v -= minus[rows, None]
    return v


def _background(v: np.ndarray, shading: np.ndarray | None = None,
                whole_rows: bool = False) -> np.ndarray:
    """Rows ``v`` (from :func:`_rows`) with each row's level (its interquartile mean) taken
    out, rows without one dropped; ``shading``: the slow column profile (see
    :func:`_shading`), out of the rows while their levels are taken (not out of the rows
    returned); ``whole_rows``: the levels from every pixel (for the offsets removed), not
    from a sample (for the test, see LEVEL_PX).

    Why the shading: a row crossing a mark has its level from the columns beside the mark
    only. Under vignetting those are darker than the mark's (central) columns, so its level
    came out lower than an unmasked row's (16.7 DN for a 32 px band at the centre of a
    480 px row, 25 % vignetting, 12-bit), and the mark's columns, whose background is all in
    the unmasked rows above and below it, got a dip common to both halves: a clean vertical
    mark was "column stripes" in 5 of 6 frames (user6)."""
    # The test's levels from every k-th pixel of the row (see LEVEL_PX): a sort of ~200 px,
    # not of the whole row. The offsets removed do not carry the sample's extra noise.
    k = 1 if whole_rows else max(1, v.shape[1] // LEVEL_PX)
    sample = v[:, ::k] if shading is None else v[:, ::k] - shading[None, ::k]
    lev = _column_median(sample, axis=1)
    ok = np.isfinite(lev)
    # float32 as the rows (a float64 level made every row float64: twice the bytes for the
    # sorts of the columns that follow, for a level known to ~1e-4 DN either way).
    if ok.all():  # (the usual case: no copy of the rows to select them)
        return v - lev[:, None].astype(np.float32)
    return v[ok] - lev[ok, None].astype(np.float32)


def _shading(profile: np.ndarray) -> np.ndarray | None:
    """The slow part of a column profile (what :func:`_highpass` takes out), bridged over
    columns without background; None when too few columns have a value."""
    ok = np.isfinite(profile)
    if ok.sum() < 2:
        return None
    slow = profile - _highpass(profile)
    x = np.arange(profile.size)
    return np.interp(x, x[ok], slow[ok]).astype(np.float32)


def sampled_rows(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the top and of the bottom half that :func:`column_stripes` tests in
    ``image`` (the row test's transposed frame, whose rows are the frame's columns, in runs:
    see :func:`_runs`); the halves stay GAP_PX apart: a dust speck or a label across the
    split would be common to both (a false pattern over its columns)."""
    h = image.shape[0]
    transposed = image.T.flags.c_contiguous and not image.flags.c_contiguous
    half = h // 2
    gap = min(GAP_PX, half - MIN_ROWS) // 2
    step = max(1, (half - gap) // TEST_ROWS)
    if step >= RUN and transposed:
        return _runs(0, half - gap, step), _runs(half + gap, h, step)
    return np.arange(0, half - gap, step), np.arange(half + gap, h, step)


def column_stripes(image: np.ndarray, mask: np.ndarray, full_scale: float,
                   alpha: float = ALPHA, minus: np.ndarray | None = None,
                   axis: str = "column", values: np.ndarray | None = None) -> Stripes:
    """Test an image's background for column stripes (rows: pass the transposed image).

    ``mask``: True on the marks' bands (left out; every column one touches needs an offset
    for a removal); ``minus``: offsets per row already found (the other axis's stripes).
    The test uses up to :data:`TEST_ROWS` rows per half, evenly spaced (:func:`sampled_rows`);
    the offsets, when found, every row. ``values``: those rows as float32, when the caller
    has them (:func:`imaging.framepass.frame_pass`).
    """
    h, w = image.shape
    half = h // 2
    if half < MIN_ROWS or w < 2 * WINDOW_PX:
        return Stripes(axis, 1.0, False, reason="too few rows or columns to test")
    rows_top, rows_bot = sampled_rows(image)
    # The slow column profile (vignetting) from every SHADING_STRIDE-th row of both halves
    # (it is smooth: a quarter of the rows gives it to well under 1 DN, at a quarter of the
    # cost), out of every row before its level is taken (see _background).
    v = _rows(image, mask, np.concatenate([rows_top, rows_bot]), full_scale, minus, values)
    shading = _shading(_column_median(_background(v[::SHADING_STRIDE])))
    top = _highpass(_column_median(_background(v[:rows_top.size], shading)))
    bot = _highpass(_column_median(_background(v[rows_top.size:], shading)))
    both = np.isfinite(top) & np.isfinite(bot)
    n = int(both.sum())
    if n < 2 * WINDOW_PX:
        return Stripes(axis, 1.0, False, reason="too few columns with background")
    a, b = top[both] - top[both].mean(), bot[both] - bot[both].mean()
    if not (a @ a > 0 and b @ b > 0):
        return Stripes(axis, 1.0, False, reason="a flat background profile")
    rho = float(a @ b / np.sqrt((a @ a) * (b @ b)))
    p = float(special.ndtr(-np.arctanh(np.clip(rho, -0.999999, 0.999999))
                            * np.sqrt(max(_effective_n(a, b) - 3, 1.0))))
    rms = float(np.sqrt(max(a @ b / n, 0.0)))
    if p >= alpha:
        return Stripes(axis, p, False, rms)
    bg = _background(_rows(image, mask, np.arange(h), full_scale, minus), shading, True)
    off = _highpass(_column_median(bg))
    need = mask.any(axis=0) & ~np.isfinite(off)
    if need.any():
        cols = np.flatnonzero(need)
        return Stripes(axis, p, True, rms, reason=(
            f"{axis}s {cols[0]}-{cols[-1]} hold a mark along all their background"))
    # Pixel noise about each column's offset (robust, pooled over the columns: shot noise
    # varies with the level, which is about the same across a background).
    dev = bg - off[None, :]
    mad = np.nanmedian(np.abs(dev - np.nanmedian(dev, axis=0)[None, :]), axis=0)
    sigma2 = float(np.nanmedian((1.4826 * mad) ** 2))
    n = np.isfinite(bg).sum(axis=0)
    var = np.where(n > 0, 1.19 * sigma2 / np.maximum(n, 1), 0.0)
    return Stripes(axis, p, True, rms, np.where(np.isfinite(off), off, 0.0),
                   offsets_var=np.where(np.isfinite(off), var, 0.0))


def find_stripes(image: np.ndarray, mask: np.ndarray | None, full_scale: float,
                 alpha: float = ALPHA,
                 samples: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[np.ndarray, tuple[Stripes, Stripes]]:
    """The image with its row and column stripes removed where found and removable, and the
    two findings (columns, rows).

    ``mask``: True on the marks' bands (:func:`imaging.band.band_mask`; None: no marks), left
    out of the background; their columns/rows must have an offset for a removal. Clipped
    pixels (0 or ``full_scale``) are left out too.
    """
    if mask is None:
        mask = np.zeros(image.shape, bool)
    # (``samples``: the two tests' rows of this image as float32, imaging.framepass.)
    col_v, row_v = samples if samples is not None else (None, None)
    cols = column_stripes(image, mask, full_scale, alpha, values=col_v)
    rows = column_stripes(image.T, mask.T, full_scale, alpha, cols.offsets_dn, "row", row_v)
    if not (cols.removed or rows.removed):
        return image, (cols, rows)  # the usual case: untouched
    out = image.astype(float)
    if cols.removed:
        out -= cols.offsets_dn[None, :]
    if rows.removed:
        out -= rows.offsets_dn[:, None]
    clipped = (image <= 0) | (image >= full_scale)  # they say "beyond the range": kept
    out[clipped] = image[clipped]
    return out, (cols, rows)


def stripes_notes(where: str, found: Sequence[Stripes], contrast_dn: float) -> tuple[str, ...]:
    """One line per axis with stripes: what they are and what was done about them."""
    out = []
    for s in found:
        if not s.found:
            continue
        size = (f"rms {s.rms_dn:.3g} DN, {100 * s.rms_dn / contrast_dn:.2g} % of the marks' "
                "contrast" if contrast_dn > 0 else f"rms {s.rms_dn:.3g} DN")
        done = ("removed: each offset estimated from the background away from the marks"
                if s.removed else f"not removed ({s.reason}): carried in u as background "
                "texture")
        out.append(f"{where}: {s.axis} stripes in the background ({s.axis} fixed-pattern "
                   f"noise, or a surface lay along the {s.axis}s; {size}, p = "
                   f"{s.p_value:.2g}): {done}")
    return tuple(out)
