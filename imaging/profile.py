"""Sub-pixel measurement of a mark's centre all along its length.

Model of a pixel near the mark (pixel-area integrated by 3x3 Gauss–Legendre quadrature):

    mu(x, y) = b + g_e . e + A . P(e - delta; w, s),
    P(e; w, s) = 1/2 [erf((e + w/2) / (sqrt2 s)) - erf((e - w/2) / (sqrt2 s))]

a groove of width w seen through a Gaussian blur s, e the signed distance of the point from
the reference line [px]. First one fit over the whole band gives the shape (w, s), the
contrast and a refined line; then the mark is cut into short segments along its length and
each segment's centre offset delta_k (with its own contrast A_k, level b_k and background
slope across the mark g_k) is fitted by Gauss–Newton with per-pixel weights from a shot +
read noise model estimated from the data.
The per-segment standard uncertainties come from each segment's Fisher information, so the
line fit downstream propagates a real uncertainty.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import median_filter
from scipy.special import erf

from imaging.detect import MarkCandidate, line_frame, wrap_angle
from imaging.errors import ImageInputError
from imaging.ring import ring_slope
from imaging.texture import TextureModel, texture_model

# Gauss–Legendre nodes/weights on a pixel [-1/2, 1/2]: 2 points (exact to cubics) for the
# shape fit, 3 points (exact to quintics) for the centres, where sub-pixel bias matters.
_GAUSS = {2: (np.array([-0.5, 0.5]) / np.sqrt(3), np.array([0.5, 0.5])),
          3: (np.array([-np.sqrt(0.6) / 2, 0.0, np.sqrt(0.6) / 2]), np.array([5.0, 8.0, 5.0]) / 18)}
_SQ2 = np.sqrt(2.0)
_SQ2PI = np.sqrt(2 * np.pi)
_SHAPE_PIXELS = 2500
EXTRA_STEPS = 4
"""Gauss–Newton steps a segment's centre may take beyond the usual ones while it still moves
(a lens bows a long off-centre mark by several px: with 2 steps of at most 1 px its ends
stopped 0.2-0.35 px short, and a calibrated lens was reported as differing from itself)."""


def _quad_offsets(angle: float, order: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Offsets along the normal of the order x order quadrature points in a pixel, weights."""
    _, n = line_frame(angle)
    g, gw = _GAUSS[order]
    ox, oy = np.meshgrid(g, g)
    return (ox * n[0] + oy * n[1]).ravel(), np.outer(gw, gw).ravel()


