"""Sub-pixel centres of a mark all along its length.

The mark is cut into short segments along its length and each segment's centre offset
delta_k (with its own contrast A_k, level b_k and background slope across the mark g_k) is
fitted by Gauss–Newton on the groove model (:mod:`imaging.groove`) about the band fit's
line (:mod:`imaging.profile`), with per-pixel weights from a shot + read noise model
estimated from the data. The per-segment standard uncertainties come from each segment's
Fisher information, so the line fit downstream propagates a real uncertainty.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from imaging.asymmetry import SegmentAsymmetry, segment_asymmetry
from imaging.band import _band, unclipped
from imaging.detect import line_frame
from imaging.errors import ImageInputError
from imaging.groove import ProfileFit, _profile_table, centres_half, noise_models, variance_floor
from imaging.groupsum import GroupSums
from imaging.ring import ring_geometry, ring_slope
from imaging.shape import basis_spans, fit_shape, shape_shift
from imaging.texture import TextureModel, texture_control, texture_model

EXTRA_STEPS = 4
"""Gauss–Newton steps a segment's centre may take beyond the usual ones while it still moves
(a lens bows a long off-centre mark by several px: with 2 steps of at most 1 px its ends
stopped 0.2-0.35 px short, and a calibrated lens was reported as differing from itself)."""

RCOND = 1e-8
"""Least ratio of the smallest to the largest eigenvalue of a segment's normal matrix, scaled
to unit diagonal (its parameters' correlation-like matrix), for the segment to be solved.
``det(N) > 0`` alone let rounding decide a nearly singular segment (a few pixels all on one
flank: centre and contrast not separated): on left04.jpg 1e-14 relative noise on the image
flipped it, its contrast ran off to ~2e8 DN and mark 1 had 45 or 49 points. Below 1e-8 the
worst-determined combination's variance is over 1e8 times the best's (the segment tells
nothing of its centre), and rounding (~1e-14 of the matrix) moves the ratio by ~1e-14: it
can no longer decide."""

MISFIT_CHI2 = 3.0
"""A segment whose pixels' chi2/dof exceeds this many times the typical segment's (at least
1) does not fit the groove (dust, a particle over an end, a crossing scratch): it stays out
of the line (:mod:`imaging.measure`) and of the groove's departure pool
(:mod:`imaging.shape`)."""

AMP_STEP = 10.0
"""Largest change of a segment's contrast in one Gauss-Newton step, in units of the band's
contrast: a bound on a runaway, not a constraint on a segment that converges."""


def _conditioned(N: np.ndarray) -> np.ndarray:
    """Which of the segments' normal matrices ``N`` (nseg, k, k) are positive definite with a
    reciprocal condition, at unit diagonal, of at least :data:`RCOND`."""
    d = np.einsum("nii->ni", N)
    ok = np.all(d > 0, axis=1)
    s = 1.0 / np.sqrt(np.where(ok[:, None], d, 1.0))
    C = N * s[:, :, None] * s[:, None, :]
    # The eigenvalues (~1 ms per step at 5 MP's ~500 segments) only where the pivots cannot
    # tell: the decision is the same (see _surely_conditioned).
    out = _surely_conditioned(C)
    doubt = ok & ~out
    if doubt.any():
        lam = np.linalg.eigvalsh(C[doubt])  # (per matrix: the same values as in a batch)
        out[doubt] = lam[:, 0] > RCOND * lam[:, -1]
    return ok & out


SURE_DET = 1e-6
"""Least determinant of a unit-diagonal normal matrix that :func:`_surely_conditioned` takes
as proof of a reciprocal condition above :data:`RCOND`."""


def _surely_conditioned(C: np.ndarray) -> np.ndarray:
    """Which of the symmetric unit-diagonal matrices ``C`` (n, k, k) are, beyond rounding,
    positive definite with lam_min > :data:`RCOND` lam_max (False: not known, not "no").

    By elimination without pivoting (C = L D L^T, the pivots D): all pivots > 0 is positive
    definite, and their product is det C. The trace is k, so lam_max < k and the other k - 1
    eigenvalues' product is at most (k / (k - 1))^(k - 1) (AM-GM): lam_min / lam_max >
    det / (k (k / (k - 1))^(k - 1)) (9.5 for k = 4). A det above :data:`SURE_DET` puts the
    ratio above ~1e-7, ten times RCOND; the factors' rounding (backward error ~1e-15 of C's
    unit entries for positive pivots) and eigvalsh's own (~1e-15) cannot bring it under, so
    the eigenvalue test says yes to every matrix this does."""
    n, k, _ = C.shape
    assert SURE_DET / (k * (k / (k - 1)) ** (k - 1)) > 2 * RCOND  # the margin counted on
    A = C.copy()
    piv = np.empty((n, k))
    with np.errstate(divide="ignore", invalid="ignore"):  # (a 0 or NaN pivot: not sure)
        for j in range(k):
            piv[:, j] = A[:, j, j]
            low = A[:, j + 1:, j] / piv[:, j, None]
            A[:, j + 1:, j + 1:] -= low[:, :, None] * A[:, j, None, j + 1:]
        return np.all(piv > 0, axis=1) & (np.prod(piv, axis=1) > SURE_DET)


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
    ``offsets_cov``: the covariance [px^2] of the centres from removed stripes' offsets,
    which every segment on a column (row) shares (None: none); ``profile_shift``,
    ``profile_shift_cov``: how far the groove's own profile (its even departure from the
    model, :mod:`imaging.shape`) moves each centre [px] and that shift's covariance [px^2]
    (None unless asked for: the Type B term ``groove_profile`` is read from them);
    ``asymmetry``: each segment's odd departure (:mod:`imaging.asymmetry`; None likewise).

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
    profile_shift : ndarray or None
        (N,) the centres' shift by the groove's own profile [px].
    profile_shift_cov : ndarray or None
        (N, N) its covariance [px^2].
    asymmetry : SegmentAsymmetry or None
        Each segment's one-sided depth change and the centre shift it made.
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
    profile_shift: np.ndarray | None = None
    profile_shift_cov: np.ndarray | None = None
    asymmetry: SegmentAsymmetry | None = None


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


_LEVEL = 2
"""Index of the segment fit's level column (ones) among its columns (centre, contrast, level,
slope)."""

RING_PX = 6.0
"""Width of the ring just outside the band whose pixels give the background slope [px]."""

MIN_CV_REPLICAS = 4
"""Fewest replica series of the band (:func:`imaging.texture.texture_model`) whose texture
coupling is applied to the centres as a control variate. The coupling estimated from n
series adds about 1/n of the centres' own noise variance, in one direction common to all of
them and not in their u: from the 8 a free mark has, ~6 % of u; from the one or two left
where other lines take the rest (a dial's graduations 30 deg apart, a ruled scale's pitch),
as much as the mark's own noise (a dial's graduation moved 15", 0.9 u, by a coupling of
36 px^2 from 1 series, -2.3 from 8 without its neighbours). Under 4 it is left out (0)."""


def _ring(wide: tuple[np.ndarray, ...], inner: np.ndarray,
          segments: tuple[np.ndarray, np.ndarray], nseg: int) -> tuple[np.ndarray, ...]:
    """Pixels of a ring just outside the band the centres are fitted on (half < |e| <=
    half + :data:`RING_PX`): (flat index, e, segment), for the background slope across the
    mark, from ``wide``, the band out to the ring's edge (:func:`_band`'s four arrays), less
    its ``inner`` pixels (|e| <= half), with ``segments`` (:func:`segment_index` of its
    pixels: segment, kept).

    Outside the band on purpose: the slope fitted inside it shares its pixels' noise with
    the centre (both odd in e), and would correlate with the centre's error by chance.
    """
    _, e, _, idx = wide
    seg, keep = segments
    sel = ~inner & keep
    sel &= seg < nseg
    return idx[sel], e[sel], seg[sel]


def pixels_at(image: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """``image``'s values at flat (row-major) indices ``flat``: one gather through the flat
    view (numpy's 2-D fancy indexing costs ~3x), by rows and columns when the image is not
    contiguous (its flat view would be a copy)."""
    if image.flags.c_contiguous:
        return image.ravel()[flat]
    return image[np.divmod(flat, image.shape[1])]


def sample_centres(image: np.ndarray, pf: ProfileFit, segment_px: float = 4.0,
                   iterations: int = 2, every: int = 1, where: str = "image",
                   texture: bool = False, avoid_px: Sequence[float] = (),
                   guess: tuple[np.ndarray, np.ndarray] | None = None,
                   offsets_var: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
                   departure: bool = False) -> Centres:
    """Centre offset of the mark in consecutive segments along its length (vectorised GN).

    ``every`` > 1 keeps only every n-th segment (a quick pass that only sets a reference line).
    ``guess``: (t, offset) [px] of the groove from the reference line along it (an earlier
    pass's centres), the start of each segment's offset; Gauss–Newton runs ``iterations``
    steps of at most 1 px each, and on (up to :data:`EXTRA_STEPS` more) while a segment still
    moves, so a strongly bowed groove's ends are not left where the steps stopped.
    ``offsets_var``: variances [DN^2] of per-column and per-row offsets already subtracted
    from the image (removed stripes, :mod:`imaging.stripes`); their errors are shared by
    every segment on the same column (row), and ``Centres.offsets_cov`` carries them.
    ``departure``: also read the groove's own profile from the residuals and how far it
    moves each centre (``Centres.profile_shift``; not applied).
    ``texture``: also measure how the background's texture correlates the centres' errors
    (replicas of the band beside the mark, :mod:`imaging.texture`), with no replica within
    a band and ring's width of the other lines at signed distances ``avoid_px`` [px].
    """
    half = centres_half(pf)
    # The band and its illumination ring rasterised once: the band's pixels are those of the
    # wider band within ``half`` of the line, in the same order (the same arrays as a band
    # of ``half`` alone; ~1 ms of each pass at 5 MP).
    wide = _band(image, pf.angle_rad, pf.offset_px, pf.t_start_px, pf.t_end_px,
                 half + RING_PX)
    inner = np.abs(wide[1]) <= half
    # Each pixel's segment once for the band and its ring (elementwise in t: the band's the
    # same as from its own t).
    seg_w, keep_w = segment_index(wide[2], pf, segment_px, every)
    vals, e, t, idx, seg, keep = (a[inner] for a in (*wide, seg_w, keep_w))
    inside = unclipped(vals, pf.full_scale_dn)  # see fit_profile
    if inside is not None:
        vals, e, t, idx, seg, keep = (a[inside] for a in (vals, e, t, idx, seg, keep))
    if vals.size == 0:
        raise ImageInputError(f"{where}: mark at offset {pf.offset_px:.0f} px: its band lies "
                              "outside the image or is all clipped")
    if not keep.all():
        vals, e, t, seg, idx = vals[keep], e[keep], t[keep], seg[keep], idx[keep]
    if vals.size == 0:
        raise ImageInputError(f"{where}: mark at offset {pf.offset_px:.0f} px: no pixels in "
                              "its segments")
    nseg = int(seg.max()) + 1
    table = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)
    groove_reach = min(pf.width_px / 2 + 4 * pf.blur_px, half)
    delta = np.zeros(nseg)
    if guess is not None and len(guess[0]) >= 2:
        mid = 0.5 * (pf.t_start_px + pf.t_end_px)
        reach = int(np.round(0.5 * (pf.t_end_px - pf.t_start_px) / segment_px)) + 1
        t_nom = mid + (np.arange(nseg) * every - reach) * segment_px
        order = np.argsort(guess[0])
        delta = np.clip(np.interp(t_nom, guess[0][order], guess[1][order]), -half / 2, half / 2)
    sym = _symmetric_window(e - delta.take(seg), seg, nseg, half)
    if not sym.all():
        vals, e, t, seg, idx = vals[sym], e[sym], t[sym], seg[sym], idx[sym]
    bc = GroupSums(seg, nseg, eager=True)  # (~60 sums a pass)
    fit = _solve_segments(vals, e, seg, bc, pf, table, delta, iterations)
    k, N, ok, delta, amp, moving = fit.k, fit.N, fit.ok, fit.delta, fit.amp, fit.moving
    ee, pe, r, wgt, J, g, npx, (v0, v1) = (fit.ee, fit.pe, fit.r, fit.wgt, fit.J, fit.g,
                                            fit.npx, fit.noise_var)
    blur_dev = blur_dev_u = None
    amp_px = amp.take(seg)  # (each pixel's segment contrast, gathered once for all below)
    cov = np.full((nseg, k, k), np.inf)
    cov[ok] = np.linalg.inv(N[ok])
    if texture:
        # The defocus test's input: each segment's blur step on the groove model's profile.
        blur_dev, blur_dev_u = _blur_step(table.blur_slope(ee) * amp_px, J, wgt, r, g,
                                          cov, ok, bc)
    ocov = None
    if any(v is not None for v in offsets_var):
        ocov = _offsets_cov(idx, image.shape[1], seg, nseg, wgt, J, cov, ok, offsets_var)
    chi2_red = bc(wgt * r * r) / np.maximum(npx - k, 1)
    shift = shift_cov = asym = None
    if departure:
        # Its odd departure, segment by segment (imaging.asymmetry: paint worn from one side).
        asym = segment_asymmetry(ee, table.profile(ee), r, amp_px, wgt, J, cov, ok, seg,
                                 pf.blur_px)
        # The groove's own profile (imaging.shape): its even departure from the model,
        # pooled over the segments' phases, and how far it moves each centre (not applied:
        # measured, for the Type B term ``groove_profile``).
        # Each pixel's distance from a straight line through the centres, not from its own
        # segment's noisy centre: near a phase where the departure is steep, the shift read
        # at the noisy centres followed their noise (a clean mark at 0.02 deg: b -10" at
        # 5 sigma_b, its error -3.5").
        sg = ok & (npx >= 6) & (np.abs(delta) < half / 2) & ~moving
        # Nor segments that misfit the groove (a particle over an end: its fringe's
        # residuals read as the profile's departure tilted hidden-end lines by up to 2 u).
        if sg.any():
            sg &= chi2_red < MISFIT_CHI2 * max(1.0, float(np.median(chi2_red[sg])))
        if sg.sum() >= 2:
            jj = np.arange(nseg)
            xx = e - np.polyval(np.polyfit(jj[sg], delta[sg], 1), jj)[seg]
            spans = basis_spans(xx, groove_reach)  # (for both: the pool is a subset)
            pool = sg.take(seg)
            # (Every pixel in the pool, the usual case: the arrays themselves, not copies.)
            sub = ((lambda a: a) if pool.all() else (lambda a: a[pool]))
            shape = fit_shape(sub(xx), sub(r), sub(amp_px), sub(wgt), groove_reach,
                              (sub(spans[0]), sub(spans[1]), spans[2]))
            if shape is not None:
                shift, shift_cov = shape_shift(shape, xx, amp_px * wgt, J, cov, ok, seg,
                                               spans)
    # An ill-conditioned segment (det > 0 by rounding only) can invert to a negative variance.
    sigma = np.where(cov[:, 0, 0] > 0, np.sqrt(np.abs(cov[:, 0, 0])), np.inf)
    info = wgt * (amp_px * pe) ** 2
    t_eff = bc(info * t) / np.maximum(bc(info), 1e-300)
    ring = _ring(wide, inner, (seg_w, keep_w), nseg)
    ring_geo = ring_geometry(ring[1], ring[2], nseg)  # (for the replicas too)
    slope = ring_slope(pixels_at(image, ring[0]), ring[1], ring[2], nseg, pf.full_scale_dn,
                       ring_geo)
    u, n = line_frame(pf.angle_rad)
    good = ok & (npx >= 6) & np.isfinite(sigma) & (np.abs(delta) < half / 2) & ~moving
    amp_safe = np.where(amp != 0, amp, 1.0)
    tex = None
    if texture:
        # Replicas just clear of the band and of its illumination ring, and further out:
        # 8 series (4 distances, both sides) make the autocovariance precise enough that
        # the loop's tests see white residuals (4 left ~10 % of textured marks flagged).
        shifts = tuple(m * (half + 4) for m in (2, 4, 6, 8))
        tex = texture_model(image, (idx, seg), nseg, wgt, J, cov, good, ring, amp_safe, n,
                            shifts, (v0, v1), pf.full_scale_dn, avoid_px, 2 * (half + 4), npx,
                            bc, ring_geo)
    if tex is not None and tex.replicas < MIN_CV_REPLICAS:
        tex = replace(tex, coupling_px2=0.0, coupling_u_px2=0.0)
    if tex is not None:
        # Control variate: the part of the centre's error that the ring's texture slope
        # predicts is taken out (what stays is independent of the regressor).
        # (centred: its mean is the shading's slope, not texture; see texture_control)
        delta = delta - texture_control(tex, slope / amp_safe, good, sigma)
    xy = (pf.offset_px + delta)[:, None] * n + t_eff[:, None] * u
    return Centres(xy=xy, sigma=sigma, t=t_eff, contrast=amp, cross_slope=slope / amp_safe,
                   chi2_red=chi2_red, ok=good, texture=tex, blur_dev=blur_dev,
                   blur_dev_u=blur_dev_u, offsets_cov=ocov, profile_shift=shift,
                   profile_shift_cov=shift_cov, asymmetry=asym)


BATCH_VALUES = 1 << 17
"""Most values (band pixels x images) :func:`sample_centres_batch` takes in one pass (more
images are taken in turns): ~1 MB an array. On the real photos' JPEG terms 2^16 to 2^18,
or all 64 images of a 9.6k-pixel band at once, cost the same; 2^15 (3 such images a pass)
cost 40 % more."""


def sample_centres_batch(images: np.ndarray, pf: ProfileFit) -> list[Centres]:
    """:func:`sample_centres` (its defaults) of the groove ``pf`` on each of ``images``
    (m, h, w), in one vectorised pass: each image's centres the same to the bit as alone.

    The JPEG term's noisy draws (:mod:`imaging.jpeg_turn`) measure one model many times
    over: the band's pixels, segments and sums are the same for every image, and one pass
    over all of them costs about what a few alone do. An image with a clipped pixel in the
    band (its own pixels left out) is measured alone."""
    images = np.asarray(images)
    half = centres_half(pf)
    wide = _band(images[0], pf.angle_rad, pf.offset_px, pf.t_start_px, pf.t_end_px,
                 half + RING_PX)
    inner = np.abs(wide[1]) <= half
    _, e, t, idx = (a[inner] for a in wide)
    per = max(2, BATCH_VALUES // max(idx.size, 1))
    if len(images) > per:
        return [c for i in range(0, len(images), per)
                for c in sample_centres_batch(images[i:i + per], pf)]
    flat = images.reshape(len(images), -1)
    vals = flat[:, idx].T.astype(float)  # (pixels, images)
    whole = [unclipped(v, pf.full_scale_dn) is None for v in vals.T] if vals.size else []
    if vals.size == 0 or not all(whole) or len(images) < 2:
        together = [i for i, w in enumerate(whole) if w]
        out = dict(zip(together, sample_centres_batch(images[together], pf), strict=True)
                   ) if len(together) >= 2 else {}
        return [out[i] if i in out else sample_centres(im, pf) for i, im in enumerate(images)]
    seg, _ = segment_index(t, pf, 4.0)
    nseg = int(seg.max()) + 1
    sym = _symmetric_window(e, seg, nseg, half)
    vals, e, t, seg, idx = vals[sym], e[sym], t[sym], seg[sym], idx[sym]
    bc = GroupSums(seg, nseg, eager=True)
    fit = _solve_segments(vals, e, seg, bc, pf,
                          _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0),
                          np.zeros(nseg), 2)
    ok, k = fit.ok, fit.k
    cov00 = np.full(ok.shape, np.inf)
    cov00[ok] = np.linalg.inv(fit.N[ok])[:, 0, 0]
    chi2_red = bc(fit.wgt * fit.r * fit.r) / np.maximum(fit.npx - k, 1)[:, None]
    sigma = np.where(cov00 > 0, np.sqrt(np.abs(cov00)), np.inf)
    info = fit.wgt * (fit.amp[seg] * fit.pe) ** 2
    t_eff = bc(info * t[:, None]) / np.maximum(bc(info), 1e-300)
    ring = _ring(wide, inner, segment_index(wide[2], pf, 4.0), nseg)
    geometry = ring_geometry(ring[1], ring[2], nseg)
    u, n = line_frame(pf.angle_rad)
    good = (ok & (fit.npx >= 6)[:, None] & np.isfinite(sigma)
            & (np.abs(fit.delta) < half / 2) & ~fit.moving)
    out = []
    for i, im in enumerate(images):
        slope = ring_slope(pixels_at(im, ring[0]), ring[1], ring[2], nseg, pf.full_scale_dn,
                           geometry)
        amp = fit.amp[:, i]
        xy = (pf.offset_px + fit.delta[:, i])[:, None] * n + t_eff[:, i, None] * u
        out.append(Centres(xy=xy, sigma=sigma[:, i], t=t_eff[:, i], contrast=amp,
                           cross_slope=slope / np.where(amp != 0, amp, 1.0),
                           chi2_red=chi2_red[:, i], ok=good[:, i]))
    return out


@dataclass(frozen=True)
class _Solved:
    """:func:`_solve_segments`'s state at each image's last pass: per pixel (``ee`` its
    distance from its segment's centre, ``pe`` the profile's slope there, ``r`` residual,
    ``wgt`` weight, ``J`` the fit's columns), per segment (``N`` normal matrix, ``g``
    gradient, ``ok`` solvable, ``delta`` centre, ``amp`` contrast, ``moving`` still moving,
    ``npx`` pixels) and per image ``noise_var`` (v0, v1); an image's axis trails them all
    but ``N``'s and ``g``'s (segment, image, k[, k])."""

    k: int
    ee: np.ndarray
    pe: np.ndarray
    r: np.ndarray
    wgt: np.ndarray
    J: tuple
    N: np.ndarray
    g: np.ndarray
    ok: np.ndarray
    delta: np.ndarray
    amp: np.ndarray
    moving: np.ndarray
    npx: np.ndarray
    noise_var: tuple


def _solve_segments(vals: np.ndarray, e: np.ndarray, seg: np.ndarray, bc: GroupSums,
                    pf: ProfileFit, table, delta: np.ndarray, iterations: int) -> _Solved:
    """Each segment's Gauss–Newton fit (centre, contrast, level, slope) to the band's pixels
    ``vals`` at distances ``e`` [px] in segments ``seg`` (``bc`` their sums), from the
    centres ``delta`` [px] (see :func:`sample_centres`).

    ``vals`` (pixels, m): m images of the same band at once (the JPEG term's draws,
    :mod:`imaging.jpeg_turn`), each image's answer the same to the bit as alone: every sum
    is over its own column, each decision (the noise model, the weights' floor, when to
    stop) is its own, and an image that has stopped takes no more steps (its state, computed
    again from the same parameters, is the same)."""
    nseg = bc.n
    lead = vals.shape[1:]  # () for one image, (m,) for m

    def col(a: np.ndarray) -> np.ndarray:
        """A per-pixel array broadcast against the images' trailing axis."""
        return a.reshape(a.shape + (1,) * len(lead))

    e_b = col(e)
    v0, v1 = pf.noise_var
    delta = np.broadcast_to(col(delta), (nseg,) + lead).copy()
    moving = np.zeros((nseg,) + lead, bool)
    done = np.zeros(lead, bool)
    amp = np.full((nseg,) + lead, pf.contrast_dn)
    lev = np.full((nseg,) + lead, pf.background_dn)
    # Each segment has its own background slope across the mark: surface texture and uneven
    # light tilt the background differently along the mark, and a slope left in the model
    # moves the fitted centre (a false "illumination gradient"). Costs little precision: the
    # slope is set by the pixels beside the groove, the centre by its flanks.
    slp = np.full((nseg,) + lead, pf.slope_across_dn_per_px)
    k = 4
    # Every per-segment sum below over the same pixels (~60 a pass): grouped once (bc).
    npx = bc(np.ones_like(e))
    for it in range(iterations + 1 + EXTRA_STEPS):
        # (Gathers by take: the same values as indexing, ~1.5x cheaper.)
        ee = e_b - delta.take(seg, axis=0)
        p, pe = table(ee)
        amp_px, slp_px = amp.take(seg, axis=0), slp.take(seg, axis=0)  # (once for mu and J)
        mu = lev.take(seg, axis=0) + slp_px * ee + amp_px * p
        r = vals - mu
        if it == 1:
            # Noise model again, now from the segment model's residuals (local level and
            # contrast absorb illumination and texture that the band fit could not);
            # each segment spends k of its pixels' degrees of freedom.
            rs = r * col(np.sqrt(npx / np.maximum(npx - k, 1))[seg])
            # Without the segments whose pixels misfit the groove far beyond the typical one
            # (a numeral inked across the mark: its dark pixels filled the groove's levels'
            # bins and the noise, read there, overstated every centre's sigma).
            ms = bc(rs * rs) / col(np.maximum(npx, 1))
            fits = ms <= MISFIT_CHI2 * np.median(ms[npx > k], axis=0)
            v = noise_models(mu, rs, fits, seg)
            # (An image stopped already keeps its own: with iterations < 2 one may be.)
            v0, v1 = (np.where(done, v0, v[0]), np.where(done, v1, v[1])) if lead else v
        # The linear noise model is fitted over the band's levels; below them (a segment's
        # model darker than any bin: a dust speck's fit) it can reach 0, and a weight of
        # 1e9 gave centres a sigma of ~0 (chi2 ~1e15 over a ruled scale's frame). No pixel
        # of a groove is quieter than a quarter of the band's typical variance.
        var = v0 + v1 * mu
        wgt = 1.0 / np.maximum(var, variance_floor(var, mu, v0, v1))
        J = (-(amp_px * pe + slp_px), p, np.ones_like(p), ee)[:k]
        N = np.empty((nseg,) + lead + (k, k))
        g = np.empty((nseg,) + lead + (k,))
        for i in range(k):
            # Once per column (the products are the same to the bit); the level's column is
            # ones, and x * 1.0 is x: those products are skipped.
            wj = wgt if i == _LEVEL else wgt * J[i]
            g[..., i] = bc(wj * r)
            for j in range(i, k):
                N[..., i, j] = N[..., j, i] = bc(wj if j == _LEVEL else wj * J[j])
        ok = _conditioned(N.reshape(-1, k, k)).reshape(N.shape[:-2])
        # The last pass only refreshes weights and information at the solution.
        done = done | ((it >= iterations) & ~np.any(moving & ok, axis=0))
        if done.all() or it == iterations + EXTRA_STEPS:
            break  # (at the last: those still moving are left out by the caller)
        go = ok & ~done
        step = np.zeros((nseg,) + lead + (k,))
        step[go] = np.linalg.solve(N[go], g[go][..., None])[..., 0]
        # A step of 0.1 px is ~5 sigma of a typical centre: such a segment has not arrived.
        moving = np.where(done, moving, np.abs(step[..., 0]) > 0.1)
        step[..., 0] = np.clip(step[..., 0], -1.0, 1.0)
        delta += step[..., 0]
        # Nor may the contrast move by more than AMP_STEP times the band's own in one step
        # (a segment nearly unable to separate it from its centre ran off to ~2e8 DN); a
        # cap of once the band's changed segments of the real chessboards that converge.
        cap = AMP_STEP * abs(pf.contrast_dn)
        amp += np.clip(step[..., 1], -cap, cap)
        lev += step[..., 2]
        if k == 4:
            slp += step[..., 3]
    return _Solved(k, ee, pe, r, wgt, J, N, g, ok, delta, amp, moving, npx, (v0, v1))


def _symmetric_window(x: np.ndarray, seg: np.ndarray, nseg: int, half: float) -> np.ndarray:
    """Pixels of a band that the frame's edge cuts on one side, kept symmetric about each
    segment's centre: |x| <= the extent the cut side still has (``x``: distance from the
    segment's centre [px]). A profile the model misses by an even amount (a rounded groove,
    one narrowed by a lens at the edge) moves no centre when both sides are sampled alike;
    cut on one side it did (user7's mark 2.4-4 px from the top edge: centres 0.03 px towards
    the edge, +45 arcsec on 300 px). Bands that reach ``half`` on both sides keep every pixel
    (a saturated or crossed pixel inside a band is no cut)."""
    lo = np.full(nseg, np.inf)
    hi = np.full(nseg, np.inf)
    np.minimum.at(lo, seg, x)
    np.minimum.at(hi, seg, -x)
    reach = np.minimum(-lo, -hi)  # the shorter side's extent per segment
    cut = reach < half - 1.0
    return ~cut[seg] | (np.abs(x) <= reach[seg] + 1e-9)


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
    wjs = wgt * js  # (each product below is (wgt * js) * x, as written out before)
    a = np.stack([bc(wjs * j) for j in J], axis=1)
    c = np.where(ok[:, None, None], cov, 0.0)
    den = bc(wjs * js) - np.einsum("ni,nij,nj->n", a, c, a)
    num = bc(wjs * r) - np.einsum("ni,nij,nj->n", a, c, g)
    good = ok & (den > 0)
    dev = np.where(good, num / np.where(good, den, 1.0), np.nan)
    return dev, np.where(good, 1.0 / np.sqrt(np.where(good, den, 1.0)), np.inf)
