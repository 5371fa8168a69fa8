"""The coarse search's candidates checked on the full-resolution image.

Each candidate is re-centred from profiles across it (robust medians along it), and kept when
it stands out pixel by pixel (contrast over the pixel noise, against the background on both
sides) and from the background's own relief averaged along it (a machining lay's streaks are
many alike; a mark is one deep groove).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy import ndimage, optimize, special

from imaging.candidate import (
    MarkCandidate,
    _dedupe,
    _drop_fused,
    _near,
    _overlap,
    line_frame,
    wrap_angle,
)
from imaging.compressed import compressed
from imaging.crossing import double_grooves, fused_crossing
from imaging.median import median, median_inplace


def across(image: np.ndarray, c: MarkCandidate, reach: int, n_along: int, top: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Profiles across a candidate at ``n_along`` places, nearest-pixel sampled at 1 px steps
    (NaN off the image and where clipped at 0 or ``top``): (values (n_along, E), e, t [px]).
    Also used by :mod:`imaging.crossmask` (where another mark crosses this one)."""
    h, w = image.shape
    u, n = line_frame(c.angle_rad)
    e = np.arange(-reach, reach + 1, dtype=float)
    t = np.linspace(c.t_start_px, c.t_end_px, n_along + 2)[1:-1]
    # Each coordinate on its own (along, across) grid: the sums of the 3-D (along, across, xy)
    # array this replaced, in the same order, at half the passes over ~250k samples at 5 MP.
    base = np.array([(w - 1) / 2, (h - 1) / 2]) + c.offset_px * n
    xi = np.rint((base[0] + t * u[0])[:, None] + e * n[0]).astype(np.intp)
    yi = np.rint((base[1] + t * u[1])[:, None] + e * n[1]).astype(np.intp)
    # Samples all on the image (the usual case, 4 reductions) need no clip and no mask.
    whole = xi.size > 0 and xi.min() >= 0 and xi.max() < w and yi.min() >= 0 and yi.max() < h
    inside = True if whole else (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    yc, xc = (yi, xi) if whole else (np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1))
    # One flat index instead of a (row, column) pair: numpy's 2-D fancy indexing costs ~2x.
    vals = image.ravel()[yc * w + xc] if image.flags.c_contiguous else image[yc, xc]
    # Off the image and clipped pixels (a padded border, a saturated patch) say nothing;
    # none there (the usual case) as two reductions tell, without the masks' four passes.
    if (whole and vals.size and vals.dtype.kind == "f" and vals.min() > 0
            and vals.max() < top):  # (NaN fails both; an integer image gets floats below)
        return vals, e, t
    vals = np.where(inside & (vals > 0) & (vals < top), vals, np.nan)
    return vals, e, t


def nan_median(x: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmedian of an array along ``axis``, the same values (the middle one of the
    sorted non-NaN values, the mean of the two middle ones when even; NaN where there is
    none, without a warning). By hand: numpy takes a masked-array path for these short
    axes, ~4 ms a call on a candidate's profiles (~0.5 s of a real photo's confirmation)."""
    s = np.sort(x, axis=axis)  # NaN sorts last
    cnt = np.count_nonzero(~np.isnan(x), axis=axis)
    h = cnt // 2
    lo = np.where(cnt % 2 == 1, h, np.maximum(h - 1, 0))
    a = np.take_along_axis(s, np.expand_dims(lo, axis), axis).squeeze(axis)
    b = np.take_along_axis(s, np.expand_dims(h, axis), axis).squeeze(axis)
    return np.where(cnt > 0, (a + b) / 2, np.nan)


def _column_median(vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's median over its finite values (nan where it has none) and which columns
    have any. np.median when nothing is missing (the same values, in about half the time of
    np.nanmedian, which sorts column by column)."""
    if _all_finite(vals):  # (the usual case, as two reductions tell: no mask's passes)
        return _median_axis0(vals).astype(float, copy=False), np.ones(vals.shape[1], bool)
    finite = np.isfinite(vals)
    cols = finite.any(axis=0)
    prof = np.full(vals.shape[1], np.nan)
    if finite.all():
        prof[:] = _median_axis0(vals)  # no column to leave out: no copy of the samples
    else:
        prof[cols] = nan_median(vals[:, cols], axis=0)
    return prof, cols


