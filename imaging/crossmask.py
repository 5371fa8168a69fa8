"""Where another mark crosses a mark: the stretch left out of its fit, or a clear refusal.

Separate from :mod:`imaging.crossing` (pure geometry, imported by the detector) because it
needs the groove's fitted profile window (:mod:`imaging.profile`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.candidate import MarkCandidate, line_frame
from imaging.centres import Centres
from imaging.confirm import across, block_medians
from imaging.crossing import MIN_CROSSING, crossing_stretch, double_groove
from imaging.errors import ImageInputError
from imaging.groove import ProfileFit, centres_half

MIN_SEGMENTS = 10
"""Fewest centres a mark's fit is made from (as :func:`imaging.measure._usable` asks)."""
CROSSING_MAX_SHARE = 0.75
"""A mark whose length lies more than this inside crossing marks' grooves is not measured
(what is left, at most two short stretches at its ends, no longer shows whether they agree)."""


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
        got = crossing_stretch(pf, o, centres_half(pf) + o.thickness_px / 2 + 1, extend=True)
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
    for tk, prof in zip(ts, profs, strict=True):
        g = double_groove(prof, e, pf.contrast_dn < 0, sigma, half)
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
