"""The pixels of a mark's band: those within a distance of its line, between two positions
along it, rasterised along the line (the cost follows the band's area).

Positions: e the signed distance from the line, t the position along it [px], both about the
image centre (the :func:`imaging.detect.line_frame` convention); flat pixel indices.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.detect import MarkCandidate, line_frame
from imaging.groove import ProfileFit


def _band(image: np.ndarray, angle: float, offset: float, t0: float, t1: float,
          half: float, gather: bool = True
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixels within ``half`` of the line and between t0 and t1: (values, e, t, flat idx).

    Rasterised along the line (one short run of pixels per column, or per row for steep
    lines), so the cost follows the band's area, not its bounding box's. ``gather``: False
    for the pixels alone (values empty: their gather from the frame is most of a wide
    band's cost at 5 MP).
    """
    h, w = image.shape
    u, n = line_frame(angle)
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    steep = abs(n[0]) > abs(n[1])  # the line runs more along y than x: walk the rows
    ax, other = (1, 0) if steep else (0, 1)
    size_ax, size_other = (h, w) if steep else (w, h)
    ends = np.array([c + offset * n + t * u for t in (t0, t1)])
    lo = max(0, int(np.floor(ends[:, ax].min() - half)))
    hi = min(size_ax - 1, int(np.ceil(ends[:, ax].max() + half)))
    if hi < lo:  # (flat indices stay integers: an empty band still indexes an image)
        return np.empty(0), np.empty(0), np.empty(0), np.empty(0, np.intp)
    k = np.arange(lo, hi + 1, dtype=float)
    # Where the line crosses walk coordinate k, and how far the band reaches across it.
    cross = c[other] + (offset - (k - c[ax]) * n[ax]) / n[other]
    reach = half / abs(n[other])
    m = int(np.ceil(2 * reach)) + 2
    start = np.floor(cross - reach).astype(int)
    oth = start[:, None] + np.arange(m)[None, :]  # (walk, across) grid of candidate pixels
    # e and t on the grid: the walk coordinate's terms once per row (broadcast), the same
    # products and sums, in the same order, as per pixel; one selection at the end (the
    # grid's row-major order, as before). Every pass of this function counts: it runs ~7
    # times per mark, over ~60k pixels at 5 MP.
    p_oth = oth - c[other]
    p_walk = (k.astype(int) - c[ax])[:, None]
    px, py = (p_oth, p_walk) if steep else (p_walk, p_oth)
    e = px * n[0] + py * n[1]
    e -= offset
    t = px * u[0] + py * u[1]
    # (In place: the chained expression's four temporaries cost more than its tests.)
    sel = np.abs(e) <= half
    sel &= t >= t0
    sel &= t <= t1
    if not (start.min() >= 0 and start.max() + m <= size_other):
        # (Else every column of the grid lies in the frame, the usual case, as its rows'
        # first and last tell: no test per pixel.)
        sel &= (oth >= 0) & (oth < size_other)
    oth_s = oth[sel]
    walk_s = np.broadcast_to(k.astype(int)[:, None], oth.shape)[sel]
    ys, xs = (walk_s, oth_s) if steep else (oth_s, walk_s)
    idx = ys * w + xs
    # By flat index: numpy's 2-D fancy indexing costs ~2x (this runs ~6 times per mark).
    if not gather:
        vals = np.empty(0, image.dtype)
    elif image.flags.c_contiguous:
        vals = image.ravel()[idx]
    else:
        vals = image[ys, xs]
    return vals, e[sel], t[sel], idx


def unclipped(vals: np.ndarray, full_scale: float) -> np.ndarray | None:
    """Which ``vals`` lie strictly inside (0, ``full_scale``) (clipped pixels say only "beyond
    the range"); None when all do, as the minimum and maximum tell (the usual case: no masks
    and no selections of a band's arrays)."""
    if vals.size and vals.min() > 0 and vals.max() < full_scale:  # (NaN fails both)
        return None
    return (vals < full_scale) & (vals > 0)


def band_pixels(image: np.ndarray, pf: ProfileFit, half: float, reach_px: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance e from the fitted line [px] and flat index of the pixels within
    ``half`` of it, ``reach_px`` beyond the measured stretch, in ``image``."""
    _, e, _, idx = _band(image, pf.angle_rad, pf.offset_px,
                         pf.t_start_px - reach_px, pf.t_end_px + reach_px, half, gather=False)
    return e, idx


def band_mask(shape: tuple[int, int], bands: Sequence[np.ndarray]) -> np.ndarray:
    """True on the pixels of every band (flat indices, as :func:`band_indices` gives them) of
    an image of ``shape``: built once per frame and shared by the background tests (each
    full-frame mask costs a 5 MP pass)."""
    mask = np.zeros(shape, bool)
    flat = mask.reshape(-1)  # (a view: indexing it costs ~1/6 of the flat iterator's)
    for idx in bands:
        flat[idx] = True
    return mask


def band_indices(image: np.ndarray, cand: MarkCandidate, reach_px: float = 20.0) -> np.ndarray:
    """Flat indices of the pixels a candidate's measurement can use: its band (as wide as
    :func:`fit_profile`'s, plus its illumination ring) and ``reach_px`` beyond its ends."""
    half = float(np.clip(2.5 * cand.thickness_px + 8, 10, 40)) + 6.0
    return _band(image, cand.angle_rad, cand.offset_px, cand.t_start_px - reach_px,
                 cand.t_end_px + reach_px, half, gather=False)[3]