def _all_finite(vals: np.ndarray) -> bool:
    """Whether a non-empty array holds no NaN and no infinity: its minimum and maximum are
    finite (a NaN makes both NaN), two reductions instead of a mask's passes."""
    return bool(vals.size and np.isfinite(vals.min()) and np.isfinite(vals.max()))


def _median_axis0(vals: np.ndarray) -> np.ndarray:
    """np.median(vals, axis=0) of finite values, the same numbers. When every value is a
    whole number in 0..65535 (an image read from an integer file, not rescaled) each column
    is selected as 16-bit integers: ~1.2 ms, not ~4, for a 5 MP mark's 2000 profiles across it
    (the middle value, or the mean of the middle two in float64, as np.median's)."""
    if vals.shape[0] >= 64 and vals.min() >= 0 and vals.max() <= 65535:
        q = vals.T.astype(np.uint16)
        if np.array_equal(q, vals.T):
            # The middle ranks by numpy's stable sort, a radix sort on 16-bit integers: ~0.8x
            # the time of a selection of rank m (and the (m-1)-th is then read, not searched).
            m = q.shape[1] // 2
            q.sort(axis=1, kind="stable")
            return (q[:, m].astype(float) if q.shape[1] % 2
                    else (q[:, m - 1].astype(float) + q[:, m]) / 2)
    return np.median(vals, axis=0)


