"""Where another mark crosses a mark: the stretch left out of its fit, or a clear refusal.

Separate from :mod:`imaging.crossing` (pure geometry, imported by the detector) because it
needs the groove's fitted profile window (:mod:`imaging.profile`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.band import _band
from imaging.candidate import MarkCandidate, line_frame
from imaging.centres import Centres
from imaging.confirm import across, block_medians
from imaging.crossing import MIN_CROSSING, crossing_stretch, double_grooves
from imaging.errors import ImageInputError
from imaging.groove import ProfileFit, centres_half

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
    for j, o in crossing:
        if o.fused is not None:  # refused itself; its grooves are the found marks'
            continue
        half = centres_half(pf) + o.thickness_px / 2 + 1
        got = crossing_stretch(pf, o, half, extend=True)
        found = crossing_stretch(pf, o, half)  # o's found part only
        if (got is not None and (found is None or found[:2] != got[:2])
                and groove_runs_on(image, pf, o, half) is False):
            # A corner: o ends where its ridge was found; only that part lies in the window.
            got = found
        if got is not None:
            stretches.append((got[0], got[1], j))
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
            out[b] = np.median(v)
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


def _probe_end(image: np.ndarray, pf: ProfileFit, o: MarkCandidate, step: float
               ) -> bool | None:
    """:func:`groove_runs_on` at o's end ``step`` (+1: its t_end, -1: its t_start)."""
    s_end = o.t_end_px if step > 0 else o.t_start_px
    half = int(np.ceil(o.thickness_px + 8))
    mask = max(4.0, pf.width_px / 2 + 2)
    inner = min(PROBE_PX, 0.5 * o.length_px)
    ref, past = (_median_profile(image, o, pf, *sorted((s_end, s_end + d)), half, mask)
                 for d in (-step * inner, step * PROBE_PX))
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
    slope = float(np.median((q[j] - q[i])[dr != 0] / dr[dr != 0]))
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
    noise = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2) if d.size else 0.0
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
