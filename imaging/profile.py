"""The band fit of a mark: one fit of the groove model over its whole band, and its ends.

The groove model (:mod:`imaging.groove`): a groove of width w seen through a Gaussian blur s,
mu = b + g_e e + A P(e - delta; w, s) integrated over each pixel. One fit over the whole
band (robust to dust: Huber-reweighted Levenberg–Marquardt) gives the shape (w, s), the
contrast and a refined line (:class:`~imaging.groove.ProfileFit`); the centres along the
mark are :mod:`imaging.centres`' job; :func:`groove_extent` finds where the groove ends.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.ndimage import median_filter

from imaging.band import _band, band_indices, band_pixels, unclipped
from imaging.centres import Centres, sample_centres
from imaging.detect import MarkCandidate, line_frame, wrap_angle
from imaging.errors import ImageInputError
from imaging.groove import (
    ProfileFit,
    ProfileTable,
    _carry_extent,
    _noise_model,
    _profile_table,
    _quad_offsets,
    centres_half,
    profile_lazy,
)
from imaging.groupsum import GroupSums
from imaging.median import median, median_inplace

__all__ = ["BAND_FIT_STEPS", "Centres", "ProfileFit", "ProfileTable", "band_indices",
           "band_pixels", "centres_half", "extent_look", "fit_profile", "groove_extent",
           "sample_centres"]
"""The band fit's own functions, and (re-exported) what moved to imaging.groove, .band and
.centres when this module was split."""

_SHAPE_PIXELS = 2500

BAND_FIT_STEPS = 25
"""The band fit's cap on accepted Levenberg–Marquardt steps. On a groove narrower than its
blur the fit is still moving along the width–blur valley there (not converged), but the
angle hardly depends on where it stops (``benchmarks/band_convergence.py``: on renders with
truth, converging moves it by 0.1 of the line fit's u RMS, at most 0.25, and its errors
stay the same), so the cap stays: converging would cost time and buy nothing."""


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
    bg = float(median(vals[~inner])) if np.any(~inner) else float(median(vals))
    amp0 = float(median(vals[inner]) - bg) if np.any(inner) else 0.0
    w0 = max(cand.thickness_px, _half_depth_width(e, vals, bg, amp0), 1.5)
    x0 = np.array([0.0, 0.0, amp0, bg, 0.0, 0.0, w0, 1.0])
    a_ref = cand.angle_rad

    def model(p):
        """The model at ``p`` and a function that gives its Jacobian (see _irls_lm)."""
        da, dd, amp, b, g_e, g_t, w, s = p
        sh, wt = _quad_offsets(a_ref + da, order=2)
        # Small rotation about the band's middle, then shift: linearised line geometry.
        ee = e - dd - da * (t - tm)
        pp, derivs = profile_lazy(ee, w, s, sh, wt)
        mu = b + g_e * ee + g_t * (t - tm) / 100 + amp * pp

        def jac() -> np.ndarray:
            pe, pw, ps = derivs()
            return np.column_stack([
                -(amp * pe + g_e) * (t - tm), -(amp * pe + g_e), pp, np.ones_like(ee), ee,
                (t - tm) / 100, amp * pw, amp * ps])
        return mu, jac

    scale = max(abs(amp0) / 10, 1.0)
    lo = [-0.05, -half / 2, -np.inf, -np.inf, -np.inf, -np.inf, 0.05, 0.3]
    hi = [0.05, half / 2, np.inf, np.inf, np.inf, np.inf, 4 * half, half]
    # (the model at the solution comes back with it: no evaluation again)
    x, mu = _irls_lm(model, vals, x0, np.array(lo), np.array(hi), scale)
    da, dd, amp, b, g_e, _, w, s = x
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
             scale: float, iterations: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg–Marquardt on Huber-reweighted residuals (IRLS), parameters kept in [lo, hi].

    The band fit has 8 parameters and a few thousand pixels; a hand loop avoids the
    per-iteration overhead of scipy's trust-region solver, which dominated the time here.
    Dust pixels get Huber weights (threshold ``scale``) so they cannot pull the shape.
    ``fun(x)`` gives the model at x and a function that computes its Jacobian, called only
    for the steps accepted. At most ``iterations`` steps (:data:`BAND_FIT_STEPS`, read at
    the call, if None). Returns the solution and the model there.
    """
    if iterations is None:
        iterations = BAND_FIT_STEPS
    x = x0.astype(float).copy()
    lam = 1e-3
    mu, jac = fun(x)
    J = jac()
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
            mun, jacn = fun(xn)
            rn = y - mun
            cn = cost(rn)
            if cn <= c:
                lam = max(lam / 3, 1e-9)
                break
            lam *= 4
            if lam > 1e8:
                return x, mu
        done = c - cn < 1e-10 * c
        x, mu, r, c = xn, mun, rn, cn
        if done:
            break
        J = jacn()  # (not needed after the last step)
    return x, mu


