"""Where another mark crosses a mark: the stretch left out of its fit, or a clear refusal.

Separate from :mod:`imaging.crossing` (pure geometry, imported by the detector) because it
needs the groove's fitted profile window (:mod:`imaging.profile`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from imaging.band import _band
from imaging.candidate import MarkCandidate, line_frame
from imaging.centres import Centres
from imaging.confirm import across, block_medians
from imaging.crossing import MIN_CROSSING, crossing_stretch, double_grooves
from imaging.errors import ImageInputError
from imaging.groove import ProfileFit, centres_half, profile_and_derivs
from imaging.median import median, median_inplace
from imaging.profile import fit_profile

MIN_SEGMENTS = 10
"""Fewest solved segments a mark's fit is made from (of which a majority must fit the
groove: :func:`segments_needed`)."""
CROSSING_MAX_SHARE = 0.75
"""A mark whose length lies more than this inside crossing marks' grooves is not measured
(what is left, at most two short stretches at its ends, no longer shows whether they agree)."""


def segments_needed(solved: int) -> int:
    """Fewest segments a mark's line is fitted from, of the ``solved`` ones: those that fit
    the groove and agree with their neighbours are found by tests against the segments'
    median (chi2, ring slope, running median of the residuals), which hold while most of
    them are good: a strict majority, up to :data:`MIN_SEGMENTS`. Its line's u is the fit's
    of the segments kept (a 70 px tick's 9 of 13, 4 beside a speck whose ring slope they
    read, was refused at a fixed 10)."""
    return min(MIN_SEGMENTS, solved // 2 + 1)


def crossing_skip(image: np.ndarray, cen: Centres, pf: ProfileFit,
                  crossing: Sequence[tuple[int, MarkCandidate]], top: float, where: str,
                  look: bool = True) -> tuple[np.ndarray | None, tuple[tuple[int, int], ...]]:
    """Segments of a mark over which another mark's groove lies inside its centres' band.

    There the fitted centre is pulled towards the other groove (at a shallow crossing over a
    long stretch: 2 (band + the other's half-width) / sin(angle) px), so those segments are
    left out of the fit. Two sources, joined: the other marks found (``crossing``: (index,
    candidate)), their grooves taken to run on through the stretch where they fuse with this
    one (their ridge is lost there), and a second groove seen in this mark's own profiles
    (:func:`grooves_beside`, when ``look``: a mark found too short, or not found). Gaps
    between excluded stretches shorter than the longest of them are the fused core (one
    groove, pulled) and are excluded too. When they are most of the mark
    (:data:`CROSSING_MAX_SHARE`) the two cannot be told apart: an ImageInputError naming
    the pixel region.

    Returns (skip mask or None, ((other index or -1: not found, px left out), ...)).
    """
    # The band the centres are fitted on, and the other groove's half-width (taken as this
    # one's when it was not found).
    window = centres_half(pf) + max(2.5, pf.width_px / 2 + 1)
    stretches: list[tuple[float, float, int]] = []
    beside: list[tuple[int, MarkCandidate]] = []  # (with the run-on ends measured)
    for j, o in crossing:
        if o.fused is not None:  # refused itself; its grooves are the found marks'
            continue
        # o's core (its ridge's half-width) within the band.
        half = probe = centres_half(pf) + o.thickness_px / 2 + 1
        got = crossing_stretch(pf, o, half, extend=True)
        found = crossing_stretch(pf, o, half)  # o's found part only
        o_on = o  # o with its ends where its groove is seen to end
        if got is not None and (found is None or found[:2] != got[:2]):
            runs = groove_runs_on(image, pf, o, probe)
            if runs is False:
                # A corner: o ends where its ridge was found; only that part lies in the
                # window.
                got = found
            else:
                # o's groove taken to run on past its found ends only as far as it is seen
                # to (or hidden under this groove): a groove stepped beside this one that
                # starts just before the crossing is not taken to run on through it.
                o_on = run_on(image, pf, o, half)
                got = crossing_stretch(pf, o_on, half) or found
        if got is not None:
            stretches.append((got[0], got[1], j))
            beside.append((j, o_on))
    for t0, t1 in grooves_beside(image, pf, top, window) if look else ():
        stretches.append((t0, t1, -1))
    if not stretches:
        return None, ()
    stretches.sort(key=lambda s: s[0])
    longest = max(s[1] - s[0] for s in stretches)
    merged = [list(stretches[0])]
    for t0, t1, j in stretches[1:]:
        last = merged[-1]
        if t0 - last[1] < longest:  # overlapping, or the fused core between two stretches
            last[1] = max(last[1], t1)
            last[2] = max(last[2], j)  # named by the mark found, if any
        else:
            merged.append([t0, t1, j])
    length = max(pf.t_end_px - pf.t_start_px, 1e-9)
    skip = np.zeros(len(cen.t), bool)
    for t0, t1, _ in merged:
        skip |= (cen.t >= t0) & (cen.t <= t1)
    # and beside them, while the crossing grooves' flanks in the band still turn the line
    # (each centre's segment: 4 px, its t at its middle)
    for j, o in beside:
        more = flank_skip(image, cen, pf, o, skip, top)
        if more.any():
            t0, t1 = float(cen.t[more].min()) - 2.0, float(cen.t[more].max()) + 2.0
            for m in merged:
                if t0 <= m[1] + 4.0 and t1 >= m[0] - 4.0:  # beside this stretch: widens it
                    m[0], m[1] = min(m[0], t0), max(m[1], t1)
                    break
            else:
                merged.append([t0, t1, j])
            skip |= more
    share = sum(min(t1, pf.t_end_px) - max(t0, pf.t_start_px) for t0, t1, _ in merged)
    # (and too few segments left beside the crossing to fit: the same refusal, not a bare
    # "too few usable segments")
    if share > CROSSING_MAX_SHARE * length or (cen.ok & ~skip).sum() < MIN_SEGMENTS:
        t0, t1, j = max(merged, key=lambda s: s[1] - s[0])
        u, n = line_frame(pf.angle_rad)
        centre = np.array([(image.shape[1] - 1) / 2, (image.shape[0] - 1) / 2])
        a, b = (centre + pf.offset_px * n + t * u for t in (max(t0, pf.t_start_px),
                                                           min(t1, pf.t_end_px)))
        other = f"mark {j}" if j >= 0 else "another groove"
        raise ImageInputError(
            f"{where}: mark at offset {pf.offset_px:.0f} px: {other} lies in its profile "
            f"window from pixel (x {a[0]:.0f}, y {a[1]:.0f}) to (x {b[0]:.0f}, y {b[1]:.0f}), "
            f"{share:.0f} of its {length:.0f} px (marks crossing at a shallow angle); the two "
            "cannot be measured apart")
    return skip, tuple((j, int(round(min(t1, pf.t_end_px) - max(t0, pf.t_start_px))))
                       for t0, t1, j in merged)


FLANK_TURN = 0.25
"""Most a crossing groove's flank, left in the band of the centres kept beside it, may turn a
mark's line, in units of the line's u from its centres: a bias of a quarter of u raises the
RMS of err/u by 3 %. (A groove whose flank reached 2 blur widths into the band beside a
5 deg crossing, the rest of its core left out, turned the line 71.8'' at 18.3'' u.)"""


def centre_pull(pf: ProfileFit, po: ProfileFit, d_px: np.ndarray) -> np.ndarray:
    """How far another groove (profile ``po``) whose line lies ``d_px`` from this one's
    (``pf``) moves a centre of :func:`imaging.centres.sample_centres` [px, along the normal]:
    one Gauss-Newton step of the segment's model (level, slope across, contrast, centre;
    equal weights over the band) from its noise-free profile, the other's added."""
    half = centres_half(pf)
    e = np.arange(-half, half + 1e-9, 0.05)
    one, zero = np.ones(1), np.zeros(1)
    p, pe = profile_and_derivs(e, pf.width_px, pf.blur_px, zero, one, shape_derivs=False)
    J = np.stack([-(pf.contrast_dn * pe + pf.slope_across_dn_per_px), p, np.ones_like(e), e], 1)
    A = np.linalg.pinv(J)[0]  # the centre's row of (J'J)^-1 J'
    d = np.asarray(d_px, float)
    po_e = profile_and_derivs(e[None, :] - d.ravel()[:, None], po.width_px, po.blur_px, zero,
                              one, shape_derivs=False)[0]
    return ((po.contrast_dn * po_e) @ A).reshape(d.shape)


def flank_skip(image: np.ndarray, cen: Centres, pf: ProfileFit, o: MarkCandidate,
               skip: np.ndarray, top: float) -> np.ndarray:
    """Centres beside those left out (``skip``) where mark ``o``'s groove, its blurred flank
    still in their band, would turn the line by more than :data:`FLANK_TURN` of its u
    (:func:`centre_pull` from o's own fitted profile; this groove's when o's cannot be
    fitted), left out too, nearest the crossing first. (Only o's core is in the window of
    :func:`crossing_skip`: its flank reaches 3 blur widths further.)"""
    use = cen.ok & ~skip & np.isfinite(cen.sigma)
    more = np.zeros(len(cen.t), bool)
    uo, no = line_frame(o.angle_rad)
    uc, nc = line_frame(pf.angle_rad)
    cos = float(uo @ uc)
    if abs(cos) < 1e-6 or use.sum() < 3:
        return more
    # o's line where it passes each centre: s along o, d its distance from this line.
    s = (cen.t - o.offset_px * float(no @ uc)) / cos
    d = o.offset_px * float(no @ nc) + s * float(uo @ nc) - pf.offset_px
    near = use & (s >= o.t_start_px) & (s <= o.t_end_px) & (np.abs(d) < centres_half(pf)
                                                              + pf.width_px + 4 * pf.blur_px)
    if not near.any():
        return more
    try:
        po = fit_profile(image, o, full_scale=top)
    except ImageInputError:
        po = pf
    b = np.zeros(len(cen.t))
    b[near] = centre_pull(pf, po, d[near])
    w = np.where(use, 1.0 / np.where(use, cen.sigma, 1.0) ** 2, 0.0)
    while (use & ~more).sum() >= 3:
        k = use & ~more
        tm = np.sum(w[k] * cen.t[k]) / np.sum(w[k])
        sxx = np.sum(w[k] * (cen.t[k] - tm) ** 2)
        turn = np.sum(w[k] * (cen.t[k] - tm) * b[k]) / sxx
        if abs(turn) <= FLANK_TURN / np.sqrt(sxx) or not (k & (b != 0)).any():
            break
        # The centre nearest o's line next.
        cand = np.flatnonzero(k & (b != 0))
        more[cand[np.argmin(np.abs(d[cand]))]] = True
    return more


def run_on(image: np.ndarray, pf: ProfileFit, o: MarkCandidate, half_px: float
           ) -> MarkCandidate:
    """Mark ``o`` with its found ends moved out as far as its groove is seen to run on, or
    is hidden, towards and within ``half_px`` of this mark's (``pf``) line.

    Past each end, :data:`RUN_STEP_PX` px at a time, o's profile is compared with its own
    just inside the end (:func:`_probe_end`): on while it runs on or cannot be told (o's
    core hidden by this groove where the two fuse), stopped at the far side of the first
    stretch bare surface fills (the groove's end lies within it), or where o's line
    leaves the window."""
    uo, no = line_frame(o.angle_rad)
    nc = line_frame(pf.angle_rad)[1]
    sin = float(uo @ nc)
    d0 = o.offset_px * float(no @ nc) - pf.offset_px
    s_lo, s_hi = sorted(((-half_px - d0) / sin, (half_px - d0) / sin))
    ends = [o.t_start_px, o.t_end_px]
    for k, step, inside in ((0, -1.0, lambda s: s > s_lo), (1, 1.0, lambda s: s < s_hi)):
        s = ends[k]
        while inside(s):
            past = _probe_end(image, pf, o, step, abs(s - ends[k]), RUN_STEP_PX)
            s += step * RUN_STEP_PX
            if past is False:
                break
        ends[k] = s
    return replace(o, t_start_px=min(ends[0], o.t_start_px), t_end_px=max(ends[1], o.t_end_px))


RUN_STEP_PX = 20.0
"""Length of each stretch past another groove's found end that :func:`run_on` probes [px]:
its end is placed at the far side of the first bare one (a 40 px stretch with the groove
over half of it, partly hidden under this one, read as bare)."""


RUNS_ON = 0.5
"""The other groove runs on past its found end when its profile there is at least this
fraction of its profile just inside the end (the regression slope of one on the other)."""
ENDS = 0.25
"""...and it ends there when that slope is below this (between the two: not known)."""
PROBE_PX = 40.0
"""Length of the stretches inside and past the other groove's found end compared [px]."""


def _median_profile(image: np.ndarray, o: MarkCandidate, pf: ProfileFit, t0: float,
                    t1: float, half: int, mask_px: float) -> np.ndarray:
    """Median across o's line per 1-px bin of e (-half..half) [DN] between t0 and t1 along
    it, leaving out the pixels within ``mask_px`` of ``pf``'s line (NaN: too few)."""
    vals, e, t, _ = _band(image, o.angle_rad, o.offset_px, t0, t1, half + 0.5)
    uo, no = line_frame(o.angle_rad)
    nc = line_frame(pf.angle_rad)[1]
    d_c = o.offset_px * float(no @ nc) - pf.offset_px + t * float(uo @ nc) + e * float(no @ nc)
    keep = (np.abs(d_c) > mask_px) & (vals > 0) & (vals < pf.full_scale_dn)
    k = np.round(e[keep]).astype(int) + half
    out = np.full(2 * half + 1, np.nan)
    for b in np.unique(k):
        v = vals[keep][k == b]
        if v.size >= 3:
            out[b] = median(v)
    return out


def groove_runs_on(image: np.ndarray, pf: ProfileFit, o: MarkCandidate, half_px: float
                   ) -> bool | None:
    """Whether mark ``o``'s groove runs on past its found end(s) where it would lie in this
    mark's (``pf``) profile window: a crossing (True), or a corner where it ends (False);
    None when the image cannot tell (o's core hidden by this groove past its end, o's own
    profile flat, too few pixels).

    At a shallow crossing the other mark's ridge is lost where the two grooves fuse, so its
    found end says nothing about whether it goes on (:func:`imaging.crossing.
    crossing_stretch`'s ``extend``, ``half_px`` the window's half-width there). The ends
    probed: the one facing the point where the two lines meet, when that lies beyond o's
    found extent; else each end past which o's line lies in the window over this mark's
    extent. At each, o's median profile across its own line over :data:`PROBE_PX` px just
    inside the end (its groove, whatever its shape: a real edge is seldom the groove
    model's) and over as much past it, each leaving out the pixels near this mark's groove;
    the slope of the second on the first over the bins both hold is 1 where the groove goes
    on, 0 where bare surface follows (:data:`RUNS_ON`, :data:`ENDS`). False only when every
    end probed ends. (A comparison of two profiles, written here.)
    """
    uo, no = line_frame(o.angle_rad)
    uc, nc = line_frame(pf.angle_rad)
    sin = float(uo @ nc)
    if abs(sin) < np.sin(MIN_CROSSING):
        return None
    d0 = o.offset_px * float(no @ nc) - pf.offset_px  # o's line's distance from c's at s = 0
    s_x = -d0 / sin  # where o's line meets c's
    if s_x > o.t_end_px:
        steps = [1.0]
    elif s_x < o.t_start_px:
        steps = [-1.0]
    else:
        def in_window(s: float) -> bool:
            tc = o.offset_px * float(no @ uc) + s * float(uo @ uc)
            return (abs(d0 + s * sin) <= half_px
                    and pf.t_start_px - half_px <= tc <= pf.t_end_px + half_px)
        steps = [st for st, s_end in ((-1.0, o.t_start_px), (1.0, o.t_end_px))
                 if in_window(s_end + 2 * st)]
    got = [_probe_end(image, pf, o, st) for st in steps]
    if not got or None in got:
        return None
    return any(got)


def _probe_end(image: np.ndarray, pf: ProfileFit, o: MarkCandidate, step: float,
               beyond_px: float = 0.0, length_px: float = PROBE_PX) -> bool | None:
    """:func:`groove_runs_on` at o's end ``step`` (+1: its t_end, -1: its t_start): the
    stretch past it compared starts ``beyond_px`` past the end (along ``step``) and is
    ``length_px`` long."""
    s_end = o.t_end_px if step > 0 else o.t_start_px
    half = int(np.ceil(o.thickness_px + 8))
    mask = max(4.0, pf.width_px / 2 + 2)
    inner = min(PROBE_PX, 0.5 * o.length_px)
    ref = _median_profile(image, o, pf, *sorted((s_end, s_end - step * inner)), half, mask)
    s0 = s_end + step * beyond_px
    past = _median_profile(image, o, pf, *sorted((s0, s0 + step * length_px)), half, mask)
    core = np.abs(np.arange(-half, half + 1)) <= o.thickness_px / 2 + 1
    both = np.isfinite(ref) & np.isfinite(past)
    if (both & core).sum() < 2 or both.sum() < 6:
        return None
    r, q = ref[both], past[both]
    if np.ptp(r) == 0:
        return None
    # Theil-Sen (the median of the pairwise slopes): a bin or two of this groove's fringe
    # left past the mask do not decide it. (By hand: scipy.stats.theilslopes would import
    # scipy.stats, ~0.8 s of CPU per process, for a median of a few hundred slopes.)
    i, j = np.triu_indices(r.size, 1)
    dr = r[j] - r[i]
    slope = float(median_inplace((q[j] - q[i])[dr != 0] / dr[dr != 0]))
    return True if slope >= RUNS_ON else False if slope < ENDS else None


def grooves_beside(image: np.ndarray, pf: ProfileFit, top: float, window: float,
                   block_px: int = 16) -> list[tuple[float, float]]:
    """Stretches (t0, t1) [px] along a mark where its median profile shows a second groove
    within ``window`` px of its line, not parallel to it (that is a neighbour, kept out of
    the texture's replicas instead), and not the mark itself."""
    half = max(2.5, pf.width_px / 2 + 1)
    n_along = max(int(pf.t_end_px - pf.t_start_px), 2 * block_px)
    vals, e, t = across(image, pf, int(np.ceil(window + 6)), n_along, top)
    # Pixel noise from differences along the mark (its groove and the background's smooth
    # relief cancel there; a crossing groove changes slowly).
    d = np.diff(vals, axis=0)
    d = d[np.isfinite(d)]
    noise = 1.4826 * float(median_inplace(np.abs(d - median(d)))) / np.sqrt(2) if d.size else 0.0
    sigma = 1.25 * noise / np.sqrt(block_px)
    profs, ts = block_medians(vals, t, block_px)
    seen = []
    for tk, g in zip(ts, double_grooves(profs, e, pf.contrast_dn < 0, sigma, half),
                     strict=True):
        if g is None or min(abs(g[0]), abs(g[1])) > half:
            continue
        other = g[1] if abs(g[0]) <= abs(g[1]) else g[0]
        if abs(other) <= window:
            seen.append((float(tk), other))
    if len(seen) < 2:
        return []
    ts, es = np.array(seen).T
    slope = np.polyfit(ts, es, 1)[0] if np.ptp(ts) > 0 else 0.0
    if abs(slope) < np.sin(MIN_CROSSING):
        return []
    return [(tk - block_px / 2, tk + block_px / 2) for tk in ts]


def fused_error(c: MarkCandidate, where: str, shape: tuple[int, int]) -> ImageInputError:
    """The refusal of a candidate that is two grooves fused into one line (c.fused)."""
    t, sep = c.fused if c.fused is not None else (0.5 * (c.t_start_px + c.t_end_px), 0.0)
    u, n = line_frame(c.angle_rad)
    centre = np.array([(shape[1] - 1) / 2, (shape[0] - 1) / 2])
    ends = [centre + c.offset_px * n + s * u for s in (c.t_start_px, c.t_end_px)]
    x, y = centre + c.offset_px * n + t * u
    return ImageInputError(
        f"{where}: the line from pixel (x {ends[0][0]:.0f}, y {ends[0][1]:.0f}) to (x "
        f"{ends[1][0]:.0f}, y {ends[1][1]:.0f}) is two grooves (marks crossing at a shallow "
        f"angle, or side by side: {sep:.0f} px apart near (x {x:.0f}, y {y:.0f})) that cannot "
        "be measured apart; not measured")
