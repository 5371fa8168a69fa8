"""Where a groove's ends lie when something opaque may cover them (dust, printed ink).

An opaque particle over a groove's end replaces the reflectance there, groove and surface
alike: the groove seems to end at the particle's edge, and where it really ends under it
cannot be seen. Each end of a measured groove (:func:`imaging.profile.groove_extent`, the
half-depth points) is therefore checked for an obstruction touching it: along the line,
beyond the end, the band's pixels are fitted per 1-px bin as level + contrast x the groove's
profile (as for the extent). A bin is *disturbed* when its level leaves the surface's (a
linear trend over the measured stretch) by more than :data:`LEVEL_K` robust deviations, or
its residual RMS exceeds :data:`RESID_K` times the stretch's median, or its contrast is
of the wrong sign or far deeper than the groove's (:data:`AMP_K`). A disturbed run that
starts within two blur widths of the end is an obstruction:

* if the groove is seen again beyond it (:data:`DEEP_RUN` undisturbed bins at half its
  depth or more, past the obstruction's fringe: bins not *quiet*, within :data:`QUIET_K`),
  the end was not one: it moves to the end of that stretch (and is checked again);
* otherwise the end is *hidden*: the groove ends somewhere under the obstruction, between
  the visible end and the far side of the disturbed run (out to where the surface is
  seen quiet again, plus a blur width) — a bound, not a length.

Positions t [px] along the line of the :class:`~imaging.groove.ProfileFit` (its frame).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

from imaging.band import _band, unclipped
from imaging.centres import RING_PX, Centres
from imaging.detect import MarkCandidate, line_frame
from imaging.groove import ProfileFit, _profile_table, centres_half
from imaging.groupsum import GroupSums
from imaging.median import median, median_inplace

LEVEL_K = 4.5
"""A bin's level this many robust deviations from the surface's trend is disturbed."""
RESID_K = 3.0
"""A bin whose residual RMS is this many times the stretch's median is disturbed."""
AMP_K = 0.5
"""A bin whose groove contrast is below -AMP_K or above 1 + AMP_K times the stretch's median
is disturbed."""
DEEP_RUN = 6
"""Consecutive undisturbed bins at half the groove's depth that say the groove goes on past
a speck (a blurred speck's fringe alone can look like a few bins of groove)."""
QUIET_K = 2.5
"""A bin within this many robust deviations of the surface's level is quiet (the surface
seen, no speck's fringe)."""
GAP = 2
"""Clean bins allowed inside one obstruction's disturbed run."""
BARE_RUN = 6
"""Consecutive bins of bare surface (quiet, no groove) inside the extent that end the groove
there, at least 3 blur widths: what lies beyond is something else on the line (a numeral's
bar printed just past a scale's long line was read as 18 px more of it)."""


@dataclass(frozen=True)
class GrooveEnds:
    """Both ends of a groove along its line [px]: ``start_px``/``end_px`` the visible ends
    (half-depth points, past any speck the groove is seen beyond), ``start_min_px``/
    ``end_max_px`` how far each could reach under an obstruction touching it (equal to the
    visible end when nothing covers it).

    Attributes
    ----------
    start_px, end_px : float
        The visible ends along the line [px].
    start_min_px, end_max_px : float
        How far each end could reach under an obstruction touching it [px].
    """

    start_px: float
    end_px: float
    start_min_px: float
    end_max_px: float

    @property
    def hidden(self) -> tuple[bool, bool]:
        """Whether the start, the end is under an obstruction."""
        return self.start_min_px < self.start_px, self.end_max_px > self.end_px

    @property
    def length_px(self) -> float:
        """Visible length [px] (a lower bound when an end is hidden)."""
        return self.end_px - self.start_px

    @property
    def length_max_px(self) -> float:
        """Longest length the groove can have under the obstructions [px]."""
        return self.end_max_px - self.start_min_px


