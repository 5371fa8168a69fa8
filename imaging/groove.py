"""The groove model: the pixel-integrated profile of a mark, its tabulation, its fit's result.

Model of a pixel near the mark (pixel-area integrated by 3x3 Gauss–Legendre quadrature):

    mu(x, y) = b + g_e . e + A . P(e - delta; w, s),
    P(e; w, s) = 1/2 [erf((e + w/2) / (sqrt2 s)) - erf((e - w/2) / (sqrt2 s))]

a groove of width w seen through a Gaussian blur s, e the signed distance of the point from
the reference line [px]; the pixels' variance v0 + v1 mu (shot + read noise). The band fit
(:mod:`imaging.profile`) gives a :class:`ProfileFit`; the centres along the mark
(:mod:`imaging.centres`) use the tabulated profile.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import erf

from axisbase.interp import interp_uniform, uniform_slopes
from imaging.detect import line_frame
from imaging.median import median, median_inplace

# Gauss–Legendre nodes/weights on a pixel [-1/2, 1/2]: 2 points (exact to cubics) for the
# shape fit, 3 points (exact to quintics) for the centres, where sub-pixel bias matters.
_GAUSS = {2: (np.array([-0.5, 0.5]) / np.sqrt(3), np.array([0.5, 0.5])),
          3: (np.array([-np.sqrt(0.6) / 2, 0.0, np.sqrt(0.6) / 2]), np.array([5.0, 8.0, 5.0]) / 18)}
_SQ2 = np.sqrt(2.0)
_SQ2PI = np.sqrt(2 * np.pi)


def _quad_offsets(angle: float, order: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Offsets along the normal of the order x order quadrature points in a pixel, weights."""
    _, n = line_frame(angle)
    g, gw = _GAUSS[order]
    ox, oy = np.meshgrid(g, g)
    return (ox * n[0] + oy * n[1]).ravel(), np.outer(gw, gw).ravel()


def profile_and_derivs(e: np.ndarray, w: float, s: float, shifts: np.ndarray,
                       weights: np.ndarray, shape_derivs: bool = True) -> tuple[np.ndarray, ...]:
    """Pixel-integrated profile P and its derivatives dP/de (and dP/dw, dP/ds)."""
    p, derivs = profile_lazy(e, w, s, shifts, weights)
    return (p, *derivs(shape_derivs))


def profile_lazy(e: np.ndarray, w: float, s: float, shifts: np.ndarray, weights: np.ndarray
                 ) -> tuple[np.ndarray, Callable[[bool], tuple[np.ndarray, ...]]]:
    """:func:`profile_and_derivs` in two steps: P now, and a function that gives dP/de (and
    dP/dw, dP/ds when asked) from the same intermediate arrays, the same bits. The band fit
    needs the derivatives only at a step it accepts (a rejected Levenberg–Marquardt step
    spent ~45 % of its evaluation on the Gaussians and derivatives it never used)."""
    z = e[..., None] + shifts
    hp, hm = (z + w / 2), (z - w / 2)
    p = 0.5 * (erf(hp / (_SQ2 * s)) - erf(hm / (_SQ2 * s)))

    def derivs(shape_derivs: bool = True) -> tuple[np.ndarray, ...]:
        gp, gm = np.exp(-0.5 * (hp / s) ** 2), np.exp(-0.5 * (hm / s) ** 2)
        de = (gp - gm) / (_SQ2PI * s)
        if not shape_derivs:
            return (de @ weights,)
        dw = (gp + gm) / (2 * _SQ2PI * s)
        ds = -(hp * gp - hm * gm) / (_SQ2PI * s * s)
        return de @ weights, dw @ weights, ds @ weights

    return p @ weights, derivs


def _blur_derivative(e: np.ndarray, w: float, s: float, shifts: np.ndarray,
                     weights: np.ndarray) -> np.ndarray:
    """dP/ds of :func:`profile_and_derivs` alone, by the same expressions (the same bits),
    without the profile's erf and the other derivatives it does not need."""
    z = e[..., None] + shifts
    hp, hm = (z + w / 2), (z - w / 2)
    gp, gm = np.exp(-0.5 * (hp / s) ** 2), np.exp(-0.5 * (hm / s) ** 2)
    return (-(hp * gp - hm * gm) / (_SQ2PI * s * s)) @ weights