def _peak(vals: np.ndarray, e: np.ndarray, dark: bool, half: float, search: float,
          median: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[float, float]:
    """Median profile's extreme within ``search`` of the line: (position [px], contrast [DN]).

    The contrast is against the background on each side separately (the median of up to 6 px
    just beyond the flank), and the smaller of the two counts: a mark stands out from both
    sides, whereas an edge, or the strip of background between a mark and a dark padded
    border, stands out from one side only. No valid pixel beyond one flank: contrast 0.
    ``median``: :func:`_column_median` of ``vals`` when the caller has it already.
    """
    prof, cols = median if median is not None else _column_median(vals)
    if cols.sum() < 5:
        return 0.0, 0.0
    sign = -1.0 if dark else 1.0
    score = np.where(np.abs(e) <= search, sign * prof, np.nan)
    if not np.isfinite(score).any():
        return 0.0, 0.0
    k = int(np.nanargmax(score))
    sides = []
    for side in (-1, 1):
        d = side * (e - e[k])
        pick = cols & (d > half + 1) & (d <= half + 7)
        if pick.sum() < 2:
            return float(e[k]), 0.0
        sides.append(float(median_inplace(prof[pick])))  # (a boolean selection: a copy)
    contrast = min(sign * (prof[k] - b) for b in sides)
    bg = max(sides) if dark else min(sides)
    near = (np.abs(e - e[k]) <= half) & cols
    wgt = np.clip(sign * (prof - bg), 0, None) * near
    pos = float((wgt * e).sum() / wgt.sum()) if wgt.sum() > 0 else float(e[k])
    return pos, float(contrast)


def _full_res(image: np.ndarray, c: MarkCandidate, noise: float, f: int, top: float,
              n_along: int = 48) -> tuple[MarkCandidate, float]:
    """The candidate re-centred on the full-resolution image, and its contrast / pixel noise.

    The block-averaged search places a mark only to a block or so, and near the frame edge
    the padding pulls its ridge inwards; profiles across the mark (the median over places is
    robust to dust) put it back, each half of its length separately to correct the angle.
    The contrast is what one pixel shows: a line-shaped filter integrates a long faint
    streak into a strong response, a mark stands out pixel by pixel.
    """
    reach = int(np.ceil(c.thickness_px + 8 + 3 * f))
    half = max(1.0, c.thickness_px / 2 + 1)
    vals, e, t = across(image, c, reach, n_along, top)
    search = half + 1 + 2 * f
    pos, contrast = _peak(vals, e, c.dark, half, search)
    m = n_along // 2
    p1, c1 = _peak(vals[:m], e, c.dark, half, search)
    p2, c2 = _peak(vals[m:], e, c.dark, half, search)
    u, n = line_frame(c.angle_rad)
    if c1 > 0 and c2 > 0 and abs(p1 - pos) < half + 2 and abs(p2 - pos) < half + 2:
        q1 = c.offset_px * n + t[:m].mean() * u + p1 * n
        q2 = c.offset_px * n + t[m:].mean() * u + p2 * n
        v = q2 - q1
        a = wrap_angle(float(np.arctan2(-v[1], v[0])))
        if abs(wrap_angle(a - c.angle_rad)) < np.deg2rad(3):
            u2, n2 = line_frame(a)
            ends = sorted(float((c.offset_px * n + tk * u) @ u2)
                          for tk in (c.t_start_px, c.t_end_px))
            return replace(c, angle_rad=a, offset_px=float(q1 @ n2), t_start_px=ends[0],
                           t_end_px=ends[1]), contrast / max(noise, 1e-12)
    return replace(c, offset_px=c.offset_px + pos), contrast / max(noise, 1e-12)


def distinctness(image: np.ndarray, c: MarkCandidate, top: float, reach: float = 60.0,
                 alpha: float = 1e-3, lit: bool = False,
                 profiles: tuple[np.ndarray, np.ndarray] | None = None
                 ) -> tuple[float, float]:
    """How far a candidate stands out of the background's own relief across it, averaged
    along it, and how far the relief alone could reach by chance: (contrast / spread, limit).

    The median along the candidate's length averages pixel noise and isotropic texture away,
    but not a machining lay running the same way: there the profile beside the candidate is
    as rough as the candidate itself (one of many similar ridges), whereas a mark is one
    deep groove on a background that averages flat. ``spread`` is the robust (MAD) spread of
    that profile beside the candidate (up to ``reach`` px each side), a quadratic trend
    (vignetting, a gradient) removed.

    ``limit``: the relief's largest value in the search at level ``alpha``: the normal
    quantile at alpha / (2 M), M ~ the image diagonal in px (the across positions searched,
    one per px, both polarities), widened by 3 standard errors of the MAD spread (relative
    1.16 / sqrt(n_eff); n_eff from the profile's lag-1 correlation r, n (1 - r) / (1 + r)).
    (inf, 0): too little background beside it to judge; left to the other tests.

    ``lit``: each profile divided by its own light level first (:func:`relative_to_light`),
    where one straight shadow edge crosses the candidate or runs along it (the light steps
    by :data:`LIGHT_STEP` or more, monotonically: :func:`light_steps`; else (0, inf)): a
    shadow's edge crossing the candidate makes the medians along it step from the lit to
    the shadowed level where the crossing point passes mid-length, one running along it
    puts a step beside the groove in every profile: reliefs the groove does not have. (A
    mark under an edge along it is measured on the light the edge's model divides out:
    :func:`shadow_free`.)

    ``profiles``: :func:`distinct_profiles` of the same arguments when the caller has them
    (the plain test and the ``lit`` one read the same profiles).
    """
    half = max(1.0, c.thickness_px / 2 + 1)
    n_along = int(np.clip(c.length_px, 16, 2000))
    vals, e = distinct_profiles(image, c, top, reach) if profiles is None else profiles
    if lit:
        change, rho, _ = light_steps(vals, e, half)
        if change < LIGHT_STEP or rho < MONOTONE:
            return 0.0, float("inf")  # no shadow edge across or along it: the plain test stands
        vals = relative_to_light(vals, 4 * int(np.ceil(half)) + 3)
    least = max(5, n_along // 4)
    cols = (np.full(vals.shape[1], vals.shape[0] >= least) if _all_finite(vals)
            else np.isfinite(vals).sum(axis=0) >= least)
    med = _column_median(vals)  # one median profile for both uses (each column's own)
    prof = np.where(cols, med[0], np.nan)
    bg = cols & (np.abs(e) > 2 * half + 2)
    if bg.sum() < 20:
        return float("inf"), 0.0
    _, contrast = _peak(vals, e, c.dark, half, half + 1, med)
    x, y = e[bg], prof[bg]
    res = y - np.polyval(np.polyfit(x, y, 2), x)
    spread = 1.4826 * float(median_inplace(np.abs(res - median(res))))
    if spread <= 0:
        return float("inf"), 0.0
    adjacent = np.diff(x) == 1
    rc = res - res.mean()
    r1 = float(np.clip((rc[1:] * rc[:-1])[adjacent].mean() / max(np.mean(rc * rc), 1e-300),
                       0.0, 0.95)) if adjacent.any() else 0.0
    n_eff = max(len(res) * (1 - r1) / (1 + r1), 4.0)
    m = 2 * np.hypot(*image.shape)
    limit = float(-special.ndtri(alpha / (2 * m)) * (1 + 3 * 1.16 / np.sqrt(n_eff)))
    return float(contrast / spread), limit


def distinct_profiles(image: np.ndarray, c: MarkCandidate, top: float, reach: float = 60.0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The profiles across candidate ``c`` that :func:`distinctness` judges: (values, e [px])
    of :func:`across`, one per px of its length (16-2000), ``reach`` px beyond its groove."""
    half = max(1.0, c.thickness_px / 2 + 1)
    vals, e, _ = across(image, c, int(np.ceil(reach + half)), int(np.clip(c.length_px, 16, 2000)),
                        top)
    return vals, e


LIGHT_STEP = 0.08
"""Relative change of the light along a candidate (10th to 90th percentile of its profiles'
background levels) from which a shadow's edge is taken to cross it: above what vignetting
changes along a mark (a few %), below the shallowest shadow that hid a mark (15-20 %)."""
MONOTONE = 0.8
"""Least |Spearman rank correlation| of that light level with the position along the
candidate: one straight shadow edge takes it from one level to the other once; a busy
scene (a circuit board, printed matter) changes it up and down."""
UNDER = 0.5
"""Largest fraction of a candidate's length along which the step in the light lies beside
the groove (within its profile window): beyond it the edge runs along the mark (a shallow
crossing), the step biases the groove's centres, and the candidate is not taken on this
ground."""
MAX_NFEV = 100
"""Evaluations each start of the shadow-edge fit may take (:func:`shadow_free`): twice what
the converging starts took on the real chessboards (at most ~50; left01-03, right02); a
start still running beyond them is wandering (left01: 654 evaluations to a worse cost)."""
TIE = 1e-6
"""Relative cost within which shadow-edge fits count as the same: the cost is half the sum of
squares of ~1e4 relative residuals, so 1e-6 of it is ~1e-2 in chi2, no evidence between
them."""


def light_steps(vals: np.ndarray, e: np.ndarray, half: float) -> tuple[float, float, float]:
    """How the light changes along a line, from profiles across it (:func:`across`; ``half``
    the groove's half-width [px]): (change, monotony, under).

    ``change``: the spread (10th to 90th percentile) of the profiles' light levels (each the
    median beyond ``2 half + 2`` px of the line, both sides) over their median; ``monotony``:
    |Spearman rank correlation| of those levels with the position along the line;
    ``under``: the fraction of profiles whose two sides (within 12 px beyond that) differ by
    more than LIGHT_STEP / 2 (the step lies beside the groove). Zeros when too few profiles
    have background.
    """
    clear = 2 * half + 2
    far = np.abs(e) > clear
    rows = np.isfinite(vals[:, far]).sum(axis=1) >= 5
    if rows.sum() < 8:
        return 0.0, 0.0, 0.0
    v = vals[rows]
    level = nan_median(v[:, far], axis=1)
    q10, q50, q90 = np.percentile(level, (10, 50, 90))
    if q50 <= 0 or q90 == q10:
        return 0.0, 0.0, 0.0
    rho = abs(float(np.corrcoef(np.flatnonzero(rows), _ranks(level))[0, 1]))
    # A side off the image is NaN: no step seen there.
    left = nan_median(v[:, (e < -clear) & (e >= -clear - 12)], axis=1)
    right = nan_median(v[:, (e > clear) & (e <= clear + 12)], axis=1)
    under = float(np.mean(np.abs(left - right) > 0.5 * LIGHT_STEP * q50))
    return float((q90 - q10) / q50), rho, under


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks of ``x``, ties averaged (Spearman's correlation is the linear one of ranks).
    By hand: scipy.stats.rankdata would import scipy.stats, ~0.8 s per command
    (tests/test_import_graph.py)."""
    r = np.empty(len(x))
    r[np.argsort(x, kind="stable")] = np.arange(len(x))
    _, inv, cnt = np.unique(x, return_inverse=True, return_counts=True)
    return (np.bincount(inv, r) / cnt)[inv]


def shadow_along(vals: np.ndarray, e: np.ndarray, half: float) -> bool:
    """Whether one straight shadow edge runs along a line (:func:`light_steps`): the light
    changes by :data:`LIGHT_STEP` or more, monotonically (:data:`MONOTONE`), and steps beside
    the groove over more than :data:`UNDER` of its length."""
    change, rho, under = light_steps(vals, e, half)
    return change >= LIGHT_STEP and rho >= MONOTONE and under > UNDER


def _edge_model(q: np.ndarray, t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """A straight shadow edge's factor on the light at (t, e): 1 - D Phi((e - e0 - k t) / w),
    ``q`` = (e0 [px], k, log w [log px], D)."""
    e0, k, logw, d = q
    return 1.0 - d * special.ndtr((e - e0 - k * t) / np.exp(logw))


def _lit_edge_jacobian(q: np.ndarray, t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Jacobian (N, 7) of :func:`shadow_free`'s model of the light, plane (q[4] + q[5] t / 100
    + q[6] e / 100) times the edge's factor (:func:`_edge_model` of q[:4]), at (t, e) [px].
    By hand: finite differences cost 7 more evaluations of the model per step (a real
    photo's edge: ~0.3 s CPU over 10 fits of ~17k pixels)."""
    return _lit_edge(q, t, e)[1]()


def _lit_edge(q: np.ndarray, t: np.ndarray, e: np.ndarray
              ) -> tuple[np.ndarray, Callable[[], np.ndarray]]:
    """:func:`shadow_free`'s model of the light at ``q`` (the plane times :func:`_edge_model`,
    the same bits) and a function that gives its Jacobian (:func:`_lit_edge_jacobian`) from
    the same intermediate arrays. scipy's least_squares asks for the Jacobian at the point
    whose residual it has just taken: each accepted step's edge, Gaussian argument, normal
    CDF and plane were computed twice. (scipy's own work per step, not this model, is most
    of a fit's CPU on these ~2-17k-pixel problems.)"""
    e0, k, logw, d = q[:4]
    w = np.exp(logw)
    z = (e - e0 - k * t) / w
    plane = q[4] + q[5] * t / 100 + q[6] * e / 100
    cdf = special.ndtr(z)
    edge = 1.0 - d * cdf

    def jac() -> np.ndarray:
        phi = np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)
        g = plane * d * phi / w  # d/d(e0); the edge lies at e0 + k t
        return np.column_stack([g, g * t, g * w * z, -plane * cdf,
                                edge, edge * t / 100, edge * e / 100])

    return plane * edge, jac


def shadow_free(image: np.ndarray, c: MarkCandidate, top: float, reach: float = 40.0
                ) -> tuple[np.ndarray, tuple[float, float, float, float]] | None:
    """The image with the shadow of one straight edge running along candidate ``c`` divided
    out, and the edge: (image [DN], (angle to the line [rad], offset at the line's middle
    [px], penumbra sigma [px], depth)); None when no edge runs along it.

    A shadow multiplies the light by 1 - D Phi(s / w) (s the distance from the edge, w the
    penumbra's sigma). The edge is fitted, with a plane for the rest of the light, to the
    background within ``reach`` px of the line (the groove's band left out; scipy's
    least_squares from a grid of starts): the edge is straight, so where it runs under the
    groove its place there is the one the background on both sides of that stretch fixes.
    The groove is then measured on the image divided by the edge's factor (the plane
    stays: the measurement takes a smooth light itself).
    """
    half = max(1.0, c.thickness_px / 2 + 1)
    n_along = int(np.clip(c.length_px / 4, 16, 200))
    vals, e, t = across(image, c, int(np.ceil(reach + half)), n_along, top)
    if not shadow_along(vals, e, half):
        return None
    tt, ee = np.broadcast_arrays(t[:, None] - t.mean(), e[None, :])
    keep = np.isfinite(vals) & (np.abs(ee) > 2 * half + 2)
    y, tt, ee = vals[keep], tt[keep], ee[keep]
    scale = float(median(y))

    y_rel = y / scale
    # The solver is given the compressed problem (imaging.compressed: 8 rows, not one per
    # background pixel), not its SVD of the ~2-17k x 7 scaled Jacobian every step (0.80 ->
    # 0.69 s over left01-03). Each point's residual and Jacobian from one model evaluation.
    last: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def at(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = q.tobytes()
        if key not in last:
            last.clear()
            lit, jac = _lit_edge(q, tt, ee)
            last[key] = compressed(lit - y_rel, jac())
        return last[key]

    lo = [-reach, -0.5, np.log(0.3), -0.95, 0, -1, -1]
    hi = [reach, 0.5, np.log(reach), 0.95, 3, 1, 1]
    starts = [[e0, 0.0, np.log(3.0), d0, 1.0, 0.0, 0.0]
              for e0 in np.linspace(-reach / 2, reach / 2, 5) for d0 in (0.3, -0.3)]
    # Each start is stopped after MAX_NFEV evaluations: on left01-03 and right02 the starts
    # that converge take at most ~50, while one (left01: edge at -20 px, depth -0.3) wandered
    # for 654 (0.4 s of CPU) to a cost above the best. Dropping starts whose cost after a
    # few evaluations is far above the best's was tried and is not safe: on left03 the
    # winning start's cost was 37 % above another's after 10 evaluations and fell below it.
    fits = [optimize.least_squares(lambda q: at(q)[0], x0, jac=lambda q: at(q)[1],
                                   bounds=(lo, hi), max_nfev=MAX_NFEV) for x0 in starts]
    # Several starts reach the same cost with the edge a fraction of a pixel apart (the
    # data do not pin it there): among those within a relative TIE of the least cost, the
    # edge nearest the line is taken, so the choice does not hang on the last digits.
    least = min(r.cost for r in fits)
    best = min((r for r in fits if r.cost <= least * (1 + TIE)), key=lambda r: abs(r.x[0]))
    q = best.x
    h, w = image.shape
    u, n = line_frame(c.angle_rad)
    ys, xs = np.mgrid[0:h, 0:w]
    px, py = xs - (w - 1) / 2, ys - (h - 1) / 2
    tp = px * u[0] + py * u[1] - t.mean()
    ep = px * n[0] + py * n[1] - c.offset_px
    out = image / _edge_model(q[:4], tp, ep)
    return out, (float(np.arctan(q[1])), float(q[0]), float(np.exp(q[2])), float(q[3]))


def shadow_note(image: np.ndarray, cands: Sequence[MarkCandidate], top: float) -> str | None:
    """Why a line that a shadow's edge runs along was not taken (for "no mark found"): the
    first coarse candidate ``cands`` whose light steps under its groove (:func:`light_steps`
    beyond :data:`UNDER`), or None."""
    for c in cands:
        half = max(1.0, c.thickness_px / 2 + 1)
        vals, e, _ = across(image, c, int(np.ceil(3 * half + 16)), 64, top)
        change, rho, under = light_steps(vals, e, half)
        if change >= LIGHT_STEP and rho >= MONOTONE and under > UNDER:
            return (f"a shadow's edge runs along the line at {np.rad2deg(c.angle_rad):.1f}° "
                    f"(the light steps {100 * change:.0f} % beside it over "
                    f"{100 * under:.0f} % of its length): a groove whose background steps "
                    "under it is not measured; light the face evenly or keep the shadow's "
                    "edge off the mark")
    return None


def relative_to_light(vals: np.ndarray, window: int) -> np.ndarray:
    """Profiles across a line (:func:`across`) each divided by its own light level: a running
    median across, ``window`` px wide (odd, over twice the groove's width).

    A shadow multiplies the light: the ratio is the surface's own reflectance, flat across a
    shadow's edge. The running median keeps a step (a monotone edge passes a median filter
    unchanged) and drops a groove or streak narrower than half the window, so those stay in
    the ratio as they were. Missing samples (NaN) are filled with the row's median for the
    filter and stay missing.
    """
    finite = np.isfinite(vals)
    rows = finite.any(axis=1)
    fill = np.zeros(len(vals))
    fill[rows] = nan_median(vals[rows], axis=1)
    level = ndimage.median_filter(np.where(finite, vals, fill[:, None]), size=(1, window),
                                  mode="nearest")
    return np.where(finite & (level > 0), vals / np.where(level > 0, level, 1.0), np.nan)


def confirm_candidates(image: np.ndarray, cands: list[MarkCandidate], noise_full: float,
                       f: int, top: float, min_pixel_snr: float, reach: float = 60.0
                       ) -> list[MarkCandidate]:
    """Candidates re-centred on the full-resolution image that stand out pixel by pixel and
    from the background's relief."""
    out = []
    for c in cands:
        coarse = c
        # Twice: a coarse angle smears the profile along a short mark (and hides its contrast).
        c, _ = _full_res(image, c, noise_full, f, top)
        c, snr = _full_res(image, c, noise_full, f, top)
        if snr < min_pixel_snr:
            continue
        # A machining lay running along the candidate: each streak is long, and the ridge
        # filter integrates it into a strong response, but beside it lie many like it.
        # (the profiles read once for both tests: ~1/4 of a busy photo's profile reads)
        profiles = distinct_profiles(image, c, top, reach)
        ratio, limit = distinctness(image, c, top, reach, profiles=profiles)
        lit = ratio < limit
        if lit:
            # A shadow's edge crossing it: judged again on the light-normalised profiles.
            ratio, limit = distinctness(image, c, top, reach, lit=True, profiles=profiles)
            if ratio < limit:
                continue
        # Two marks fused along their bisector: seen so on the coarse line (re-centring
        # would pull it onto one of the two grooves, and the other would go unsaid). Asked
        # of those kept only (building.jpg: 22 of 46 are refused above).
        fused = _fused(image, coarse, noise_full, top)
        # (once re-centred, a line lies on a groove: two grooves no longer straddle it)
        out.append((c if fused is None else replace(coarse, fused=fused), lit))
    kept = _dedupe([c for c, lit in out if not (lit and any(_shoulder(c, o) for o, _ in out))])
    return _drop_fused(_joined_along(image, kept, top))


def _joined_along(image: np.ndarray, cands: list[MarkCandidate], top: float
                  ) -> list[MarkCandidate]:
    """Pieces of one mark that a shadow's edge along it broke in two, joined.

    Where the edge runs under the groove (a 5 deg edge: over ~100 px of a 350 px mark) the
    ridge filter sees no groove, and the mark is found as two collinear pieces; each was
    then measured over the whole groove (the measurement follows it to its ends): one mark
    reported twice, or refused as lying in the other's window. Two pieces of one polarity,
    not overlapping, both along the line through their middles (:func:`_through`; the edge
    pulls a piece's coarse direction by up to ~4 deg) and one of them with a shadow's edge
    along it (:func:`shadow_along`): one candidate through both middles.
    """
    out = list(cands)
    i = 0
    while i < len(out):
        c = out[i]
        pair = next(((j, k) for j, o in enumerate(out) if j != i and o.dark == c.dark
                     and not _overlap(c, o) and (k := _through(c, o)) is not None
                     and (_along(image, c, top) or _along(image, o, top))), None)
        if pair is None:
            i += 1
            continue
        j, joined = pair
        out = [k for m, k in enumerate(out) if m not in (i, j)]
        out.insert(min(i, j), joined)
        i = 0
    return out


def _through(c: MarkCandidate, o: MarkCandidate) -> MarkCandidate | None:
    """One candidate through the middles of ``c`` and ``o`` when both lie along it (their
    directions within 5 deg of it, their ends within their width + 6 px of it), else None."""
    ends = np.array([_point(k, t) for k in (c, o) for t in (k.t_start_px, k.t_end_px)])
    mids = np.array([ends[:2].mean(axis=0), ends[2:].mean(axis=0)])
    v = mids[1] - mids[0]
    a = wrap_angle(float(np.arctan2(-v[1], v[0])))
    u, n = line_frame(a)
    d = np.abs(ends @ n - mids[0] @ n)
    if (any(abs(wrap_angle(k.angle_rad - a)) >= np.deg2rad(5) for k in (c, o))
            or d[:2].max() >= c.thickness_px + 6 or d[2:].max() >= o.thickness_px + 6):
        return None
    t = ends @ u
    return replace(c if c.strength >= o.strength else o, angle_rad=a,
                   offset_px=float(mids[0] @ n), t_start_px=float(t.min()),
                   t_end_px=float(t.max()), strength=c.strength + o.strength,
                   thickness_px=max(c.thickness_px, o.thickness_px))


def _point(c: MarkCandidate, t: float) -> np.ndarray:
    """The point at ``t`` [px] along a candidate's line (relative to the image centre)."""
    u, n = line_frame(c.angle_rad)
    return c.offset_px * n + t * u


def _along(image: np.ndarray, c: MarkCandidate, top: float) -> bool:
    """Whether a shadow's edge runs along candidate ``c`` (:func:`shadow_along`)."""
    half = max(1.0, c.thickness_px / 2 + 1)
    vals, e, _ = across(image, c, int(np.ceil(3 * half + 16)), 64, top)
    return shadow_along(vals, e, half)


def _shoulder(c: MarkCandidate, o: MarkCandidate) -> bool:
    """Whether c is the strip of background between mark o and a shadow's edge along it:
    of the other polarity, weaker, parallel and within o's width and a few px of it (the
    strip is brighter than the groove on one side and the shadow on the other)."""
    return (c.dark != o.dark and c.strength < o.strength
            and _near(c, o, np.deg2rad(3), c.thickness_px + o.thickness_px + 6) and _overlap(c, o))


def _fused(image: np.ndarray, c: MarkCandidate, noise: float, top: float,
           block_px: int = 20) -> tuple[float, float] | None:
    """Where a candidate is seen as two grooves straddling it (see MarkCandidate.fused):
    median profiles across it over ``block_px`` stretches, each tested for two grooves."""
    half = max(2.5, c.thickness_px)
    n_along = max(int(c.length_px), 2 * block_px)
    vals, e, t = across(image, c, int(np.ceil(c.thickness_px + 18)), n_along, top)
    sigma = 1.25 * noise / np.sqrt(block_px)
    profs, ts = block_medians(vals, t, block_px)
    return fused_crossing(list(zip(ts, double_grooves(profs, e, c.dark, sigma, half),
                                   strict=True)), half)


def block_medians(vals: np.ndarray, t: np.ndarray, block_px: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Median profiles over consecutive blocks of ``block_px`` rows of :func:`across`
    values (NaN where a column has no value), and each block's mean position t [px]."""
    nb = len(t) // block_px
    v = vals[:nb * block_px].reshape(nb, block_px, -1)
    if np.isfinite(v).all():
        # np.median's values (the middle one, or the mean of the middle two) from one sort:
        # on blocks of ~20 rows ~4x faster than its partition, and np.nanmedian's.
        # (Each block's columns sorted as contiguous rows: ~30 % faster than along axis 1.)
        s = np.sort(v.transpose(0, 2, 1), axis=-1)
        m = block_px // 2
        profs = s[..., m] if block_px % 2 else (s[..., m - 1] + s[..., m]) / 2
    else:
        profs = nan_median(v, axis=1)  # an all-NaN column is NaN, as it should be
    return profs, t[:nb * block_px].reshape(nb, block_px).mean(axis=1)
