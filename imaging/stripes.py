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
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats
from scipy.ndimage import median_filter

ALPHA = 1e-3
"""Level of the test for stripes along each axis (one false flag per 1000 clean images)."""
WINDOW_PX = 65
"""Running median that takes the slow shading out of a profile [px]: wide enough to keep
~90 % of a white pattern's variance, narrow enough to follow vignetting."""
MIN_ROWS = 16
"""Fewest background pixels along a column (row) for its offset to be estimated."""
TEST_ROWS = 256
"""Rows (columns) per half used by the test (a sample keeps 5 MP cheap)."""


@dataclass(frozen=True)
class Stripes:
    """Stripes along one axis of an image.

    ``axis``: "column" (vertical stripes, offsets per column) or "row"; ``p_value`` of the
    test that there are none; ``found``: p below :data:`ALPHA`; ``rms_dn``: the pattern's
    standard deviation [DN] (from the covariance of the two halves' profiles);
    ``offsets_dn``: the offsets subtracted (None: none were: not found, or a mark covers a
    column without background, ``reason``).
    """

    axis: str
    p_value: float
    found: bool
    rms_dn: float = 0.0
    offsets_dn: np.ndarray | None = None
    reason: str = ""

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
    filled = np.interp(x, x[ok], p[ok])
    out = p - median_filter(filled, size=min(WINDOW_PX, p.size // 2 * 2 + 1), mode="nearest")
    out[~ok] = np.nan
    return out


def _column_median(a: np.ndarray) -> np.ndarray:
    """Median of each column over its finite entries (NaN with fewer than MIN_ROWS)."""
    n = np.isfinite(a).sum(axis=0)
    out = np.full(a.shape[1], np.nan)
    good = n >= MIN_ROWS
    if good.any():
        out[good] = np.nanmedian(a[:, good], axis=0)
    return out


def column_stripes(bg: np.ndarray, bands: np.ndarray, alpha: float = ALPHA) -> Stripes:
    """Test the background ``bg`` (float, NaN where marks or clipped pixels are) for column
    stripes; ``bands``: which columns a mark's band touches (their offsets are needed)."""
    h, w = bg.shape
    rowlev = np.nanmedian(bg, axis=1)
    ok = np.isfinite(rowlev)
    r = bg[ok] - rowlev[ok, None]
    half = r.shape[0] // 2
    if half < MIN_ROWS or w < 2 * WINDOW_PX:
        return Stripes("column", 1.0, False, reason="too few rows or columns to test")
    step = max(1, half // TEST_ROWS)
    top = _highpass(_column_median(r[:half:step]))
    bot = _highpass(_column_median(r[half::step]))
    both = np.isfinite(top) & np.isfinite(bot)
    n = int(both.sum())
    if n < 2 * WINDOW_PX:
        return Stripes("column", 1.0, False, reason="too few columns with background")
    a, b = top[both] - top[both].mean(), bot[both] - bot[both].mean()
    rho = float(a @ b / np.sqrt((a @ a) * (b @ b)))
    p = float(stats.norm.sf(np.arctanh(np.clip(rho, -0.999999, 0.999999)) * np.sqrt(n - 3)))
    rms = float(np.sqrt(max(a @ b / n, 0.0)))
    if p >= alpha:
        return Stripes("column", p, False, rms)
    off = _highpass(_column_median(r))
    need = bands & ~np.isfinite(off)
    if need.any():
        cols = np.flatnonzero(need)
        return Stripes("column", p, True, rms, reason=(
            f"columns {cols[0]}-{cols[-1]} hold a mark along all their background"))
    return Stripes("column", p, True, rms, np.where(np.isfinite(off), off, 0.0))


def find_stripes(image: np.ndarray, masks: Sequence[np.ndarray], full_scale: float,
                 alpha: float = ALPHA) -> tuple[np.ndarray, tuple[Stripes, Stripes]]:
    """The image with its row and column stripes removed where found and removable, and the
    two findings (columns, rows).

    ``masks``: flat pixel indices of each mark's band (left out of the background; their
    columns/rows must have an offset for a removal). Clipped pixels (0 or ``full_scale``)
    are left out too.
    """
    h, w = image.shape
    bg = image.astype(np.float32)  # half the memory of float64; medians need no more
    bg[(image <= 0) | (image >= full_scale)] = np.nan
    flat = bg.reshape(-1)
    ys, xs = np.zeros(h, bool), np.zeros(w, bool)
    for idx in masks:
        flat[idx] = np.nan
        ys[idx // w] = True
        xs[idx % w] = True
    cols = column_stripes(bg, xs, alpha)
    rows_first = column_stripes(bg.T, ys, alpha) if not cols.removed else None
    if not cols.found and rows_first is not None and not rows_first.found:
        return image, (cols, replace(rows_first, axis="row"))  # the usual case: untouched
    out = image.astype(float)
    clipped = (image <= 0) | (image >= full_scale)  # they say "beyond the range": kept
    if cols.removed:
        out -= cols.offsets_dn[None, :]
        bg -= cols.offsets_dn[None, :]
    rows = replace(rows_first if rows_first is not None else column_stripes(bg.T, ys, alpha),
                   axis="row")
    if rows.removed:
        out -= rows.offsets_dn[:, None]
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
                   f"noise, {size}, p = {s.p_value:.2g}): {done}")
    return tuple(out)
