"""The groove's own cross-profile, read from the mark's residuals (an empirical line spread).

The centres are fitted with a flat-bottomed groove through a Gaussian blur
(:mod:`imaging.groove`). A real groove need not be flat-bottomed (a ground scribe's is a
rounded V): the misfit is symmetric, but where the profile holds detail near the pixel
frequency, sampled by the pixel grid at a sub-pixel phase it moves each segment's centre by
an amount that depends on that phase. On a mark within a fraction of a degree of a pixel
axis the phase drifts slowly along the mark, and the bias becomes a slow trend that tilts
the fitted line (user6's rounded groove, sub-pixel samples of its sharp-edged profile
blurred after them: RMS z 1.52; the same groove blurred before the pixels integrate it, as
optics do, showed none: RMS z 1.02 over 24 marks).

The pixels of all segments sample the profile at many phases (x = e - delta_k, the pixel's
distance from its own segment's centre), as the slanted-edge method (ISO 12233) oversamples
an edge. Their residuals divided by the contrast, pooled over the mark, give the profile's
departure D(x) from the model on a cubic B-spline basis (knots every :data:`KNOT_PX`), kept
*even* in x: a symmetric groove's profile is even about its centre, so D cannot move a
centre on its own, only through the phase. D is zero beyond the groove and its blur
(w/2 + 4 s), where the band holds background only.

D is **measured, not applied**: how far it moves each segment's centre
(:func:`shape_shift`) tilts the line by b, and sqrt(b^2 + sigma_b^2) enters the angle's u
as the Type B term ``groove_profile`` (:func:`profile_angle_u`) on every mark, without a
significance gate (at p < 1e-3 user6's rounded grooves, chi^2 15-55 on 12 dof, mostly went
uncovered). Fitted back into the centres (tried and withdrawn) it moved a
quantisation-dominated 8-bit groove (+17.1" -> +20.7" at u 5") and a ruled scale's line
among numerals (z -4.6) the wrong way; as a term it only widens u: x 1.003 on synth's clean
marks (median), x 1.06 on flat-bottomed grooves within 0.3 deg of an axis (the departure's
noise, at most x 1.45; ``tests/imaging/test_shape.py``). The pixels' distances are taken
from a straight line through the centres (``imaging.centres``), not from each segment's
own noisy centre.

What it cannot see: on a mark crossing < 1 phase cycle every segment samples the profile at
nearly one phase, and the centres absorb the part of the misfit that moves them, so the
pooled residuals show about half the bias (user6's grooves noise-free: 2.0" of 4.2",
1.2" of 3.1", 1.5" of 3.3"); fitting the departure jointly with the centres is not
determined there (its tilt came out -50" for +4.2").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline
from scipy.special import chdtrc

from imaging.groupsum import GroupSums

KNOT_PX = 0.5
"""Knot spacing of the departure's B-spline basis [px]: the blurred, pixel-integrated
profile varies over ~1 px (blur >= 0.5 px plus the pixel), which cubics every 0.5 px
follow to a few per cent."""

def phase_cycles(angle_rad: float, length_px: float) -> float:
    """How many cycles of the sub-pixel phase a line crosses along its length.

    Parameters
    ----------
    angle_rad : float
        The line's direction in the image [rad].
    length_px : float
        Its length [px].

    Returns
    -------
    float
        length x |sin| of its angle to the nearest pixel axis (dimensionless).
    """
    off_axis = (angle_rad + np.pi / 4) % (np.pi / 2) - np.pi / 4
    return float(length_px * abs(np.sin(off_axis)))


P_APPLY = 1e-3
"""A departure the pooled residuals hold at p < this (chi^2 test) is significant."""

MAX_Z = 5.0
"""Pixels whose residual exceeds this many sigma (dust, a crossing) stay out of the pool."""


@dataclass(frozen=True)
class GrooveShape:
    """An even departure D(x) of the groove's profile from the model (fraction of contrast).

    Attributes
    ----------
    knots : ndarray
        The B-spline's knots [px].
    fold : ndarray
        (n_basis, K) maps the K even coefficients onto the basis.
    coef : ndarray
        (K,) the even coefficients [1].
    cov : ndarray
        (K, K) their covariance [1].
    chi2 : float
        coef' cov^-1 coef: the departure's significance (K degrees of freedom).
    """

    knots: np.ndarray
    fold: np.ndarray
    coef: np.ndarray
    cov: np.ndarray
    chi2: float

    @property
    def significant(self) -> bool:
        """Whether the residuals hold the departure at p < :data:`P_APPLY`."""
        return bool(chdtrc(len(self.coef), self.chi2) < P_APPLY)

    def local(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The even basis at ``x`` [px], sparse: (cols, vals), each (len(x), 4); a column of
        -1 (value 0) where the basis function is not one of the K (or x lies outside)."""
        return _local(x, self.knots, self.fold)

    def design(self, x: np.ndarray) -> np.ndarray:
        """(len(x), K) the even basis at distances ``x`` from the centre [px] (0 outside)."""
        return _dense(*self.local(x), len(self.coef))

    def tabulate(self, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """D and dD/dx on ``grid`` [px] (0 beyond the groove's reach)."""
        spl = BSpline(self.knots, self.fold @ self.coef, 3, extrapolate=False)
        d, dd = spl(grid), spl.derivative()(grid)
        return np.nan_to_num(d), np.nan_to_num(dd)


def _knots(reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Uniform knots symmetric about 0 and the fold onto the even basis functions whose
    support lies within +-reach [px] (so D and its first two derivatives vanish there)."""
    m = max(int(np.ceil(reach / KNOT_PX)), 3)
    knots = KNOT_PX * np.arange(-m - 3, m + 4, dtype=float)
    n = len(knots) - 4
    inside = [j for j in range(n) if knots[j] >= -m * KNOT_PX - 1e-9
              and knots[j + 4] <= m * KNOT_PX + 1e-9]
    pairs = sorted({(min(j, n - 1 - j), max(j, n - 1 - j)) for j in inside})
    fold = np.zeros((n, len(pairs)))
    for c, (a, b) in enumerate(pairs):
        fold[a, c] = fold[b, c] = 1.0
    return knots, fold


def _local(x: np.ndarray, knots: np.ndarray, fold: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Uniform cubic B-splines at ``x`` folded onto the even columns: the 4 functions that
    are non-zero at each x (closed form in the position within the knot span) and their
    column (-1: none).

    By hand, not scipy's design matrix (the same numbers, tested): the uniform knots make
    each x's 4 values one cubic of its fractional position, and the sparse form turns the
    normal equations into bincounts. The dense product took ~8 ms CPU a mark in OpenBLAS's
    threads on a shared host, for 0.1 ms of work."""
    span, vals, span_cols = _spans(x, knots, fold)
    cols = span_cols[span]
    return cols, np.where(cols >= 0, vals, 0.0)


def _spans(x: np.ndarray, knots: np.ndarray, fold: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_local` by knot span: each x's span (len(knots) - 1 for an x outside the
    basis), the 4 cubics' values at it (not zeroed), and each span's 4 columns (-1: none):
    the columns of x are ``span_cols[span]``."""
    h = knots[1] - knots[0]
    u = (x - knots[0]) / h
    i = np.floor(u).astype(np.intp)
    f = u - i
    f3 = f ** 3  # (each power once: the same numbers as written out in each cubic)
    vals = np.stack([(1 - f) ** 3, 3 * f3 - 6 * f ** 2 + 4,
                     -3 * f3 + 3 * f ** 2 + 3 * f + 1, f3], axis=1) / 6
    colmap = np.full(fold.shape[0], -1)
    rows, cols = np.nonzero(fold)
    colmap[rows] = cols
    nspan = len(knots)
    inside = (x >= knots[3]) & (x < knots[-4])
    span = np.where(inside, i, nspan - 1)
    first = np.arange(nspan)
    span_cols = colmap[np.clip(first[:, None] + np.arange(-3, 1)[None, :], 0, len(colmap) - 1)]
    span_cols[(first < 3) | (first > nspan - 5)] = -1  # (no x inside lies in them)
    return span, vals, span_cols


def _dense(cols: np.ndarray, vals: np.ndarray, k: int) -> np.ndarray:
    """(n, k) from the sparse (cols, vals) of :func:`_local`."""
    n = len(cols)
    flat = (np.arange(n)[:, None] * k + np.maximum(cols, 0)).ravel()
    return np.bincount(flat, vals.ravel(), minlength=n * k).reshape(n, k)


def fit_shape(x: np.ndarray, r: np.ndarray, amp: np.ndarray, wgt: np.ndarray,
              reach: float, spans: tuple[np.ndarray, ...] | None = None) -> GrooveShape | None:
    """The even departure of the profile from the model, from pooled residuals.

    Parameters
    ----------
    x : ndarray
        Each pixel's distance from its segment's fitted centre [px].
    r : ndarray
        Its residual from the model [DN].
    amp : ndarray
        Its segment's contrast [DN].
    wgt : ndarray
        Its weight (1 / noise variance) [1/DN^2].
    reach : float
        Half-width of the groove and its blur, w/2 + 4 s [px]: D is 0 beyond.
    spans : tuple of ndarray, optional
        :func:`basis_spans` of ``x`` for this ``reach``, when the caller has them.

    Returns
    -------
    GrooveShape or None
        None when too few pixels for the basis.
    """
    knots, fold = _knots(reach)
    k = fold.shape[1]
    span, vals, span_cols = _spans(x, knots, fold) if spans is None else spans
    if len(x) < 4 * k:
        return None
    # Pixels no basis function reaches (the band's background) add exact zeros: left out.
    on = (span_cols >= 0).any(axis=1)[span]
    span, r, amp, wgt = span[on], r[on], amp[on], wgt[on]
    # The 4 functions' values and columns as 4 contiguous rows, each built as a row (the
    # products below read whole rows, not every 4th number): the same numbers as by pixel.
    cols = [np.ascontiguousarray(span_cols[:, a]).take(span) for a in range(4)]
    vals = np.stack([np.where(cols[a] >= 0, vals[:, a][on], 0.0) * amp for a in range(4)])
    # Dust or a crossing stays out of the pool: pixels beyond MAX_Z sigma of the departure's
    # own fit (a first fit on all, then without them; a clip on the residuals before the
    # departure dropped the groove's floor where the misfit itself is large).
    w = wgt.copy()
    ca = [np.maximum(c, 0) for c in cols]
    # The normal equations' sums per knot span (the 4 functions non-zero on a span are
    # fixed), then put in their columns: one grouping of the pixels for the 14 sums of each
    # pass (sums by column pair cost ~3x more; the sums' order differs in the last bit).
    # N is symmetric: the pairs a <= c only, the others as the transpose.
    sums = GroupSums(span, len(knots), eager=True)
    pairs = [(a, c) for a in range(4) for c in range(a, 4)]
    into_b = [(span_cols[:, a] >= 0, span_cols[:, a]) for a in range(4)]
    into_n = []
    for a, c in pairs:
        use = (span_cols[:, a] >= 0) & (span_cols[:, c] >= 0)
        into_n.append((use, span_cols[use, a], span_cols[use, c]))
    sw = np.sqrt(wgt)
    for it in range(2):
        wv = w * vals
        b = np.zeros(k)
        for a, (use, col) in enumerate(into_b):
            np.add.at(b, col[use], sums(wv[a] * r)[use])
        N = np.zeros((k, k))
        for (a, c), (use, row, col) in zip(pairs, into_n, strict=True):
            part = np.zeros((k, k))
            np.add.at(part, (row, col), sums(wv[a] * vals[c])[use])
            N += part if a == c else part + part.T
        try:
            cov = np.linalg.inv(N)
        except np.linalg.LinAlgError:
            return None
        coef = cov @ b
        if it == 1:
            break  # (the second fit's own outliers are not used)
        # (the sum over the 4 columns written out: the same order, ~3x faster than .sum)
        fit = ((vals[0] * coef[ca[0]] + vals[1] * coef[ca[1]]) + vals[2] * coef[ca[2]]
               + vals[3] * coef[ca[3]])
        keep = np.abs(r - fit) * sw < MAX_Z
        if keep.all():
            break  # (no outlier: the second fit's weights, and so its sums, are the first's)
        w = np.where(keep, wgt, 0.0)
    return GrooveShape(knots, fold, coef, cov, float(coef @ N @ coef))


def basis_spans(x: np.ndarray, reach: float) -> tuple[np.ndarray, ...]:
    """The departure's basis at ``x`` [px] for a groove of ``reach`` [px], by knot span (see
    :func:`fit_shape`, :func:`shape_shift`): computed once for both."""
    return _spans(x, *_knots(reach))


def shape_shift(shape: GrooveShape, x: np.ndarray, aw: np.ndarray, J: Sequence[np.ndarray],
                cov: np.ndarray, ok: np.ndarray, seg: np.ndarray,
                spans: tuple[np.ndarray, ...] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """How far the departure moves each segment's centre, and that shift's covariance.

    A departure D = B(x) c added to the model moves segment k's centre by
    -[N_k^-1 sum_px w J A_k B(x)]_0 c (one Gauss–Newton step): S c, with covariance
    S cov_c S^T from the departure's own noise.

    Parameters
    ----------
    shape : GrooveShape
        The fitted departure.
    x : ndarray
        Each pixel's distance from its segment's centre [px].
    aw : ndarray
        Each pixel's contrast times its weight [1/DN].
    J : sequence of ndarray
        The segment fit's columns at each pixel (centre first).
    cov : ndarray
        (nseg, k, k) the segments' inverse normal matrices.
    ok : ndarray
        (nseg,) segments whose fit is valid (bool).
    seg : ndarray
        Each pixel's segment.
    spans : tuple of ndarray, optional
        :func:`basis_spans` of ``x`` for the shape's reach, when the caller has them.

    Returns
    -------
    shift : ndarray
        (nseg,) the centres' shift [px] (0 on segments not ok).
    shift_cov : ndarray
        (nseg, nseg) its covariance [px^2].
    """
    if spans is None:
        spans = _spans(x, shape.knots, shape.fold)
    span, vals, span_cols = spans
    # Pixels no basis function reaches add exact zeros: left out.
    on = (span_cols >= 0).any(axis=1)[span]
    span = span[on]
    # (As 4 contiguous rows, each built as a row: the same numbers.)
    vals = [np.where(np.ascontiguousarray(span_cols[:, a]).take(span) >= 0, vals[:, a][on], 0.0)
            for a in range(4)]
    aw, J, seg = aw[on], [j[on] for j in J], seg[on]
    nseg, kk, nspan = len(ok), len(shape.coef), len(span_cols)
    # Sums per (segment, knot span), one grouping for all 16, then put in each span's
    # column (as fit_shape: the 4 functions on a span are fixed; the sums' order differs
    # in the last bit from sums per column).
    # (Not a matrix product for the scatter: OpenBLAS's threads cost more than the work;
    # not np.add.at, slow on 2-D: the spans of each column in rounds without repeats.)
    sums = GroupSums(seg * nspan + span, nseg * nspan, eager=True)
    rounds = [_unrepeated(span_cols[:, a]) for a in range(4)]
    G = np.zeros((nseg, len(J), kk))
    for i in range(len(J)):
        awj = aw * J[i]
        for a in range(4):
            part = sums(awj * vals[a]).reshape(nseg, nspan)
            for spans_r, cols_r in rounds[a]:
                G[:, i, cols_r] += part[:, spans_r]
    c0 = np.where(ok[:, None], cov[:, 0, :], 0.0)
    S = -np.einsum("ni,nij->nj", c0, G)
    return S @ shape.coef, S @ shape.cov @ S.T


def _unrepeated(cols: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The knot spans with a column (``cols`` >= 0) as rounds of (spans, their columns), no
    column twice within a round (a fancy-indexed += adds a repeated index once)."""
    todo = np.flatnonzero(cols >= 0)
    out = []
    while todo.size:
        _, first = np.unique(cols[todo], return_index=True)
        out.append((todo[first], cols[todo[first]]))
        todo = np.delete(todo, first)
    return out


def profile_angle_u(t: np.ndarray, sigma: np.ndarray, shift: np.ndarray,
                    shift_cov: np.ndarray) -> float:
    """The Type B term ``groove_profile`` [rad]: the tilt the departure's shifts give the line.

    The straight line's slope is linear in the centres: g = w (t - t_w) / sum w (t - t_w)^2
    with w = 1/sigma^2 and t_w their weighted mean. The shifts tilt it by b = g . shift, known
    to sigma_b^2 = g' C g; both are carried, sqrt(b^2 + sigma_b^2) (the bias is not removed:
    fitted back into the centres it moved a quantisation-dominated groove and a line among
    numerals the wrong way, while as a term it only widens u where the residuals hold it).

    Parameters
    ----------
    t : ndarray
        The used centres' positions along the line [px].
    sigma : ndarray
        Their u across it [px].
    shift : ndarray
        Their shift by the departure [px] (:func:`shape_shift`).
    shift_cov : ndarray
        Its covariance [px^2].

    Returns
    -------
    float
        The term [rad].
    """
    w = 1.0 / sigma ** 2
    dt = t - np.sum(w * t) / np.sum(w)
    g = w * dt / np.sum(w * dt ** 2)
    return float(np.hypot(g @ shift, np.sqrt(max(float(g @ shift_cov @ g), 0.0))))
