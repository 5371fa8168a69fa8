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
from imaging.centres import Centres
from imaging.detect import MarkCandidate, line_frame
from imaging.groove import ProfileFit, _profile_table
from imaging.groupsum import GroupSums

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
        b[:, r] = bc(cols[r] * vals)
        for c in range(r, 3):
            A[:, r, c] = A[:, c, r] = bc(cols[r] * cols[c])
    cnt = A[:, 0, 0]
    # A bin too short along the line to tell a slope (or with no spread in dt) keeps 2 terms.
    ok = good & (cnt >= 5) & (np.abs(np.linalg.det(A)) > 1e-9 * np.prod(
        np.maximum(np.diagonal(A, axis1=1, axis2=2), 1e-300), axis=1))
    A[~ok, 2, :] = A[~ok, :, 2] = 0.0
    A[~ok, 2, 2] = 1.0
    b[~ok, 2] = 0.0
    A[~good] = np.eye(3)
    x = np.linalg.solve(A, b[..., None])[..., 0]
    pred = x[j, 0] + x[j, 1] * p + x[j, 2] * p * dt
    ss = bc((vals - pred) ** 2)
    dof = np.maximum(cnt - np.where(ok, 3, 2), 1)
    return np.where(good, np.sqrt(ss / dof), np.nan), np.where(good, x[:, 0], np.nan)


def groove_path(centres: Centres, pf: ProfileFit) -> np.polynomial.Polynomial | None:
    """The groove's centre across the profile's line as a smooth function of t [px]: a
    weighted quadratic through its usable measured ``centres`` (raw image); None from fewer
    than 5. A lens bows a straight groove's image by a smooth curve (pixels at a frame's
    corner), and off a straight band the groove's ends looked shallow and misfit — they were
    read as obstructions.
    """
    u, n = line_frame(pf.angle_rad)
    xy, sigma = centres.xy[centres.ok], centres.sigma[centres.ok]
    good = np.all(np.isfinite(xy), axis=1) & np.isfinite(sigma) & (sigma > 0)
    if good.sum() < 5:
        return None
    return np.polynomial.Polynomial.fit(xy[good] @ u, xy[good] @ n - pf.offset_px, 2,
                                        w=1 / sigma[good])


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
    clip_bin = np.round(t[~ok] - t0 + reach_px).astype(int) if ok is not None else np.empty(0, int)
    if ok is not None:
        vals, e, t = vals[ok], e[ok], t[ok]
    vals = vals.astype(float)
    if vals.size == 0:
        return same
    j = np.round(t - t0 + reach_px).astype(int)
    nb = int(np.ceil(t1 - t0 + 2 * reach_px)) + 1
    j = np.clip(j, 0, nb - 1)
    # The table groove_extent and the centres built for this groove (the same arguments):
    # a cache hit, not ~1.3 ms of erf per mark.
    p, _ = _profile_table(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)(e)
    # Per-bin least squares of vals = level + amp p (closed form from the bins' sums).
    bc = GroupSums(j, nb)  # (15 sums over the same bins)
    cnt = bc.counts.astype(float)
    sp, spp = bc(p), bc(p * p)
    sv, spv = bc(vals), bc(p * vals)
    det = cnt * spp - sp * sp
    good = (cnt >= 4) & (det > 1e-9 * np.maximum(cnt * spp, 1e-300))
    dd = np.where(good, det, 1.0)
    amp = np.where(good, (cnt * spv - sp * sv) / dd, np.nan)
    level = np.where(good, (spp * sv - sp * spv) / dd, np.nan)
    tb = t0 - reach_px + np.arange(nb)
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
    scale = 1.4826 * float(np.median(np.abs(dev[inside] - np.median(dev[inside]))))
    # (again without the bins a speck on the groove moves: they tilt the line, and the
    # surface beyond an end reads off by what they moved)
    fit = inside & (np.abs(dev) <= LEVEL_K * max(scale, 1e-12))
    if fit.sum() >= 10:
        trend = np.polyfit(tb[fit], level[fit], 1)
        dev = level - np.polyval(trend, tb)
        scale = 1.4826 * float(np.median(np.abs(dev[inside] - np.median(dev[inside]))))
    scale = max(scale, 1e-9 * abs(float(np.polyval(trend, tb[inside]).mean())) + 1e-12)
    rms_ref = float(np.median(rms[inside]))
    disturbed = good & ((np.abs(dev) > LEVEL_K * scale) | (rms > RESID_K * rms_ref))
    disturbed[np.clip(clip_bin, 0, nb - 1)] = True
    amp_s = np.full(nb, np.nan)
    amp_s[good] = median_filter(amp[good], size=5, mode="nearest")
    ref = float(np.median(amp_s[inside]))
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
            if not hit:
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
"""How far past the extent's look the groove must be seen for the centres to be sampled
again over it [px] (a few blur widths: more than where the half-depth point may fall)."""


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


def runs_on_stretch(image: np.ndarray, pf: ProfileFit, ext: Sequence[float], opened: Sequence[bool],
             cen: Centres, others: Sequence[tuple[int, MarkCandidate]] = ()
             ) -> tuple[tuple[float, float] | None, EndsCheck | None]:
    """The stretch to sample the centres on when the groove runs on past the look of
    :func:`imaging.profile.extent_look` (still deep at the look's limit), or None.

    The search's stretch ends where its ridge broke (a speck beside the line, another on
    it); the groove's half-depth extent is looked for only
    :data:`imaging.profile.EXTENT_REACH_PX` beyond it. Its ends are then followed as the
    end check does (:func:`imaging.ends.groove_ends`: past specks the groove is seen
    beyond, never past bare surface), and the stretch is what they enclose, trimmed by the
    blurred end (half-width + 2 blur widths), up to the nearest end of another mark found
    on the same line (``others``: (index, candidate); two pieces of one edge stay two marks,
    not one measured twice). Also the ends checked (:class:`EndsCheck`; None when no end
    was open and none were)."""
    if not any(opened):
        return None, None
    e = groove_ends(image, pf, ext, path=groove_path(cen, pf))
    check = EndsCheck(weakref.ref(image), pf, (float(ext[0]), float(ext[1])), cen, e)
    # Only a groove seen on well past the look (a clean long mark's end can lie just at it).
    on = (opened[0] and e.start_px < ext[0] - RUNS_ON_PX,
          opened[1] and e.end_px > ext[1] + RUNS_ON_PX)
    if not any(on):
        return None, check
    trim = max(4.0, pf.width_px / 2 + 2 * pf.blur_px)
    t0 = e.start_px + trim if on[0] else pf.t_start_px
    t1 = e.end_px - trim if on[1] else pf.t_end_px
    u, n = line_frame(pf.angle_rad)
    for _, o in others:
        uo, no = line_frame(o.angle_rad)
        ends = np.array([o.offset_px * no + s * uo for s in (o.t_start_px, o.t_end_px)])
        if np.max(np.abs(ends @ n - pf.offset_px)) > max(3.0, o.thickness_px):
            continue  # not on this line
        lo, hi = sorted(ends @ u)
        if lo >= pf.t_end_px:
            t1 = min(t1, lo - trim)
        elif hi <= pf.t_start_px:
            t0 = max(t0, hi + trim)
    t0, t1 = min(t0, pf.t_start_px), max(t1, pf.t_end_px)
    if t0 == pf.t_start_px and t1 == pf.t_end_px:
        return None, check
    return (t0, t1), check