def _bin_rms(j: np.ndarray | GroupSums, vals: np.ndarray, p: np.ndarray, dt: np.ndarray,
             nb: int, good: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each bin's residual RMS [DN] about level + (amp + slope dt) x profile, and that
    level [DN] (NaN where not ``good``): the groove's
    depth may change within the bin (dt [px] along the line from the bin's centre). A square
    end drops the depth from full to none over a few blur widths, and a 1-px bin across it
    misfits level + amp x profile by far more than the noise — it was read as an
    obstruction on every clean end. What the slope cannot absorb is no groove: a speck's
    level or shape. (Per-bin 3x3 normal equations from bincount sums; no library fits many
    tiny grouped regressions at once.) ``j``: each pixel's bin, or their
    :class:`imaging.groupsum.GroupSums` when the caller has it."""
    bc = j if isinstance(j, GroupSums) else GroupSums(j, nb)
    j = bc.labels
    cols = (np.ones_like(p), p, p * dt)
    A = np.empty((nb, 3, 3))
    b = np.empty((nb, 3))
    for r in range(3):
        # (The first column is ones, and x * 1.0 is x: its products are skipped, the same sums.)
        b[:, r] = bc(vals if r == 0 else cols[r] * vals)
        for c in range(r, 3):
            A[:, r, c] = A[:, c, r] = bc(cols[c] if r == 0 else cols[r] * cols[c])
    cnt = A[:, 0, 0]
    # A bin too short along the line to tell a slope (or with no spread in dt) keeps 2 terms.
    # (Determinants and solutions of the good bins only: each matrix's are its own, the
    # same in any batch; the others' rms is not used, and the bins beyond the frame are
    # about half of them.)
    ok = good & (cnt >= 5)
    Aok = A[ok]
    ok[ok] = np.abs(np.linalg.det(Aok)) > 1e-9 * np.prod(
        np.maximum(np.diagonal(Aok, axis1=1, axis2=2), 1e-300), axis=1)
    A[~ok, 2, :] = A[~ok, :, 2] = 0.0
    A[~ok, 2, 2] = 1.0
    b[~ok, 2] = 0.0
    x = b.copy()  # (an identity's solution, for the bins not good)
    x[good] = np.linalg.solve(A[good], b[good][..., None])[..., 0]
    x = np.ascontiguousarray(x.T)  # (each term's row gathered by one take)
    pred = x[0].take(j) + x[1].take(j) * p + x[2].take(j) * p * dt
    ss = bc((vals - pred) ** 2)
    dof = np.maximum(cnt - np.where(ok, 3, 2), 1)
    return np.where(good, np.sqrt(ss / dof), np.nan), np.where(good, x[0], np.nan)


def groove_path(centres: Centres, pf: ProfileFit) -> np.polynomial.Polynomial | None:
    """The groove's centre across the profile's line as a smooth function of t [px]: a
    weighted quadratic through its usable measured ``centres`` (raw image); None from fewer
    than 5. A lens bows a straight groove's image by a smooth curve (pixels at a frame's
    corner), and off a straight band the groove's ends looked shallow and misfit — they were
    read as obstructions.
    """
    t, y, s = _path_points(centres, pf)
    return None if t.size < 5 else np.polynomial.Polynomial.fit(t, y, 2, w=1 / s)


def _path_points(centres: Centres, pf: ProfileFit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The usable measured centres along and across the profile's line [px] and their
    sigmas [px]."""
    u, n = line_frame(pf.angle_rad)
    xy, sigma = centres.xy[centres.ok], centres.sigma[centres.ok]
    good = np.all(np.isfinite(xy), axis=1) & np.isfinite(sigma) & (sigma > 0)
    return xy[good] @ u, xy[good] @ n - pf.offset_px, sigma[good]


def path_u(centres: Centres, pf: ProfileFit) -> tuple[float, float]:
    """How well the groove's usable measured ``centres`` (those :func:`groove_path` is
    fitted to, at their own sigmas, widened by their scatter about the path: the square root
    of its chi^2/dof when above 1 — a JPEG's blocks move the centres by several times their
    own sigma, ~5x at q50) read its direction and its bow: the u [rad] of a line's direction
    through them, and the relative u of the path's curvature (inf: fewer than 5 centres).
    """
    t, y, s = _path_points(centres, pf)
    if t.size < 5:
        return float("inf"), float("inf")
    h = max(float(np.ptp(t)) / 2, 1.0)
    x = (t - float(np.mean(t))) / h
    A = np.column_stack([np.ones_like(x), x, x * x]) / s[:, None]
    c, *_ = np.linalg.lstsq(A, y / s, rcond=None)
    r = y / s - A @ c
    scale = max(float(r @ r) / max(len(y) - 3, 1), 1.0)
    w = 1.0 / s**2
    spread = float(np.sum(w * (t - np.sum(w * t) / np.sum(w)) ** 2))
    cov = np.linalg.pinv(A.T @ A) * scale
    bow = abs(float(c[2]))
    return (float(np.sqrt(scale / spread)),
            float(np.sqrt(cov[2, 2])) / bow if bow > 0 else float("inf"))


def groove_ends(image: np.ndarray, pf: ProfileFit, extent: tuple[float, float],
                reach_px: float = 40.0, path: np.polynomial.Polynomial | None = None
                ) -> GrooveEnds:
    """The groove's ends, each checked for an obstruction (see the module docstring).

    Parameters
    ----------
    image : (H, W) array
        The image [DN].
    pf : ProfileFit
        The groove's fitted profile and line.
    extent : (t0, t1)
        Its half-depth ends [px] (:func:`imaging.profile.groove_extent`).
    reach_px : float
        How far beyond each end to look at least [px] (and as far as the groove is long).
    path : numpy.polynomial.Polynomial or None
        The groove's centre across the line as a function of t [px] (:func:`groove_path`,
        extrapolated past the ends); None: on the line.

    Returns
    -------
    GrooveEnds
        The visible ends and how far each could reach under an obstruction [px].
    """
    t0, t1 = extent
    same = GrooveEnds(t0, t1, t0, t1)
    if not (np.isfinite(t0) and np.isfinite(t1)) or t1 - t0 < 10:
        return same
    # A speck across the middle can leave a piece seen beyond it as long as the rest.
    reach_px = max(reach_px, t1 - t0)
    half = float(np.clip(pf.width_px / 2 + 4 * pf.blur_px + 3, 6, 40))
    span = np.linspace(t0 - reach_px, t1 + reach_px, 65)
    # The band follows the groove's path (clipped: a wild extrapolation is no path).
    bow = (lambda tt: np.clip(path(tt), -half, half)) if path is not None else None
    wide = half + (float(np.abs(bow(span)).max()) if bow is not None else 0.0)
    vals, e, t, _ = _band(image, pf.angle_rad, pf.offset_px, t0 - reach_px, t1 + reach_px,
                          wide)
    if bow is not None:
        e = e - bow(t)
        near = np.abs(e) <= half
        vals, e, t = vals[near], e[near], t[near]
    ok = unclipped(vals, pf.full_scale_dn)
    # Clipped pixels (a saturated speck) say "not the surface": a bin of them is disturbed.
    # 1-px bins counted from the middle, so the same from either end: the same pixels rotated
    # by 180 deg fall in the same bins (counted from t0, an end the walk moved came out
    # 0.1 px elsewhere, the centres' stretch with it, and the angle by 0.16 u).
    mid = 0.5 * (t0 + t1)
    half_n = int(np.ceil(0.5 * (t1 - t0) + reach_px))
    clip_bin = (np.round(t[~ok] - mid).astype(int) + half_n if ok is not None
                else np.empty(0, int))
    if ok is not None:
        vals, e, t = vals[ok], e[ok], t[ok]
    vals = vals.astype(float)
    if vals.size == 0:
        return same
    j = np.round(t - mid).astype(int) + half_n
    nb = 2 * half_n + 1
    j = np.clip(j, 0, nb - 1)
    # The table groove_extent and the centres built for this groove (the same arguments):
    # a cache hit, not ~1.3 ms of erf per mark.
    p = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0).profile(e)
    # Per-bin least squares of vals = level + amp p (closed form from the bins' sums).
    bc = GroupSums(j, nb, eager=True)  # (15 sums over the same bins)
    cnt = bc.counts.astype(float)
    sp, spp = bc(p), bc(p * p)
    sv, spv = bc(vals), bc(p * vals)
    det = cnt * spp - sp * sp
    good = (cnt >= 4) & (det > 1e-9 * np.maximum(cnt * spp, 1e-300))
    dd = np.where(good, det, 1.0)
    amp = np.where(good, (cnt * spv - sp * sv) / dd, np.nan)
    level = np.where(good, (spp * sv - sp * spv) / dd, np.nan)
    tb = mid + (np.arange(nb) - half_n)
    # (the level with the depth's slope in the bin: at a square end the depth drops within
    # one bin, and level + amp p alone put that bin's level 4.9 robust deviations low)
    rms, level = _bin_rms(bc, vals, p, t - tb[j], nb, good)
    inside = good & (tb >= t0) & (tb <= t1)
    if inside.sum() < 10:
        return same
    # The surface's level along the stretch (vignetting, a gradient: a slow trend), and its
    # robust scatter from bin to bin (noise, texture, ordinary dust on the groove). (A
    # quadratic trend, for vignetting's curve, cut a long graduation of a scale through a
    # barrel lens at 134 px of its 225: a line.)
    trend = np.polyfit(tb[inside], level[inside], 1)
    dev = level - np.polyval(trend, tb)
    scale = 1.4826 * float(median_inplace(np.abs(dev[inside] - median(dev[inside]))))
    # (again without the bins a speck on the groove moves: they tilt the line, and the
    # surface beyond an end reads off by what they moved)
    fit = inside & (np.abs(dev) <= LEVEL_K * max(scale, 1e-12))
    if fit.sum() >= 10:
        trend = np.polyfit(tb[fit], level[fit], 1)
        dev = level - np.polyval(trend, tb)
        scale = 1.4826 * float(median_inplace(np.abs(dev[inside] - median(dev[inside]))))
    scale = max(scale, 1e-9 * abs(float(np.polyval(trend, tb[inside]).mean())) + 1e-12)
    rms_ref = float(median(rms[inside]))
    disturbed = good & ((np.abs(dev) > LEVEL_K * scale) | (rms > RESID_K * rms_ref))
    disturbed[np.clip(clip_bin, 0, nb - 1)] = True
    amp_s = np.full(nb, np.nan)
    amp_s[good] = median_filter(amp[good], size=5, mode="nearest")
    ref = float(median(amp_s[inside]))
    deep = good & (amp_s / ref >= 0.5) if ref != 0 else np.zeros(nb, bool)
    # Contrast of the wrong sign (a bright speck on a dark groove's line) or far beyond the
    # groove's (a dark one) is no groove either, even when its level stays near the surface's.
    if ref != 0:
        disturbed |= good & ((amp_s / ref < -AMP_K) | (amp_s / ref > 1 + AMP_K))
    quiet = good & (np.abs(dev) <= QUIET_K * scale) & (rms <= RESID_K * rms_ref)
    touch = int(np.ceil(2 * pf.blur_px + 2))

    def run_from(i: int, step: int) -> int:
        """The last bin of the obstruction through bin i going ``step``: bins not quiet
        (its fringe included), gaps of up to GAP quiet bins."""
        last, clean = i, 0
        while 0 <= i + step < nb and clean <= GAP:
            i += step
            if good[i] and not quiet[i]:
                last, clean = i, 0
            else:
                clean += 1
        return last

    def walk(k: int, step: int) -> tuple[int, int]:
        """From the end's bin k (step +-1 outward): (last bin of the groove seen clean,
        farthest bin an obstruction touching the end covers); equal when none does."""
        while True:
            # The groove seen on past the end (the extent stops at its search's reach).
            while 0 <= k + step < nb and deep[k + step] and not disturbed[k + step]:
                k += step
            near = [k + step * i for i in range(-touch, touch + 1) if 0 <= k + step * i < nb]
            hit = [i for i in near if disturbed[i]]
            # One disturbed 1-px bin is the end's own fall of depth misfit within the bin (a
            # sharp end, blur under 1 px, on a lens-bowed path: its residual 3.3 x the body's
            # on a clean corner mark), not an obstruction: an opaque particle's blurred
            # edge alone spans more than one bin.
            if len(hit) < 2:
                return k, k
            # The obstruction's run, inward and outward from what touches the end.
            inner = run_from(hit[0], -step)
            outer = run_from(hit[-1], step)
            clean_end = min(k, inner - step) if step > 0 else max(k, inner - step)
            # (An obstruction's run out to the last bin inward: its inner side is that bin,
            # not one past it — an IndexError at the end, a wrap to the far end at the start.)
            clean_end = min(max(clean_end, 0), nb - 1)
            # An extent that reached over bare surface into the obstruction (the look runs
            # a fixed reach past the search's stretch) is no groove there: what is seen ends
            # at the groove's last deep bin inside it (a speck 4 px past a short graduation's
            # end read it 3.5 px long when a family's wider search let the look reach it).
            while clean_end != k and not deep[clean_end] and (clean_end - mid) * step > 0:
                clean_end -= step
            # The groove seen again beyond it (deep, on the surface's level): the end was a
            # speck lying on the groove; the groove's end is further. A stretch of groove
            # too short to say so, ending on another obstruction, joins them (a numeral's
            # bar, then a speck on the end).
            while True:
                i = outer + step
                while (0 <= i < nb and not (deep[i] and quiet[i])
                       and abs(i - outer) <= touch + GAP):
                    i += step
                run = 0
                while 0 <= i < nb and deep[i] and not disturbed[i]:
                    run += 1
                    i += step
                if run >= DEEP_RUN or not (0 <= i < nb and disturbed[i]):
                    break
                outer = run_from(i, step)
            if run >= DEEP_RUN and (i - step - k) * step > 0:
                k = i - step  # strictly further out: the walk ends
                continue
            # The groove may end anywhere the obstruction's fringe still hides it: out to
            # the surface seen quiet again, plus a blur width.
            far = outer + step
            while 0 <= far + step < nb and not quiet[far]:
                far += step
            far = int(np.clip(far + step * int(np.ceil(pf.blur_px)), 0, nb - 1))
            return clean_end, far

    k0 = int(np.argmin(np.abs(tb - t0)))
    k1 = int(np.argmin(np.abs(tb - t1)))
    mid = (k0 + k1) // 2

    def cross(k: int, step: int) -> float:
        """Half-depth crossing between the last deep bin k and the next one out."""
        k_out = k + step
        if not (0 <= k_out < nb) or not good[k_out] or not good[k]:
            return float(tb[k])
        a, b = amp_s[k] / ref - 0.5, amp_s[k_out] / ref - 0.5
        return float(tb[k] + step * a / (a - b)) if a > 0 > b else float(tb[k])

    bare = max(BARE_RUN, int(np.ceil(3 * pf.blur_px)))

    bare_bin = (quiet & ~deep).tolist()  # (a list: ~2000 look-ups a mark at 5 MP)

    def body_end(k: int, step: int) -> int:
        """The groove's last bin before bare surface, from its middle out to bin k."""
        i, run = (k0 + k1) // 2, 0
        while (k - i) * step > 0:
            i += step
            run = run + 1 if bare_bin[i] else 0
            if run >= bare:
                return i - step * run
        return k

    ends = []
    for k, t_end, step in ((k0, t0, -1), (k1, t1, +1)):
        b = body_end(k, step)
        # (Only the outer half of each half: a gap near the middle is no groove's end.)
        if b != k and abs(tb[b] - tb[(k0 + k1) // 2]) >= 0.25 * (t1 - t0):
            k, t_end = b, cross(b, step)
        vis, far = walk(k, step)
        # An end that did not move (by more than a bin) keeps its half-depth crossing.
        v = t_end if abs(vis - k) <= 1 else cross(vis, step)
        ends.append((v, v if far == vis else float(tb[far])))
    (s_vis, s_min), (e_vis, e_max) = ends
    if e_vis <= s_vis:
        return same
    return GrooveEnds(s_vis, e_vis, min(s_min, s_vis), max(e_max, e_vis))


RUNS_ON_PX = 10.0
"""How far past the extent's look the groove must be seen for its extent to be looked for
again from the longer stretch [px] (a few blur widths: more than where the half-depth point
may fall)."""


@dataclass(frozen=True)
class EndsCheck:
    """:func:`groove_ends` of one measurement's profile, extent and centres (its path) in
    one image: kept with the measurement, so that the obstruction check of its ends
    (``align.family.member_ends``) does not run again on the same pixels (~4 % of a 640 x 480
    frame's time). The measurement looks for its ends once, before its full centres pass,
    along the path of its first (quick) centres, and keys the check to its final centres
    (:func:`imaging.measure.measure_candidate`): the two paths agree to a fraction of a
    pixel, and the same ends serve both. It answers only for those very objects
    (:meth:`for_mark`): the image itself, not a copy or a version with a background or a
    shadow removed (held by a weak reference: a session's results do not keep its frames
    alive)."""

    image: weakref.ref
    profile: ProfileFit
    extent: tuple[float, float]
    centres: Centres
    ends: GrooveEnds

    def for_mark(self, image: np.ndarray, pf: ProfileFit, extent: Sequence[float],
                 cen: Centres) -> GrooveEnds | None:
        """The ends when ``image``, ``pf``, ``extent`` and ``cen`` are the ones checked,
        else None."""
        same = (self.image() is image and pf is self.profile and cen is self.centres
                and tuple(extent) == tuple(self.extent))
        return self.ends if same else None


def checked_ends(image: np.ndarray, pf: ProfileFit, extent: tuple[float, float],
                 cen: Centres, check: EndsCheck | None = None) -> GrooveEnds:
    """:func:`groove_ends` along the groove's path through ``cen``, from ``check`` when it
    holds these very inputs (the same result: the same function of the same pixels)."""
    got = check.for_mark(image, pf, extent, cen) if check is not None else None
    return got if got is not None else groove_ends(image, pf, extent,
                                                   path=groove_path(cen, pf))


EDGE_MARGIN_PX = 2.0
"""How far inside the frame a lengthened stretch's band (and its illumination ring) stays at
each end [px]: the extension stops where the frame would cut its band."""

OTHER_REACH_PX = 40.0
"""How far past another mark's detected stretch its groove is taken to run on [px] (its
ridge fades a filter width before its ends, as this one's does: ~24 px at 640 x 480, ~40 px
at 5 MP)."""


def frame_limits(shape: tuple[int, int], pf: ProfileFit, reach_px: float,
                 margin_px: float = EDGE_MARGIN_PX) -> tuple[float, float]:
    """How far along the line [px] the stretch may run at each end with its band (``reach_px``
    either side of the line) inside the frame by ``margin_px``: (lowest t0, highest t1).

    Only the frame's sides the band is clear of at the search's own end limit that end; an
    end whose band the frame already cuts (a mark along the frame's edge, or running out of
    it) is not lengthened at all (its limit is the search's end)."""
    h, w = shape[:2]
    u, n = line_frame(pf.angle_rad)
    c = np.array([(w - 1) / 2, (h - 1) / 2]) + pf.offset_px * n
    lo_hi = [margin_px, margin_px, w - 1 - margin_px, h - 1 - margin_px]
    limits = []
    for t_end, sgn in ((pf.t_start_px, -1.0), (pf.t_end_px, 1.0)):
        far = np.inf
        for side in (-reach_px, reach_px):
            a = c + side * n
            for k in (0, 1):
                for bound, lower in ((lo_hi[k], True), (lo_hi[k + 2], False)):
                    # g(t) = +-(a_k + t u_k - bound) >= 0 inside.
                    g0 = (a[k] + t_end * u[k] - bound) * (1 if lower else -1)
                    slope = sgn * u[k] * (1 if lower else -1)  # dg per px outward
                    if g0 < 0:
                        far = 0.0
                    elif slope < 0:
                        far = min(far, g0 / -slope)
        limits.append(t_end + sgn * far)
    return limits[0], limits[1]


def others_limits(pf: ProfileFit, others: Sequence[tuple[int, MarkCandidate]], reach_px: float,
                  trim_px: float) -> tuple[float, float]:
    """How far along the line [px] the stretch may run at each end before another mark's
    groove comes within its band: (lowest t0, highest t1).

    Every other mark counts, at any angle: one that crosses the line past an end (a corner, a
    crossing mark the search stopped at), one that runs on along it (two pieces of one edge
    stay two marks, not one measured twice), a neighbour whose end comes near it. Its groove
    is taken to run :data:`OTHER_REACH_PX` past its detected stretch, and the stretch stops
    ``trim_px`` plus its half-width short of where it enters the band (``reach_px`` either
    side of the line). What lies beside the search's own stretch is the crossing mask's
    (:func:`imaging.crossmask.crossing_skip`)."""
    u, n = line_frame(pf.angle_rad)
    t0, t1 = -np.inf, np.inf
    for _, o in others:
        uo, no = line_frame(o.angle_rad)
        ts = np.arange(o.t_start_px - OTHER_REACH_PX, o.t_end_px + OTHER_REACH_PX + 1.0, 1.0)
        pts = o.offset_px * no + ts[:, None] * uo
        tt, dd = pts @ u, pts @ n - pf.offset_px
        gap = o.thickness_px / 2 + trim_px
        inside = np.abs(dd) <= reach_px + o.thickness_px / 2
        after = tt[inside & (tt > pf.t_end_px)]
        before = tt[inside & (tt < pf.t_start_px)]
        if after.size:
            t1 = min(t1, float(after.min()) - gap)
        if before.size:
            t0 = max(t0, float(before.max()) + gap)
    return t0, t1


def centres_stretch(image: np.ndarray, pf: ProfileFit, ext: Sequence[float],
                    opened: Sequence[bool], cen: Centres,
                    others: Sequence[tuple[int, MarkCandidate]] = ()
                    ) -> tuple[tuple[float, float] | None, EndsCheck, tuple[bool, bool]]:
    """The stretch to sample the centres on: out to where the groove really ends.

    The search's stretch stops short of each end (its ridge fades a filter width before it,
    ~24 px at 640 x 480; or breaks at a speck beside the line), and the centres sampled on it
    left the angle 1.5x its bound: a 300 px groove measured over 248 px, and with a lens's
    k1 free the angle is read against the bow from the ends' centres most. The groove's ends
    are followed as the end check does (:func:`groove_ends` from the half-depth extent
    ``ext`` of :func:`imaging.profile.extent_look`: past specks the groove is seen beyond,
    never past bare surface), and each end of the stretch is moved out towards them, but
    only as far as the groove is whole and nothing else lies in its band:

    * a blurred end (half-width + 2 blur widths) short of each end, clean or hidden: every
      centre sees the groove's full depth across its band, none its fall of depth along the
      line nor an obstruction's fringe;
    * short of any other mark's groove entering the band (:func:`others_limits`: a crossing
      or corner mark, a line running on along this one, a neighbour's end);
    * with the band and its ring inside the frame (:func:`frame_limits`);
    * never shorter than the search's stretch (what it saw, the crossing mask and the
      refusals judge as before).

    Each added centre gets its own u from its own pixels, like any other.

    Returns the stretch (None: the search's, unchanged), the ends checked
    (:class:`EndsCheck`, keyed to ``pf``, ``ext`` and ``cen``) and, per end, whether the
    groove was seen on well past the look of the extent (``opened`` there, and more than
    :data:`RUNS_ON_PX` further): the extent is then looked for again from the new stretch.
    """
    e = groove_ends(image, pf, ext, path=groove_path(cen, pf))
    check = EndsCheck(weakref.ref(image), pf, (float(ext[0]), float(ext[1])), cen, e)
    on = (bool(opened[0]) and e.start_px < ext[0] - RUNS_ON_PX,
          bool(opened[1]) and e.end_px > ext[1] + RUNS_ON_PX)
    trim = max(4.0, pf.width_px / 2 + 2 * pf.blur_px)
    reach = centres_half(pf) + RING_PX
    f0, f1 = frame_limits(image.shape, pf, reach)
    o0, o1 = others_limits(pf, others, reach, trim)
    # Each end no further out than the groove's half-depth point (``ext``) unless it runs on
    # past the look: the end check's walk may stop a few px past a clean end (3.6 px on a
    # strongly lens-bowed one), and the last centres then saw its fall of depth (misfit,
    # left out in some images of a mark and not in others).
    end0 = e.start_px if on[0] else max(e.start_px, float(ext[0]))
    end1 = e.end_px if on[1] else min(e.end_px, float(ext[1]))
    t0 = max(end0 + trim, f0, o0)
    t1 = min(end1 - trim, f1, o1)
    t0, t1 = min(t0, pf.t_start_px), max(t1, pf.t_end_px)
    if t0 == pf.t_start_px and t1 == pf.t_end_px:
        return None, check, on
    return (t0, t1), check, on
