"""Two marks that cross at a shallow angle: told apart in the coarse search, kept apart in the fit.

Where two grooves cross at a few degrees their ridges fuse into one long connected component;
its principal axis then points between the two (a phantom mark), and the arms of each mark
beyond the fused stretch become separate, shorter pieces. :func:`split_two_lines` tests a
component for a second straight line (a two-line RANSAC on its ridge points) and returns the
two lines' points apart. :func:`crossing_stretch` gives the stretch of one mark over which the
other's groove lies inside its profile window: there the fitted centres are pulled towards the
other groove, so that stretch is left out of the mark's fit.

Pure numpy on point sets; nothing here knows the image or the rest of the pipeline.
"""

from __future__ import annotations

import numpy as np

TOL_PX = 1.0
"""Half-width of a line's band of ridge points in the (block-averaged) search image [px]."""
MIN_ANGLE = np.deg2rad(1.0)
"""Two lines closer in direction than this are one (a wide or bowed mark, not a crossing)."""
_HYPOTHESES = 300


def _ransac_line(pts: np.ndarray, tol: float, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The straight line with most points within ``tol``, refitted to them by least squares:
    (point on it, unit direction, inlier mask). RANSAC is written here because what matters
    is the second line after the first (scikit-image's ``ransac`` fits one model; looping it
    would cost more than this vectorised draw of point pairs)."""
    n = len(pts)
    i = rng.integers(0, n, _HYPOTHESES)
    j = rng.integers(0, n, _HYPOTHESES)
    d = pts[j] - pts[i]
    norm = np.hypot(d[:, 0], d[:, 1])
    ok = norm >= 4.0
    if not ok.any():
        return pts.mean(0), np.array([1.0, 0.0]), np.ones(n, bool)
    i, d, norm = i[ok], d[ok], norm[ok]
    nrm = np.column_stack([-d[:, 1], d[:, 0]]) / norm[:, None]
    dist = np.abs(np.einsum("hnk,hk->hn", pts[None, :, :] - pts[i][:, None, :], nrm))
    best = int(np.argmax((dist <= tol).sum(1)))
    inl = dist[best] <= tol
    for _ in range(2):  # least-squares refit on the inliers, then their new band
        m = pts[inl].mean(0)
        w, v = np.linalg.eigh(np.cov((pts[inl] - m).T))
        u = v[:, 1]
        inl = np.abs((pts - m) @ np.array([-u[1], u[0]])) <= tol
        if inl.sum() < 3:
            break
    return m, u, inl


def _intersection(m1, u1, m2, u2) -> np.ndarray:
    """Where two lines (point, direction) meet."""
    a = np.column_stack([u1, -u2])
    s = np.linalg.solve(a, m2 - m1)
    return m1 + s[0] * u1


def split_two_lines(pts: np.ndarray, min_piece: float, tol: float = TOL_PX
                    ) -> list[np.ndarray] | None:
    """A component's ridge points as two crossing straight lines, or None when it is one.

    Parameters
    ----------
    pts : ndarray (N, 2)
        Ridge pixels (x, y) of one connected component [px].
    min_piece : float
        Shortest stretch of ridge that counts as a piece of a line [px].
    tol : float
        Half-width of a line's band of points [px].

    Returns
    -------
    None when one straight line explains the points (or the second line is not a crossing:
    a bowed mark is two chords meeting at a kink, each on one side of it); else the points
    of each line, those in both bands (the fused stretch at the crossing) in neither.
    """
    if len(pts) < 20:
        return None
    # One straight ridge lies within the band of its principal axis: nothing to split.
    m = pts.mean(0)
    axis = np.linalg.eigh(np.cov((pts - m).T))[1][:, 1]
    if np.abs((pts - m) @ np.array([-axis[1], axis[0]])).max() <= 2 * tol:
        return None
    rng = np.random.default_rng(0)  # deterministic: the same image, the same marks
    m1, u1, in1 = _ransac_line(pts, tol, rng)
    n1 = np.array([-u1[1], u1[0]])
    rest = np.abs((pts - m1) @ n1) > 2 * tol
    if rest.sum() < max(10, 0.1 * len(pts)):
        return None
    m2, u2, in2r = _ransac_line(pts[rest], tol, rng)
    sin = abs(float(u1[0] * u2[1] - u1[1] * u2[0]))
    if sin < np.sin(MIN_ANGLE) or in2r.sum() < max(10, 0.6 * rest.sum()):
        return None
    n2 = np.array([-u2[1], u2[0]])
    in2 = np.abs((pts - m2) @ n2) <= tol
    x = _intersection(m1, u1, m2, u2)
    # A crossing: at least one line runs on past the meeting point on both sides, beyond
    # the fused stretch (a bow's two chords each stop at their kink).
    fused = 2 * tol / sin
    sides = []
    for inl, u in ((in1, u1), (in2, u2)):
        t = (pts[inl] - x) @ u
        if len(t) < 10 or np.ptp(t) < min_piece:
            return None
        sides.append(min(-t.min(), t.max()))
    if max(sides) < max(fused, min_piece / 2):
        return None
    both = in1 & in2
    return [pts[in1 & ~both], pts[in2 & ~both]]


MIN_CROSSING = np.deg2rad(1.0)
"""Lines closer in direction than this are parallel neighbours (kept out of the texture's
replicas by :func:`imaging.beside.neighbours`), not crossings."""


def _frame(angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    # The package's line convention (imaging.detect.line_frame), restated: detect imports
    # this module.
    return (np.array([np.cos(angle_rad), -np.sin(angle_rad)]),
            np.array([np.sin(angle_rad), np.cos(angle_rad)]))


def crossing_stretch(c, o, half_px: float, extend: bool = False
                     ) -> tuple[float, float, np.ndarray] | None:
    """The stretch of line ``c`` over which line ``o``'s groove lies within ``half_px`` of it.

    ``c`` and ``o`` carry ``angle_rad``, ``offset_px`` [px], ``t_start_px``/``t_end_px``
    [px] (MarkCandidate or ProfileFit-like). ``half_px``: half-width of c's profile window
    plus o's half-width [px]. ``extend``: o's groove may run on past its found ends by the
    stretch over which it lies within ``half_px`` of c (its ridge fused with c's there); if
    that reaches the crossing, the whole stretch around the crossing counts.

    Returns (t0, t1, where) [px along c; where: the crossing point, px from the image
    centre], clipped to c's extent, or None when o does not come that close within both
    extents or runs parallel to c (within :data:`MIN_CROSSING`).
    """
    uc, nc = _frame(c.angle_rad)
    uo, no = _frame(o.angle_rad)
    sin = float(uo @ nc)  # how fast o leaves c's line per px along o
    if abs(sin) < np.sin(MIN_CROSSING):
        return None
    p0 = o.offset_px * no  # o's point at s = 0
    d0 = float(p0 @ nc) - c.offset_px
    # |d0 + s sin| <= half over s in o's extent
    s_lo, s_hi = sorted(((-half_px - d0) / sin, (half_px - d0) / sin))
    # o's groove may run on past its found ends by the stretch where it is fused with c's
    # (its ridge is lost there, and how far it goes beyond is unknown): when it comes that
    # close to the crossing, all of the crossing's stretch counts.
    fused = half_px / abs(sin) if extend else 0.0
    s_x = -d0 / sin
    # A groove found further from c along its line than its own found length is another
    # piece of (nearly) the same line — two graduations of one
    # dial diameter, collinear up to their angles' errors, the dial's centre between them —
    # not a groove that fused with c (at a crossing the ridge is lost where the two meet, so
    # what is found of it ends at c, give or take the coarse filter's width).
    o_t = sorted(float((p0 + s * uo) @ uc) for s in (o.t_start_px, o.t_end_px))
    gap = max(o_t[0] - c.t_end_px, c.t_start_px - o_t[1])
    beside = gap > o.t_end_px - o.t_start_px
    # The crossing itself must lie on c (within its extent, give or take the window): two
    # near-parallel lines side by side whose lines would meet far beyond c's ends (a family
    # of window edges 1-3 deg apart: hundreds of px of "stretch") are neighbours, not a
    # crossing (building.jpg lost 8 of 14 lines that way).
    t_x = float((p0 + s_x * uo) @ uc)
    on_c = c.t_start_px - half_px <= t_x <= c.t_end_px + half_px
    # (Twice that stretch: the coarse search's ridge fuses at a filter width further out.)
    if not (extend and not beside and on_c
            and o.t_start_px - 2 * fused <= s_x <= o.t_end_px + 2 * fused):
        s_lo, s_hi = max(s_lo, o.t_start_px), min(s_hi, o.t_end_px)
    if s_lo >= s_hi:
        return None
    t_lo, t_hi = sorted(float((p0 + s * uo) @ uc) for s in (s_lo, s_hi))
    t_lo, t_hi = max(t_lo, c.t_start_px), min(t_hi, c.t_end_px)
    if t_lo >= t_hi:
        return None
    return t_lo, t_hi, p0 + np.clip(s_x, o.t_start_px - fused, o.t_end_px + fused) * uo


def double_groove(prof: np.ndarray, e: np.ndarray, dark: bool, sigma: float,
                  half_px: float) -> tuple[float, float] | None:
    """Two grooves side by side in a median profile across a line: their positions, or None.

    Parameters
    ----------
    prof : ndarray
        Median profile [DN] at the across positions ``e`` [px] (1 px steps; NaN: no data).
    dark : bool
        Grooves darker than the surface.
    sigma : float
        Noise of one value of ``prof`` [DN].
    half_px : float
        Half-width of one groove [px]: minima closer than this are one groove.

    Returns (e1, e2) [px], e1 < e2, when the profile has two minima (maxima for bright
    grooves) each at least a third of the deeper one's depth below the background, with a
    hump between them rising 5 ``sigma`` and a tenth of that depth above the shallower one.
    """
    ok = np.isfinite(prof)
    if ok.sum() < 8:
        return None
    y = np.where(ok, -prof if dark else prof, np.nan)  # grooves as peaks
    ends = np.concatenate([y[:4], y[-4:]])
    ends = ends[np.isfinite(ends)]
    bg = float(ends.mean()) if ends.size else float(np.nanmean(y))  # background beyond both
    y = y - bg
    with np.errstate(invalid="ignore"):  # NaN compares False: no peak next to a gap
        peaks = np.flatnonzero((y[1:-1] >= y[:-2]) & (y[1:-1] > y[2:])) + 1
    if len(peaks) < 2:
        return None
    top = float(y[peaks].max())
    peaks = peaks[y[peaks] >= top / 3]
    if len(peaks) < 2:
        return None
    # Every pair (i < j) at once (a loop over the pairs cost ~0.1 ms a profile, ~200 profiles
    # a 5 MP mark): the lowest value between them is the running minimum from i (NaN
    # skipped) read at j; the deepest dip wins, the first pair in (i, j) order on a tie.
    yp, ep = y[peaks], e[peaks]
    span = np.arange(peaks[0], peaks[-1] + 1)
    runs = np.fmin.accumulate(np.where(span[None, :] >= peaks[:, None], y[span][None, :],
                                       np.nan), axis=1)
    low = np.minimum(yp[:, None], yp[None, :])
    dip = low - runs[:, peaks - peaks[0]]
    pair = np.triu(np.ones((len(peaks),) * 2, bool), 1) & (ep[None, :] - ep[:, None] >= half_px)
    good = pair & (dip >= max(5 * sigma, 0.1 * top))
    if not good.any():
        return None
    a, b = np.unravel_index(np.argmax(np.where(good, dip, -np.inf)), dip.shape)
    return float(ep[a]), float(ep[b])


def double_grooves(profs: np.ndarray, e: np.ndarray, dark: bool, sigma: float,
                   half_px: float) -> list[tuple[float, float] | None]:
    """:func:`double_groove` of each row of ``profs`` (median profiles, one per block along
    a line), the same answers: a row without two peaks of a third of the highest's height
    (above the background beyond both ends) is None at once, the others go through
    :func:`double_groove`.

    Along a clean line every block stops there (~220 blocks of a 5 MP mark, each a call
    of ~20 us), so that first test runs on all rows together: for rows without NaN by the
    same operations as :func:`double_groove`'s (the background the mean of the 4 values at
    each end, summed in numpy's pairwise order for 8 values), with a margin of 1e-9 of the
    profile's scale on the third (a row at the limit is passed on, never dropped). Rows
    with NaN go through :func:`double_groove` whole.
    """
    profs = np.asarray(profs, dtype=float)
    if profs.ndim != 2 or profs.shape[1] < 8 or profs.shape[0] == 0:
        return [double_groove(p, e, dark, sigma, half_px) for p in profs]
    y = -profs if dark else profs
    E = np.concatenate([y[:, :4], y[:, -4:]], axis=1)
    bg = (((E[:, 0] + E[:, 1]) + (E[:, 2] + E[:, 3]))
          + ((E[:, 4] + E[:, 5]) + (E[:, 6] + E[:, 7]))) / 8
    y = y - bg[:, None]
    with np.errstate(invalid="ignore"):
        mid = y[:, 1:-1]
        peak = (mid >= y[:, :-2]) & (mid > y[:, 2:])
        top = np.max(np.where(peak, mid, -np.inf), axis=1)
        margin = 1e-9 * (np.abs(top) + np.abs(bg))
        big = peak & (mid >= (top / 3 - margin)[:, None])
    maybe = (big.sum(axis=1) >= 2) | ~np.isfinite(profs).all(axis=1)
    return [double_groove(p, e, dark, sigma, half_px) if m else None
            for p, m in zip(profs, maybe, strict=True)]


FUSE_WIDTHS = 5.0
"""Widest separation of two straddling grooves that can be one fused ridge [groove
half-widths] (see :func:`fused_crossing`)."""


def fused_crossing(pairs: list[tuple[float, tuple[float, float] | None]], half_px: float
                   ) -> tuple[float, float] | None:
    """Whether a line is the fused ridge of two marks crossing at a shallow angle.

    ``pairs``: (position t along the line [px], :func:`double_groove` of the profile across
    it there). The fused ridge runs along the bisector of the two marks, so where their
    grooves part, both lie off the line on opposite sides; along a true mark that another
    crosses, one of the two grooves is the mark itself, on the line. Fused: two or more
    places where the grooves straddle the line (each more than ``half_px`` off it). (Two
    parallel grooves found as one line straddle it too, and cannot be measured as one mark
    either.)

    Returns (t [px], separation [px]) of the widest such place, or None.
    """
    # Two grooves far apart no longer make one ridge between them (the coarse filter is a
    # few groove widths wide): beyond FUSE_WIDTHS half-widths apart they are neighbours —
    # a ruled scale's next line, a speck or a numeral beside the line — not a fused pair.
    straddle = [(t, g[1] - g[0]) for t, g in pairs
                if g is not None and g[0] < -half_px and g[1] > half_px
                and g[1] - g[0] <= FUSE_WIDTHS * half_px]
    if len(straddle) < 2:
        return None
    return max(straddle, key=lambda p: p[1])