EXTENT_REACH_PX = 24.0
"""How far beyond the measured stretch :func:`groove_extent` looks for the groove's ends [px]."""


def groove_extent(image: np.ndarray, pf: ProfileFit, reach_px: float = EXTENT_REACH_PX,
                  path: Callable[[np.ndarray], np.ndarray] | None = None,
                  tol: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
    """:func:`extent_look`'s ends (the half-depth points) only."""
    return extent_look(image, pf, reach_px, path, tol)[:2]


def extent_look(image: np.ndarray, pf: ProfileFit, reach_px: float = EXTENT_REACH_PX,
                path: Callable[[np.ndarray], np.ndarray] | None = None,
                tol: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float, bool, bool]:
    """Where the groove ends along its line: the outermost positions t [px], either side of
    the measured stretch, at which its contrast is still half its median (the half-depth
    points of its blurred ends, like the width's).

    The detected ridge fades a filter width before each end (its stretch ~20 px short of a
    100 px mark); this is the mark's own length, and the centres are then sampled out to it
    (:func:`imaging.ends.centres_stretch`). The groove's contrast is fitted per 1-px step along the
    line (level + contrast x the fitted profile), beyond the measured stretch by
    ``reach_px``, and smoothed by a running median over 5 px (dust, noise).

    ``path``: the groove's centre across the line as a function of t [px]
    (:func:`imaging.ends.groove_path`), which the band follows (clipped to its half-width)
    where the groove departs from the straight band enough to lose more of its depth there
    (:func:`misplaced_depth`, at the path's largest departure over the look) than the
    straight look's own scatter of depth along the groove: off a straight band a bowed
    groove's ends looked shallow, and were read short by different amounts (a 3.6 px bow
    over 287 px: one end 10.5 px short, the other 2.8, its chord turned 279'' at u 90'').
    The ends along the path are taken only where they turn the path's chord between them
    from the straight look's by more than ``tol[0]`` [rad], or change the bow the path has
    between them (its curvature x the length squared) by more than ``tol[1]`` of itself (the
    caller's u/4 of a line's direction and of the bow through its centres): elsewhere the
    two read the same groove, and the straight band's ends stand (a q50 JPEG's near-axis
    mark, 0.4 px of lens bow: ends 0.1 px apart, a turn of 2.4'' where u/4 is 7.8'', and
    its obstruction check's trim of a blocky end moved 6 px by those 0.1 px).

    Returns (t0, t1, open0, open1): the ends [px], and whether the groove was still deep
    at the look's limit on that side (its end lies further out, unseen).
    """
    half = _look_half(pf)
    straight, scatter = _look(image, pf, reach_px, None, half)
    if path is None:
        return straight
    t = np.linspace(pf.t_start_px - reach_px, pf.t_end_px + reach_px, 65)
    depart = float(np.abs(np.clip(path(t), -half, half)).max())
    if 1.0 - misplaced_depth(pf, half, depart) <= scatter:
        return straight
    along = _look(image, pf, reach_px, path, half)[0]

    def chord(ends: tuple[float, float, bool, bool]) -> float:
        # The path's chord between the ends [rad, small]: what the centres out to them see.
        return float((path(ends[1]) - path(ends[0])) / max(ends[1] - ends[0], 1.0))

    turn = abs(chord(along) - chord(straight))
    length = (along[1] - along[0]) / max(straight[1] - straight[0], 1.0)
    return along if turn > tol[0] or abs(length**2 - 1.0) > tol[1] else straight


def _look_half(pf: ProfileFit) -> float:
    """The extent look's band half-width [px]: the groove and its blurred flanks."""
    return float(np.clip(pf.width_px / 2 + 4 * pf.blur_px + 3, 6, 40))


def misplaced_depth(pf: ProfileFit, half: float, d: float) -> float:
    """The depth (level + contrast x the profile, fitted over a band of half-width ``half``
    [px]) read from the groove moved ``d`` [px] across the band, over its true depth: 1 at
    d = 0, falling as the fitted profile no longer lies on it."""
    # (The look's own table: beyond its reach the profile is the surface's, 0.)
    table = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)
    e = np.linspace(-half, half, 801)
    p, q = np.interp(e, table.grid, table.p), np.interp(e - d, table.grid, table.p)
    pc = p - p.mean()
    return float(pc @ (q - q.mean()) / (pc @ pc))