class ProfileTable:
    """The pixel-integrated profile and its slope tabulated on a fine grid of e.

    The centres stage evaluates the same (w, s, angle) profile millions of times; tabulating
    it once (3x3 quadrature, step ``step`` px) and interpolating linearly costs one cell
    look-up per pixel instead of 9 erf + 18 exp. The interpolation error is below
    step^2/8 |P''| ~ 1e-6 of the contrast.
    """

    def __init__(self, w: float, s: float, angle: float, reach: float, step: float = 0.004):
        self.grid = np.arange(-reach, reach + step, step)
        sh, wt = _quad_offsets(angle)
        self.p, self.pe = profile_and_derivs(self.grid, w, s, sh, wt, shape_derivs=False)
        # The tables' per-cell slopes once (the interpolation's, the same bits), not per look-up.
        self._slopes = uniform_slopes(self.grid, (self.p, self.pe))
        self._shape = (w, s, sh, wt)
        self._ps: tuple[np.ndarray, np.ndarray] | None = None

    def blur_slope(self, e: np.ndarray) -> np.ndarray:
        """dP/ds at ``e``: the profile's change per px of blur (tabulated on first use)."""
        if self._ps is None:
            w, s, sh, wt = self._shape
            ps = _blur_derivative(self.grid, w, s, sh, wt)
            self._ps = (ps, uniform_slopes(self.grid, (ps,))[0])
        return interp_uniform(e, self.grid, self._ps[:1], self._ps[1:])[0]

    def __call__(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return interp_uniform(e, self.grid, (self.p, self.pe), self._slopes)

    def profile(self, e: np.ndarray) -> np.ndarray:
        """The profile alone at ``e`` (the first of the call's pair, the same bits: each
        tabulated function is interpolated on its own), without its slope's pass."""
        return interp_uniform(e, self.grid, (self.p,), self._slopes[:1])[0]


TABLE_ANGLE_STEP = 1e-3
"""Angles a profile table is made for [rad]: the nearest multiple of this. The angle only
turns the pixel's quadrature points about the line (by < 0.4 px x half a step = 2e-4 px);
the profile changes by less than 1e-5 of the contrast, far below its noise, and a mark's
first and final centres passes (their lines a fraction of a milliradian apart) share one
table instead of building two (~1.5 ms each, 2-3 % of a 640 x 480 frame's time)."""


def _profile_table(w: float, s: float, angle: float, reach: float) -> ProfileTable:
    """:class:`ProfileTable` at the angle rounded to :data:`TABLE_ANGLE_STEP`, cached: a
    mark's centres passes and its extent share one."""
    return _table(w, s, float(np.round(angle / TABLE_ANGLE_STEP) * TABLE_ANGLE_STEP), reach)


@functools.lru_cache(maxsize=8)
def _table(w: float, s: float, angle: float, reach: float) -> ProfileTable:
    return ProfileTable(w, s, angle, reach)


@dataclass(frozen=True)
class ProfileFit:
    """Band fit of one mark. Lengths [px], angle [rad], levels [DN].

    Attributes
    ----------
    angle_rad : float
        Direction of the band's line [rad].
    offset_px : float
        Its signed distance from the image centre [px].
    width_px : float
        Groove width [px].
    blur_px : float
        PSF sigma [px].
    contrast_dn : float
        Groove depth [DN] (negative: dark).
    background_dn : float
        Surface level [DN].
    slope_across_dn_per_px : float
        Background slope across the mark [DN/px].
    noise_var : tuple of float
        (v0, v1): pixel noise variance = v0 + v1 x level [DN^2, DN].
    t_start_px, t_end_px : float
        Extent along the line [px].
    full_scale_dn : float
        The image's full scale [DN].
    """

    angle_rad: float
    offset_px: float
    width_px: float
    blur_px: float
    contrast_dn: float
    background_dn: float
    slope_across_dn_per_px: float
    noise_var: tuple[float, float]
    t_start_px: float
    t_end_px: float
    full_scale_dn: float = 65535.0

    def with_line(self, angle_rad: float, offset_px: float) -> ProfileFit:
        """The same stretch of mark about a refined line (angle [rad], offset [px]).

        The extent along the line is carried over through its end points: when the refined
        angle wraps across +-90 deg the direction u flips and t runs the other way (keeping the
        old t range would sample a stretch of image beside the mark, or none at all).
        """
        return replace(self, angle_rad=angle_rad, offset_px=offset_px,
                       **dict(zip(("t_start_px", "t_end_px"),
                                  _carry_extent(self.angle_rad, self.offset_px,
                                                (self.t_start_px, self.t_end_px), angle_rad),
                                  strict=True)))


def _carry_extent(angle_rad: float, offset_px: float, extent: tuple[float, float],
                  new_angle_rad: float) -> tuple[float, float]:
    """Extent (t0, t1) [px] of a stretch of line re-expressed along a nearby new direction."""
    u, n = line_frame(angle_rad)
    u2, _ = line_frame(new_angle_rad)
    t = sorted(float((offset_px * n + tk * u) @ u2) for tk in extent)
    return t[0], t[1]


def centres_half(pf: ProfileFit) -> float:
    """Half-width of the band :func:`sample_centres` fits a groove's centres on [px]."""
    return float(np.clip(pf.width_px / 2 + 4 * pf.blur_px + 3, 6, 40))


def _noise_model(mu: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """Variance = v0 + v1 * mu from binned medians of squared residuals (robust to dust)."""
    qs = np.quantile(mu, np.linspace(0, 1, NOISE_BINS + 1))
    mids, meds = [], []
    for sel in _bins(mu, qs):
        if sel.size > NOISE_BIN_MIN:
            mids.append(mu[sel].mean())
            meds.append(median_inplace(r[sel] ** 2) / CHI2_1_MEDIAN)
    return _noise_line(np.array(mids), np.array(meds), r)


NOISE_BINS = 8
"""Bins of the model's level (at its octiles) the noise model reads the residuals in."""
NOISE_BIN_MIN = 20
"""Fewest pixels (beyond) a bin needs to count."""
CHI2_1_MEDIAN = 0.4549
"""The median of chi-square with 1 degree of freedom: a median of squared residuals over
this is their variance."""


def _noise_line(mids: np.ndarray, meds: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """The noise model (v0 [DN^2], v1 [DN]) through the bins' mean levels ``mids`` [DN] and
    variances ``meds`` [DN^2] (:func:`_noise_model`); a constant, from all the residuals
    ``r`` [DN], when fewer than 3 bins or a line with a negative slope or variance."""
    if len(mids) >= 3 and np.ptp(mids) > 0:
        v1, v0 = np.polyfit(mids, meds, 1)
        if v1 >= 0 and v0 + v1 * mids.min() > 0:
            return float(v0), float(v1)
    return float(median_inplace(r**2) / CHI2_1_MEDIAN), 0.0


def _bins(mu: np.ndarray, qs: np.ndarray) -> list[np.ndarray]:
    """Indices of ``mu`` in each closed bin [qs[k], qs[k+1]], in their order in ``mu`` (so
    a bin's mean and median are those of ``mu[(mu >= lo) & (mu <= hi)]`` to the bit).

    One label per value and one stable sort of the labels (a radix sort of small integers)
    instead of two comparisons and a boolean gather per bin: 2.7 ms, not 4.4, on a 5 MP
    mark's 48k band pixels. A value equal to an inner edge belongs to both bins it closes,
    and NaN to none: then (rare for a continuous model) the bins are taken by comparison."""
    if not np.isfinite(qs).all() or np.isin(mu, qs[1:-1]).any():
        return [np.flatnonzero((mu >= lo) & (mu <= hi))
                for lo, hi in zip(qs[:-1], qs[1:], strict=True)]
    # The bin of (qs[k], qs[k+1]] is the number of inner edges below the value (the minimum,
    # qs[0], goes with bin 0): 7 comparisons, ~10x faster than a search per value.
    lab = np.zeros(mu.size, np.uint8)
    for q in qs[1:-1]:
        lab += mu > q
    order = np.argsort(lab, kind="stable")
    ends = np.searchsorted(lab[order], np.arange(qs.size), side="left")
    return [order[a:b] for a, b in zip(ends[:-1], ends[1:], strict=True)]


def noise_models(mu: np.ndarray, rs: np.ndarray, fits: np.ndarray, seg: np.ndarray
                 ) -> tuple:
    """The pixels' noise model (v0 [DN^2], v1 [DN]) from each image's model levels ``mu``
    [DN] and scaled residuals ``rs`` [DN] (pixels[, images]) over the segments (``seg``:
    each pixel's) that ``fits`` (segments[, images]) the groove (all of them when none
    does), as :func:`imaging.centres.sample_centres` reads it: floats for one image, arrays
    for several, each image's the same to the bit as :func:`_noise_model`'s on its own.

    Several at once: the images whose same segments fit are binned together
    (:func:`_binned_noise_models`)."""
    if mu.ndim == 1:
        return _noise_model(mu[fits[seg]], rs[fits[seg]]) if fits.any() else (
            _noise_model(mu, rs))
    out = np.empty((mu.shape[1], 2))
    alike: dict[bytes, list[int]] = {}
    for i in range(mu.shape[1]):
        alike.setdefault(fits[:, i].tobytes(), []).append(i)
    for cols in alike.values():
        f = fits[:, cols[0]]
        px = f[seg] if f.any() else np.ones(seg.shape, bool)
        out[cols] = _binned_noise_models(mu[px][:, cols], rs[px][:, cols])
    return out[:, 0], out[:, 1]


def _binned_noise_models(mu: np.ndarray, rs: np.ndarray) -> np.ndarray:
    """:func:`_noise_model` of each column of ``mu`` and ``rs`` (pixels,
    images), the same to the bit, as rows (v0, v1): the columns with no level on a bin's
    edge (:func:`_bins`) and nothing but finite numbers (the usual case)
    binned together (their octiles in one call, the bins in one stable sort of (image, bin)
    labels, each bin's mean and median on its pixels in their order, as alone); the others
    one by one."""
    out = np.empty((mu.shape[1], 2))
    fine = np.isfinite(mu).all(axis=0) & np.isfinite(rs).all(axis=0)
    qs = np.quantile(mu[:, fine], np.linspace(0, 1, NOISE_BINS + 1), axis=0)
    edges = qs[1:-1]  # (inner edges, images)
    on_edge = np.zeros(edges.shape[1], bool)
    for q in edges:
        on_edge |= (mu[:, fine] == q).any(axis=0)
    together = np.flatnonzero(fine)[~on_edge]
    for i in np.setdiff1d(np.arange(mu.shape[1]), together):
        out[i] = _noise_model(mu[:, i], rs[:, i])
    if not together.size:
        return out
    M, R = mu[:, together].T, rs[:, together].T  # (images, pixels)
    lab = np.zeros(M.shape, np.uint16)
    for q in edges[:, ~on_edge]:
        lab += M > q[:, None]
    lab += (NOISE_BINS * np.arange(together.size, dtype=np.uint16))[:, None]
    order = np.argsort(lab.ravel(), kind="stable")
    Mo, R2 = M.ravel()[order], R.ravel()[order] ** 2
    ends = np.concatenate([[0], np.cumsum(np.bincount(lab.ravel(),
                                                      minlength=NOISE_BINS * together.size))])
    for j, i in enumerate(together):
        mids, meds = [], []
        for b in range(j * NOISE_BINS, (j + 1) * NOISE_BINS):
            lo, hi = ends[b], ends[b + 1]
            if hi - lo > NOISE_BIN_MIN:
                mids.append(np.add.reduce(Mo[lo:hi]) / (hi - lo))  # (np.mean's sum)
                meds.append(median(R2[lo:hi]) / CHI2_1_MEDIAN)
        out[i] = _noise_line(np.array(mids), np.array(meds), R[j])
    return out


def variance_floor(var: np.ndarray, mu: np.ndarray, v0, v1):
    """The floor on the pixels' variance ``var`` = v0 + v1 ``mu`` [DN^2]: a quarter of the
    variance at the median level, at least 1e-9 (per image: ``var``, ``mu`` (pixels,
    images), ``v0``, ``v1`` (images,)).

    The median (~0.5 ms at 5 MP's 40k band pixels, every Gauss–Newton step) only when the
    floor can bite: it lies between the variances at the lowest and the highest level (the
    variance is linear in the level, and rounding keeps it monotone), so when the least
    variance is at least a quarter of the largest and above 1e-9 no pixel reaches it, and
    any value at or below the least gives the same weights. NaN falls through to the median.
    """
    lo, hi = var.min(axis=0), var.max(axis=0)
    hard = ~((lo >= 0.25 * hi) & (lo >= 1e-9))
    if not hard.any():
        return lo
    if var.ndim == 1:
        return max(0.25 * (v0 + v1 * float(median(mu))), 1e-9)
    out = lo.copy()
    v0, v1 = np.broadcast_to(v0, lo.shape), np.broadcast_to(v1, lo.shape)
    for i in np.flatnonzero(hard):
        out[i] = variance_floor(var[:, i], mu[:, i], v0[i], v1[i])
    return out