def profile_and_derivs(e: np.ndarray, w: float, s: float, shifts: np.ndarray,
                       weights: np.ndarray, shape_derivs: bool = True) -> tuple[np.ndarray, ...]:
    """Pixel-integrated profile P and its derivatives dP/de (and dP/dw, dP/ds)."""
    z = e[..., None] + shifts
    hp, hm = (z + w / 2), (z - w / 2)
    gp, gm = np.exp(-0.5 * (hp / s) ** 2), np.exp(-0.5 * (hm / s) ** 2)
    p = 0.5 * (erf(hp / (_SQ2 * s)) - erf(hm / (_SQ2 * s)))
    de = (gp - gm) / (_SQ2PI * s)
    if not shape_derivs:
        return p @ weights, de @ weights
    dw = (gp + gm) / (2 * _SQ2PI * s)
    ds = -(hp * gp - hm * gm) / (_SQ2PI * s * s)
    return p @ weights, de @ weights, dw @ weights, ds @ weights


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
        self._shape = (w, s, sh, wt)
        self._ps: np.ndarray | None = None

    def blur_slope(self, e: np.ndarray) -> np.ndarray:
        """dP/ds at ``e``: the profile's change per px of blur (tabulated on first use)."""
        if self._ps is None:
            w, s, sh, wt = self._shape
            self._ps = profile_and_derivs(self.grid, w, s, sh, wt)[3]
        return np.interp(e, self.grid, self._ps, left=0.0, right=0.0)

    def __call__(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _interp_uniform(e, self.grid, (self.p, self.pe))


@functools.lru_cache(maxsize=8)
def _profile_table(w: float, s: float, angle: float, reach: float) -> ProfileTable:
    """:class:`ProfileTable`, cached: a mark's second centres pass and its extent share one."""
    return ProfileTable(w, s, angle, reach)


def _interp_uniform(e: np.ndarray, grid: np.ndarray, fs: Sequence[np.ndarray]
                    ) -> tuple[np.ndarray, ...]:
    """np.interp(e, grid, f, left=0, right=0) for each f of ``fs``, the same to the last bit,
    on a uniformly spaced ``grid`` (np.arange).

    Hand-written: np.interp has no uniform-grid mode, and its binary search for the cell cost
    ~5x this on a mark's ~40k unsorted pixels. The cell is found by division, corrected by
    one where rounding put e across a grid point, and the value is np.interp's expression
    (per-cell slope) with its special cases: the last grid point, outside the grid, NaN.
    """
    last = grid.size - 1
    step = (grid[last] - grid[0]) / last
    out = []
    # NaN (and +-inf, set to 0 below) pass through as through np.interp, unwarned.
    with np.errstate(invalid="ignore"):
        j = np.clip(((e - grid[0]) / step).astype(np.intp), 0, last - 1)
        j -= (grid[j] > e) & (j > 0)
        j += (grid[j + 1] <= e) & (j < last - 1)
        d = e - grid[j]  # on a grid point d = 0 and the value is f[j] exactly, as np.interp's
        at_end = e == grid[last]
        off = (e < grid[0]) | (e > grid[last])
        dx = np.diff(grid)
        for f in fs:
            v = (np.diff(f) / dx)[j] * d + f[j]
            v[at_end] = f[last]
            v[off] = 0.0
            out.append(v)
    return tuple(out)


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


@dataclass(frozen=True)
class Centres:
    """Per-segment centres of a mark (image coordinates relative to the image centre, px).

    ``xy``: (N, 2) centre points; ``sigma``: (N,) standard uncertainty of each across the
    line [px]; ``t``: position along the reference line [px]; ``contrast``: A_k [DN];
    ``cross_slope``: local background slope across the mark divided by the contrast [1/px]
    (regressor for illumination-gradient bias); ``chi2_red``: each segment's pixel chi2/dof;
    ``ok``: segments usable for the line fit; ``texture``: how the background's texture
    correlates the centres' errors along the mark and with ``cross_slope`` (None: it does
    not; see :mod:`imaging.texture`); ``blur_dev``, ``blur_dev_u``: each segment's blur
    minus the band's [px] and its standard uncertainty, linearised at the solution (one
    Gauss–Newton step on the blur with the segment's other parameters free; None unless
    asked for: :mod:`imaging.defocus` reads a defocus gradient from them);
    ``offsets_cov``: the covariance [px^2] of the centres from removed stripes' offsets
    (None: none removed).

    Attributes
    ----------
    xy : ndarray
        (N, 2) centres [px].
    sigma : ndarray
        (N,) their u across the line [px].
    t : ndarray
        (N,) positions along the line [px].
    contrast : ndarray
        (N,) contrast A_k [DN].
    cross_slope : ndarray
        (N,) background slope / contrast [1/px].
    chi2_red : ndarray
        (N,) pixel chi2/dof per segment.
    ok : ndarray
        (N,) usable segments (bool).
    texture : TextureModel or None
        The texture's correlation model.
    blur_dev, blur_dev_u : ndarray or None
        Per-segment blur minus the band's and its u [px].
    offsets_cov : ndarray or None
        Covariance from removed stripes' offsets [px^2].
    """

    xy: np.ndarray
    sigma: np.ndarray
    t: np.ndarray
    contrast: np.ndarray
    cross_slope: np.ndarray
    chi2_red: np.ndarray
    ok: np.ndarray
    texture: TextureModel | None = None
    blur_dev: np.ndarray | None = None
    blur_dev_u: np.ndarray | None = None
    offsets_cov: np.ndarray | None = None


def _band(image: np.ndarray, angle: float, offset: float, t0: float, t1: float,
          half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixels within ``half`` of the line and between t0 and t1: (values, e, t, flat idx).

    Rasterised along the line (one short run of pixels per column, or per row for steep
    lines), so the cost follows the band's area, not its bounding box's.
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
    if hi < lo:
        return (np.empty(0),) * 4
    k = np.arange(lo, hi + 1, dtype=float)
    # Where the line crosses walk coordinate k, and how far the band reaches across it.
    cross = c[other] + (offset - (k - c[ax]) * n[ax]) / n[other]
    reach = half / abs(n[other])
    m = int(np.ceil(2 * reach)) + 2
    start = np.floor(cross - reach).astype(int)
    oth = start[:, None] + np.arange(m)[None, :]
    walk = np.broadcast_to(k.astype(int)[:, None], oth.shape)
    oth, walk = oth.ravel(), walk.ravel()
    inside = (oth >= 0) & (oth < size_other)
    oth, walk = oth[inside], walk[inside]
    ys, xs = (walk, oth) if steep else (oth, walk)
    px, py = xs - c[0], ys - c[1]
    e = px * n[0] + py * n[1] - offset
    t = px * u[0] + py * u[1]
    sel = (np.abs(e) <= half) & (t >= t0) & (t <= t1)
    idx = ys[sel] * w + xs[sel]
    # By flat index: numpy's 2-D fancy indexing costs ~2x (this runs ~6 times per mark).
    vals = image.ravel()[idx] if image.flags.c_contiguous else image[ys[sel], xs[sel]]
    return vals, e[sel], t[sel], idx


def centres_half(pf: ProfileFit) -> float:
    """Half-width of the band :func:`sample_centres` fits a groove's centres on [px]."""
    return float(np.clip(pf.width_px / 2 + 4 * pf.blur_px + 3, 6, 40))


def band_pixels(image: np.ndarray, pf: ProfileFit, half: float, reach_px: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance e from the fitted line [px] and flat index of the pixels within
    ``half`` of it, ``reach_px`` beyond the measured stretch, in ``image``."""
    _, e, _, idx = _band(image, pf.angle_rad, pf.offset_px,
                         pf.t_start_px - reach_px, pf.t_end_px + reach_px, half)
    return e, idx


def band_indices(image: np.ndarray, cand: MarkCandidate, reach_px: float = 20.0) -> np.ndarray:
    """Flat indices of the pixels a candidate's measurement can use: its band (as wide as
    :func:`fit_profile`'s, plus its illumination ring) and ``reach_px`` beyond its ends."""
    half = float(np.clip(2.5 * cand.thickness_px + 8, 10, 40)) + 6.0
    return _band(image, cand.angle_rad, cand.offset_px, cand.t_start_px - reach_px,
                 cand.t_end_px + reach_px, half)[3]


def fit_profile(image: np.ndarray, cand: MarkCandidate, where: str = "image",
                full_scale: float = 65535.0) -> ProfileFit:
    """Fit the groove model over the whole band of a detected mark (robust to dust)."""
    half = float(np.clip(2.5 * cand.thickness_px + 8, 10, 40))
    # Leave out the mark's blurred ends (the candidate's extent is already inside them),
    # but not so much that a 100 px mark loses most of its length.
    trim = min(half, max(4.0, 0.05 * cand.length_px))
    t0, t1 = cand.t_start_px + trim, cand.t_end_px - trim
    if t1 - t0 < 20:
        raise ImageInputError(f"{where}: mark at offset {cand.offset_px:.0f} px is too short "
                              f"({cand.length_px:.0f} px) to measure")
    vals, e, t, _ = _band(image, cand.angle_rad, cand.offset_px, t0, t1, half)
    if vals.size < 100:
        raise ImageInputError(f"{where}: the mark runs off the image")
    # The shape needs only a sample of the band: whole 8-px blocks spread along the mark
    # (the line itself is refined from every pixel in sample_centres).
    stride = max(1, int(np.ceil(vals.size / _SHAPE_PIXELS)))
    if stride > 1:
        # Blocks counted from the middle, so the same from either end (see segment_index).
        keep = (np.abs(np.round((t - 0.5 * (t0 + t1)) / 8)).astype(int) % stride) == 0
        vals, e, t = vals[keep], e[keep], t[keep]
    # Clipped pixels (0 or full scale) say only "beyond the range": left out of the fit. The
    # mark itself must not be clipped; clipped surroundings (a dark padded border, a
    # saturated patch beside it) only cost the pixels they cover.
    clipped = (vals >= full_scale) | (vals <= 0)
    core = np.abs(e) <= max(2.0, cand.thickness_px / 2 + 1.5)
    # Along the mark, 8 px at a time: a groove clipped shows in most stretches, an opaque
    # speck over its end in a few (its pixels only are lost; a ruled scale's line was
    # refused for 3 % of its pixels under a black particle).
    step = np.floor((t[core] - t0) / 8).astype(int)
    per = np.bincount(step, clipped[core]) / np.maximum(np.bincount(step), 1)
    if np.mean(clipped[core]) > 0.02 and np.median(per[np.bincount(step) > 0]) > 0.02:
        raise ImageInputError(
            f"{where}: mark near ({cand.offset_px:.0f} px offset) is saturated or clipped "
            f"({100 * np.mean(clipped[core]):.0f} % of its pixels at 0 or {full_scale:.0f}, "
            f"the {int(np.log2(full_scale + 1))}-bit full scale)")
    vals, e, t = vals[~clipped], e[~clipped], t[~clipped]
    if vals.size < 100:
        raise ImageInputError(f"{where}: mark at offset {cand.offset_px:.0f} px: too few "
                              "unclipped pixels around it")
    tm = 0.5 * (t0 + t1)
    inner = np.abs(e) < 2
    bg = float(np.median(vals[~inner])) if np.any(~inner) else float(np.median(vals))
    amp0 = float(np.median(vals[inner]) - bg) if np.any(inner) else 0.0
    w0 = max(cand.thickness_px, _half_depth_width(e, vals, bg, amp0), 1.5)
    x0 = np.array([0.0, 0.0, amp0, bg, 0.0, 0.0, w0, 1.0])
    a_ref = cand.angle_rad

    def model(p, want_jac=False):
        da, dd, amp, b, g_e, g_t, w, s = p
        sh, wt = _quad_offsets(a_ref + da, order=2)
        # Small rotation about the band's middle, then shift: linearised line geometry.
        ee = e - dd - da * (t - tm)
        pp, pe, pw, ps = profile_and_derivs(ee, w, s, sh, wt)
        mu = b + g_e * ee + g_t * (t - tm) / 100 + amp * pp
        if not want_jac:
            return mu
        J = np.column_stack([
            -(amp * pe + g_e) * (t - tm), -(amp * pe + g_e), pp, np.ones_like(ee), ee,
            (t - tm) / 100, amp * pw, amp * ps])
        return mu, J

    scale = max(abs(amp0) / 10, 1.0)
    lo = [-0.05, -half / 2, -np.inf, -np.inf, -np.inf, -np.inf, 0.05, 0.3]
    hi = [0.05, half / 2, np.inf, np.inf, np.inf, np.inf, 4 * half, half]
    x = _irls_lm(lambda p: model(p, True), vals, x0, np.array(lo), np.array(hi), scale)
    da, dd, amp, b, g_e, _, w, s = x
    mu = model(x)
    var = _noise_model(mu, vals - mu)
    ang = wrap_angle(a_ref + da)
    # Re-express the shifted/rotated line in the image-centre convention.
    u, n = line_frame(a_ref)
    p_mid = (cand.offset_px + dd) * n + tm * u
    _, n2 = line_frame(ang)
    off = float(p_mid @ n2)
    t0, t1 = _carry_extent(a_ref, cand.offset_px, (t0, t1), ang)
    return ProfileFit(ang, off, float(w), float(s), float(amp), float(b), float(g_e), var,
                      t0, t1, float(full_scale))


def _half_depth_width(e: np.ndarray, vals: np.ndarray, bg: float, amp: float) -> float:
    """Width [px] over which the median profile across the mark is beyond half its depth.

    The start for the band fit's groove width. The detector's thickness comes from a
    block-averaged copy and can be half a wide flat-bottomed groove's width; started there,
    the fit settles on a narrow, over-blurred groove (w 3.2, s 3.1 for a 7.8 px box seen
    through s 1.9), whose gentle flanks carry less information than the real ones: every
    centre's stated sigma was then ~2x its scatter (chi2/dof 0.23) and the angle's u absurd.
    """
    if amp == 0:
        return 0.0
    bins = np.round(e * 2).astype(int)
    idx = bins - bins.min()
    cnt = np.bincount(idx)
    # Each bin's median from one sort by (bin, value): np.median's values (the middle one, or
    # the mean of the middle two), without a call per bin (~40 of them).
    v = vals[np.lexsort((vals, idx))]
    start = np.cumsum(cnt) - cnt
    mid = start + cnt // 2
    even = cnt % 2 == 0
    med = np.where(even, (v[np.maximum(mid - 1, 0)] + v[np.minimum(mid, v.size - 1)]) / 2,
                   v[np.minimum(mid, v.size - 1)])
    med[(cnt < 5) | (np.bincount(idx, np.isnan(vals), cnt.size) > 0)] = np.nan
    deep = (med - bg) / amp > 0.5
    return 0.5 * float(np.count_nonzero(deep))


def _irls_lm(fun, y: np.ndarray, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             scale: float, iterations: int = 25) -> np.ndarray:
    """Levenberg–Marquardt on Huber-reweighted residuals (IRLS), parameters kept in [lo, hi].

    The band fit has 8 parameters and a few thousand pixels; a hand loop avoids the
    per-iteration overhead of scipy's trust-region solver, which dominated the time here.
    Dust pixels get Huber weights (threshold ``scale``) so they cannot pull the shape.
    """
    x = x0.astype(float).copy()
    lam = 1e-3
    mu, J = fun(x)
    r = y - mu

    def cost(res):
        a = np.abs(res)
        return float(np.sum(np.where(a <= scale, 0.5 * a * a, scale * (a - 0.5 * scale))))

    c = cost(r)
    for _ in range(iterations):
        w = np.minimum(1.0, scale / np.maximum(np.abs(r), 1e-300))
        A = J.T @ (J * w[:, None])
        g = J.T @ (w * r)
        d = np.sqrt(np.maximum(np.diag(A), 1e-300))
        while True:
            step = np.linalg.solve(A + lam * np.diag(d * d), g)
            xn = np.clip(x + step, lo, hi)
            mun, Jn = fun(xn)
            rn = y - mun
            cn = cost(rn)
            if cn <= c:
                lam = max(lam / 3, 1e-9)
                break
            lam *= 4
            if lam > 1e8:
                return x
        done = c - cn < 1e-10 * c
        x, mu, J, r, c = xn, mun, Jn, rn, cn
        if done:
            break
    return x


def _noise_model(mu: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """Variance = v0 + v1 * mu from binned medians of squared residuals (robust to dust)."""
    qs = np.quantile(mu, np.linspace(0, 1, 9))
    mids, meds = [], []
    for lo, hi in zip(qs[:-1], qs[1:], strict=True):
        sel = (mu >= lo) & (mu <= hi)
        if sel.sum() > 20:
            mids.append(mu[sel].mean())
            meds.append(np.median(r[sel] ** 2) / 0.4549)
    mids, meds = np.array(mids), np.array(meds)
    if len(mids) >= 3 and np.ptp(mids) > 0:
        v1, v0 = np.polyfit(mids, meds, 1)
        if v1 >= 0 and v0 + v1 * mids.min() > 0:
            return float(v0), float(v1)
    return float(np.median(r**2) / 0.4549), 0.0


def segment_index(t: np.ndarray, pf: ProfileFit, segment_px: float, every: int = 1
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Segment of each pixel at ``t`` along the mark, and which pixels ``every`` keeps.

    The segments are laid out from the middle of the measured stretch, one centred on it,
    so that the grid is the same from either end: the same pixels rotated by 180 deg or
    mirrored (t runs the other way) fall in the same segments. (Counted from t_start, the
    two ends' part segments differed, and the angle by 0.1 u.) Indices run from 0 along t;
    with ``every`` > 1 only segments a multiple of ``every`` from the middle one are kept.
    """
    mid = 0.5 * (pf.t_start_px + pf.t_end_px)
    j = np.round((t - mid) / segment_px).astype(int)
    reach = int(np.round(0.5 * (pf.t_end_px - pf.t_start_px) / segment_px)) + 1
    keep = np.abs(j) % every == 0 if every > 1 else np.ones(t.shape, bool)
    return (j + reach) // every if every > 1 else j + reach, keep


def _ring(image: np.ndarray, pf: ProfileFit, half: float, segment_px: float, every: int,
          nseg: int, ring: float = 6.0) -> tuple[np.ndarray, ...]:
    """Pixels of a ring just outside the band the centres are fitted on (half < |e| <=
    half + ring): (rows, columns, e, segment), for the background slope across the mark.

    Outside the band on purpose: the slope fitted inside it shares its pixels' noise with
    the centre (both odd in e), and would correlate with the centre's error by chance.
    """
    _, e, t, idx = _band(image, pf.angle_rad, pf.offset_px, pf.t_start_px, pf.t_end_px,
                         half + ring)
    seg, keep = segment_index(t, pf, segment_px, every)
    sel = (np.abs(e) > half) & keep
    sel &= seg < nseg
    idx, e, seg = idx[sel], e[sel], seg[sel]
    return idx // image.shape[1], idx % image.shape[1], e, seg


def sample_centres(image: np.ndarray, pf: ProfileFit, segment_px: float = 4.0,
                   iterations: int = 2, every: int = 1, where: str = "image",
                   texture: bool = False, avoid_px: Sequence[float] = (),
                   guess: tuple[np.ndarray, np.ndarray] | None = None,
                   offsets_var: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
                   ) -> Centres:
    """Centre offset of the mark in consecutive segments along its length (vectorised GN).

    ``every`` > 1 keeps only every n-th segment (a quick pass that only sets a reference line).
    ``guess``: (t, offset) [px] of the groove from the reference line along it (an earlier
    pass's centres), the start of each segment's offset; Gauss–Newton runs ``iterations``
    steps of at most 1 px each, and on (up to :data:`EXTRA_STEPS` more) while a segment still
    moves, so a strongly bowed groove's ends are not left where the steps stopped.
    ``offsets_var``: variances [DN^2] of per-column and per-row offsets already subtracted
    from the image (removed stripes, :mod:`imaging.stripes`); their errors are shared by
    every segment on the same column (row), and ``Centres.offsets_cov`` carries them.
    ``texture``: also measure how the background's texture correlates the centres' errors
    (replicas of the band beside the mark, :mod:`imaging.texture`), with no replica within
    a band and ring's width of the other lines at signed distances ``avoid_px`` [px].
    """
    half = centres_half(pf)
    vals, e, t, idx = _band(image, pf.angle_rad, pf.offset_px, pf.t_start_px, pf.t_end_px,
                            half)
    unclipped = (vals < pf.full_scale_dn) & (vals > 0)  # see fit_profile
    vals, e, t, idx = vals[unclipped], e[unclipped], t[unclipped], idx[unclipped]
    if vals.size == 0:
        raise ImageInputError(f"{where}: mark at offset {pf.offset_px:.0f} px: its band lies "
                              "outside the image or is all clipped")
    seg, keep = segment_index(t, pf, segment_px, every)
    if not keep.all():
        vals, e, t, seg, idx = vals[keep], e[keep], t[keep], seg[keep], idx[keep]
    if vals.size == 0:
        raise ImageInputError(f"{where}: mark at offset {pf.offset_px:.0f} px: no pixels in "
                              "its segments")
    nseg = int(seg.max()) + 1
    table = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)
    v0, v1 = pf.noise_var
    delta = np.zeros(nseg)
    if guess is not None and len(guess[0]) >= 2:
        mid = 0.5 * (pf.t_start_px + pf.t_end_px)
        reach = int(np.round(0.5 * (pf.t_end_px - pf.t_start_px) / segment_px)) + 1
        t_nom = mid + (np.arange(nseg) * every - reach) * segment_px
        order = np.argsort(guess[0])
        delta = np.clip(np.interp(t_nom, guess[0][order], guess[1][order]), -half / 2, half / 2)
    moving = np.zeros(nseg, bool)
    amp = np.full(nseg, pf.contrast_dn)
    lev = np.full(nseg, pf.background_dn)
    # Each segment has its own background slope across the mark: surface texture and uneven
    # light tilt the background differently along the mark, and a slope left in the model
    # moves the fitted centre (a false "illumination gradient"). Costs little precision: the
    # slope is set by the pixels beside the groove, the centre by its flanks.
    slp = np.full(nseg, pf.slope_across_dn_per_px)
    k = 4

    def bc(x: np.ndarray) -> np.ndarray:
        return np.bincount(seg, x, minlength=nseg)

    for it in range(iterations + 1 + EXTRA_STEPS):
        ee = e - delta[seg]
        p, pe = table(ee)
        mu = lev[seg] + slp[seg] * ee + amp[seg] * p
        r = vals - mu
        if it == 1:
            # Noise model again, now from the segment model's residuals (local level and
            # contrast absorb illumination and texture that the band fit could not);
            # each segment spends k of its pixels' degrees of freedom.
            npx = bc(np.ones_like(e))
            v0, v1 = _noise_model(mu, r * np.sqrt(npx / np.maximum(npx - k, 1))[seg])
        # The linear noise model is fitted over the band's levels; below them (a segment's
        # model darker than any bin: a dust speck's fit) it can reach 0, and a weight of
        # 1e9 gave centres a sigma of ~0 (chi2 ~1e15 over a ruled scale's frame). No pixel
        # of a groove is quieter than a quarter of the band's typical variance.
        floor = max(0.25 * (v0 + v1 * float(np.median(mu))), 1e-9)
        wgt = 1.0 / np.maximum(v0 + v1 * mu, floor)
        J = (-(amp[seg] * pe + slp[seg]), p, np.ones_like(p), ee)[:k]
        N = np.empty((nseg, k, k))
        g = np.empty((nseg, k))
        for i in range(k):
            wj = wgt * J[i]  # once per column (the products are the same to the bit)
            g[:, i] = bc(wj * r)
            for j in range(i, k):
                N[:, i, j] = N[:, j, i] = bc(wj * J[j])
        ok = np.linalg.det(N) > 0
        if it >= iterations and not (moving & ok).any():
            break  # the last pass only refreshes weights and information at the solution
        if it == iterations + EXTRA_STEPS:
            break  # still moving: those segments are left out below
        step = np.zeros((nseg, k))
        step[ok] = np.linalg.solve(N[ok], g[ok][..., None])[..., 0]
        # A step of 0.1 px is ~5 sigma of a typical centre: such a segment has not arrived.
        moving = np.abs(step[:, 0]) > 0.1
        step[:, 0] = np.clip(step[:, 0], -1.0, 1.0)
        delta += step[:, 0]
        amp += step[:, 1]
        lev += step[:, 2]
        if k == 4:
            slp += step[:, 3]
    cov = np.full((nseg, k, k), np.inf)
    cov[ok] = np.linalg.inv(N[ok])
    ocov = None
    if any(v is not None for v in offsets_var):
        ocov = _offsets_cov(idx, image.shape[1], seg, nseg, wgt, J, cov, ok, offsets_var)
    blur_dev = blur_dev_u = None
    if texture:
        blur_dev, blur_dev_u = _blur_step(table.blur_slope(ee) * amp[seg], J, wgt, r, g, cov,
                                          ok, bc)
    # An ill-conditioned segment (det > 0 by rounding only) can invert to a negative variance.
    sigma = np.where(cov[:, 0, 0] > 0, np.sqrt(np.abs(cov[:, 0, 0])), np.inf)
    npx = bc(np.ones_like(e))
    chi2_red = bc(wgt * r * r) / np.maximum(npx - k, 1)
    info = wgt * (amp[seg] * pe) ** 2
    t_eff = bc(info * t) / np.maximum(bc(info), 1e-300)
    ring = _ring(image, pf, half, segment_px, every, nseg)
    slope = ring_slope(image[ring[0], ring[1]], ring[2], ring[3], nseg, pf.full_scale_dn)
    u, n = line_frame(pf.angle_rad)
    good = ok & (npx >= 6) & np.isfinite(sigma) & (np.abs(delta) < half / 2) & ~moving
    amp_safe = np.where(amp != 0, amp, 1.0)
    tex = None
    if texture:
        # Replicas just clear of the band and of its illumination ring, and further out:
        # 8 series (4 distances, both sides) make the autocovariance precise enough that
        # the loop's tests see white residuals (4 left ~10 % of textured marks flagged).
        shifts = tuple(m * (half + 4) for m in (2, 4, 6, 8))
        tex = texture_model(image, (idx // image.shape[1], idx % image.shape[1], seg), nseg,
                            wgt, J, cov, good, ring, amp_safe, n, shifts, (v0, v1),
                            pf.full_scale_dn, avoid_px, 2 * (half + 4))
    if tex is not None:
        # Control variate: the part of the centre's error that the ring's texture slope
        # predicts is taken out (what stays is independent of the regressor).
        delta = delta - tex.coupling_px2 * slope / amp_safe
    xy = (pf.offset_px + delta)[:, None] * n + t_eff[:, None] * u
    return Centres(xy=xy, sigma=sigma, t=t_eff, contrast=amp, cross_slope=slope / amp_safe,
                   chi2_red=chi2_red, ok=good, texture=tex, blur_dev=blur_dev,
                   blur_dev_u=blur_dev_u, offsets_cov=ocov)


def _offsets_cov(idx: np.ndarray, width: int, seg: np.ndarray, nseg: int, wgt: np.ndarray,
                 J: Sequence[np.ndarray], cov: np.ndarray, ok: np.ndarray,
                 offsets_var: tuple[np.ndarray | None, np.ndarray | None]) -> np.ndarray:
    """Covariance [px^2] (nseg x nseg) the removed offsets' errors put on the centres.

    A centre is a linear functional of its pixels, delta_k = sum_px f_px v_px with f the
    first row of N^-1 J^T W; an error e_x on column x moves it by e_x sum_{px in k, col x}
    f_px = A[k, x] e_x, so the covariance is A diag(var) A^T (columns, then rows alike)."""
    c0 = np.where(ok[:, None], cov[:, 0, :], 0.0)
    f = wgt * sum(c0[seg, i] * J[i] for i in range(len(J)))
    out = np.zeros((nseg, nseg))
    for var, where in zip(offsets_var, (idx % width, idx // width), strict=True):
        if var is None:
            continue
        lo = int(where.min())
        span = int(where.max()) - lo + 1
        A = np.bincount(seg * span + (where - lo), f, minlength=nseg * span).reshape(nseg,
                                                                                      span)
        out += (A * var[lo:lo + span][None, :]) @ A.T
    return out


def _blur_step(js: np.ndarray, J: Sequence[np.ndarray], wgt: np.ndarray, r: np.ndarray,
               g: np.ndarray, cov: np.ndarray, ok: np.ndarray, bc) -> tuple[np.ndarray, ...]:
    """Each segment's blur change [px] and its u from one Gauss–Newton step on the blur with
    the segment's other parameters free (the Schur complement of the segment's normal
    matrix): ``js`` the pixels' dP/ds times the contrast, ``J``/``g``/``cov`` the segment
    fit's columns, gradient and inverse normal matrix at the solution."""
    a = np.stack([bc(wgt * js * j) for j in J], axis=1)
    c = np.where(ok[:, None, None], cov, 0.0)
    den = bc(wgt * js * js) - np.einsum("ni,nij,nj->n", a, c, a)
    num = bc(wgt * js * r) - np.einsum("ni,nij,nj->n", a, c, g)
    good = ok & (den > 0)
    dev = np.where(good, num / np.where(good, den, 1.0), np.nan)
    return dev, np.where(good, 1.0 / np.sqrt(np.where(good, den, 1.0)), np.inf)


def groove_extent(image: np.ndarray, pf: ProfileFit, reach_px: float = 24.0
                  ) -> tuple[float, float]:
    """Where the groove ends along its line: the outermost positions t [px], either side of
    the measured stretch, at which its contrast is still half its median (the half-depth
    points of its blurred ends, like the width's).

    The centres are sampled on a stretch trimmed inside the detected ridge, which itself
    fades a filter width before each end, so their span is ~20 px short of a 100 px mark;
    this is the mark's own length. The groove's contrast is fitted per 1-px step along the
    line (level + contrast x the fitted profile), beyond the measured stretch by
    ``reach_px``, and smoothed by a running median over 5 px (dust, noise).
    """
    half = float(np.clip(pf.width_px / 2 + 4 * pf.blur_px + 3, 6, 40))
    t0, t1 = pf.t_start_px - reach_px, pf.t_end_px + reach_px
    vals, e, t, _ = _band(image, pf.angle_rad, pf.offset_px, t0, t1, half)
    ok = (vals < pf.full_scale_dn) & (vals > 0)
    vals, e, t = vals[ok], e[ok], t[ok]
    mid = 0.5 * (pf.t_start_px + pf.t_end_px)
    if vals.size == 0:
        return pf.t_start_px, pf.t_end_px
    j = np.round(t - mid).astype(int)
    j -= j.min()
    nb = int(j.max()) + 1
    p, _ = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)(e)
    cnt = np.bincount(j, minlength=nb)
    sp, spp = np.bincount(j, p, nb), np.bincount(j, p * p, nb)
    sv, spv = np.bincount(j, vals, nb), np.bincount(j, p * vals, nb)
    det = cnt * spp - sp * sp
    amp = np.where(det > 1e-9 * np.maximum(cnt * spp, 1e-300),
                   (cnt * spv - sp * sv) / np.where(det > 0, det, 1.0), np.nan)
    amp[cnt < 4] = np.nan
    tb = np.bincount(j, t, nb) / np.maximum(cnt, 1)  # each bin's mean position
    good = np.isfinite(amp)
    if good.sum() < 10:
        return pf.t_start_px, pf.t_end_px
    sm = np.full(nb, np.nan)
    sm[good] = median_filter(amp[good], size=5, mode="nearest")
    inside = (tb >= pf.t_start_px) & (tb <= pf.t_end_px) & good
    ref = float(np.median(sm[inside])) if inside.any() else float(pf.contrast_dn)
    if ref == 0:
        return pf.t_start_px, pf.t_end_px
    deep = np.flatnonzero(good & (sm / ref >= 0.5))
    if deep.size == 0:
        return pf.t_start_px, pf.t_end_px
    # The outermost deep bins: a stretch covered by dust in between does not shorten it.
    lo, hi = int(deep[0]), int(deep[-1])

    def cross(k: int, k_out: int) -> float:
        """Half-depth crossing between the last deep bin and the next (linear)."""
        if not (0 <= k_out < nb) or not good[k_out]:
            return float(tb[k])
        a, b = sm[k] / ref - 0.5, sm[k_out] / ref - 0.5
        return float(tb[k] + (tb[k_out] - tb[k]) * a / (a - b)) if a != b else float(tb[k])

    return cross(lo, lo - 1), cross(hi, hi + 1)