def _look(image: np.ndarray, pf: ProfileFit, reach_px: float,
          path: Callable[[np.ndarray], np.ndarray] | None, half: float
          ) -> tuple[tuple[float, float, bool, bool], float]:
    """:func:`extent_look` on the straight band (``path`` None) or along the path, and the
    robust relative scatter of the smoothed depth along the measured stretch."""
    t0, t1 = pf.t_start_px - reach_px, pf.t_end_px + reach_px
    bow = (lambda tt: np.clip(path(tt), -half, half)) if path is not None else None
    wide = half + (float(np.abs(bow(np.linspace(t0, t1, 65))).max()) if bow is not None
                   else 0.0)
    vals, e, t, _ = _band(image, pf.angle_rad, pf.offset_px, t0, t1, wide)
    if bow is not None:
        e = e - bow(t)
        near = np.abs(e) <= half
        vals, e, t = vals[near], e[near], t[near]
    ok = unclipped(vals, pf.full_scale_dn)
    if ok is not None:
        vals, e, t = vals[ok], e[ok], t[ok]
    mid = 0.5 * (pf.t_start_px + pf.t_end_px)
    if vals.size == 0:
        return (pf.t_start_px, pf.t_end_px, False, False), 0.0
    j = np.round(t - mid).astype(int)
    j -= j.min()
    nb = int(j.max()) + 1
    # The profile alone (the table's call interpolates its slope too, unused here).
    p = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0).profile(e)
    bc = GroupSums(j, nb, eager=True)  # (5 sums over the same bins: grouped at once)
    cnt = bc.counts
    sp, spp = bc(p), bc(p * p)
    sv, spv = bc(vals), bc(p * vals)
    det = cnt * spp - sp * sp
    amp = np.where(det > 1e-9 * np.maximum(cnt * spp, 1e-300),
                   (cnt * spv - sp * sv) / np.where(det > 0, det, 1.0), np.nan)
    amp[cnt < 4] = np.nan
    tb = bc(t) / np.maximum(cnt, 1)  # each bin's mean position
    good = np.isfinite(amp)
    if good.sum() < 10:
        return (pf.t_start_px, pf.t_end_px, False, False), 0.0
    sm = np.full(nb, np.nan)
    sm[good] = median_filter(amp[good], size=5, mode="nearest")
    inside = (tb >= pf.t_start_px) & (tb <= pf.t_end_px) & good
    ref = float(median(sm[inside])) if inside.any() else float(pf.contrast_dn)
    if ref == 0:
        return (pf.t_start_px, pf.t_end_px, False, False), 0.0
    deep = np.flatnonzero(good & (sm / ref >= 0.5))
    if deep.size == 0:
        return (pf.t_start_px, pf.t_end_px, False, False), 0.0
    # The outermost deep bins: a stretch covered by dust in between does not shorten it.
    lo, hi = int(deep[0]), int(deep[-1])

    def cross(k: int, k_out: int) -> float:
        """Half-depth crossing between the last deep bin and the next (linear)."""
        if not (0 <= k_out < nb) or not good[k_out]:
            return float(tb[k])
        a, b = sm[k] / ref - 0.5, sm[k_out] / ref - 0.5
        return float(tb[k] + (tb[k_out] - tb[k]) * a / (a - b)) if a != b else float(tb[k])

    # (The depth's robust scatter along the groove, relative: the smoothed bins inside.)
    scatter = (1.4826 * float(median_inplace(np.abs(sm[inside] / ref - 1.0))) if inside.any()
               else 0.0)
    return (cross(lo, lo - 1), cross(hi, hi + 1), lo == 0, hi == nb - 1), scatter
