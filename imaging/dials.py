"""Dials: lines of one image that meet at a point, radially (a graduated dial's
graduations), found among the search's lines (:func:`group_dial`); :mod:`imaging.families`
completes them and reports them with the families.

Geometry as in :mod:`imaging.detect` (pixels relative to the image centre; angles [rad]).
"""

from __future__ import annotations

import numpy as np

from imaging.detect import MarkCandidate, line_frame, wrap_angle


def line_middle(c: MarkCandidate) -> np.ndarray:
    """A candidate's middle (x, y) [px, relative to the image centre]."""
    u, n = line_frame(c.angle_rad)
    return c.offset_px * n + 0.5 * (c.t_start_px + c.t_end_px) * u


MIN_DIAL = 4
"""Fewest lines meeting at one point that make a dial."""
DIAL_ANGLE = np.deg2rad(1.0)
"""Direction error of a detected line (short lines: ~0.5 deg): how far it may miss the
dial's centre is this angle times its distance from it, plus :data:`DIAL_MISS_PX`."""
DIAL_MISS_PX = 3.0
DIAL_PROPOSERS = 40
"""The strongest lines whose pairs propose a dial's centre."""
DIAL_MIN_STEP = np.deg2rad(2.0)
"""Smallest angle between a dial's neighbouring graduations."""
DIAL_MAX_SKIP = 3.0
"""Most steps per gap on average (a dial may miss some graduations, not most)."""
DIAL_MIN_SPREAD = np.deg2rad(6.0)
"""Least spread of a dial's directions: parallel lines "meet" anywhere along their normal
(3 times a family's direction tolerance, :data:`imaging.families.FAMILY_ANGLE`)."""


def meets(c: MarkCandidate, p: np.ndarray) -> tuple[bool, float]:
    """Whether a line runs radially from point p (its line passes near p, and p lies beyond
    the segment's end, not on it): (meets, distance of its middle from p [px])."""
    u, n = line_frame(c.angle_rad)
    mid = line_middle(c)
    r = float(np.hypot(*(mid - p)))
    miss = abs(float(p @ n) - c.offset_px)
    along = abs(float((mid - p) @ u))
    return (miss < DIAL_MISS_PX + r * np.tan(DIAL_ANGLE) and along > 0.5 * c.length_px + 5,
            r)


def dial_centre(cands: list[MarkCandidate], idx: list[int]) -> np.ndarray:
    """Least-squares point nearest to the lines ``idx`` [px, relative to the image centre]
    (each weighted by 1 / its distance from the point: the direction error's reach)."""
    p = np.zeros(2)
    for _ in range(3):
        a, b = np.zeros((2, 2)), np.zeros(2)
        for i in idx:
            n = line_frame(cands[i].angle_rad)[1]
            w = 1 / max(float(np.hypot(*(line_middle(cands[i]) - p))), 10.0) ** 2
            a += w * np.outer(n, n)
            b += w * n * cands[i].offset_px
        p = np.linalg.solve(a, b)
    return p


def group_dial(cands: list[MarkCandidate], idx: list[int]) -> list[int]:
    """The lines among ``idx`` that meet at one point, radially (a dial's graduations), at
    least :data:`MIN_DIAL` of them in at least 3 directions; [] if none.

    Every pair of lines more than 5 deg apart proposes its crossing; the crossing most lines
    run radially from wins, refined by least squares (:func:`dial_centre`)."""
    if len(idx) < MIN_DIAL:
        return []
    # Every proposal tested against every line at once (arrays over the lines); the
    # strongest DIAL_PROPOSERS lines propose (a busy photograph has hundreds of pairs).
    a = np.array([cands[q].angle_rad for q in idx])
    nrm = np.column_stack([np.sin(a), np.cos(a)])
    along = np.column_stack([np.cos(a), -np.sin(a)])
    off = np.array([cands[q].offset_px for q in idx])
    mid = np.array([line_middle(cands[q]) for q in idx])
    half = np.array([cands[q].length_px / 2 for q in idx])
    dark = np.array([cands[q].dark for q in idx])

    def meeting(p: np.ndarray, pol: bool) -> np.ndarray:
        r = np.hypot(*(mid - p).T)
        miss = np.abs(nrm @ p - off)
        return ((dark == pol) & (miss < DIAL_MISS_PX + r * np.tan(DIAL_ANGLE))
                & (np.abs(np.sum((mid - p) * along, axis=1)) > half + 5))

    best = np.zeros(len(idx), bool)
    prop = sorted(range(len(idx)), key=lambda k: -cands[idx[k]].strength)[:DIAL_PROPOSERS]
    for x, k in enumerate(prop):
        for j in prop[x + 1:]:
            if dark[j] != dark[k]:
                continue
            m = nrm[[k, j]]
            if abs(np.linalg.det(m)) < np.sin(np.deg2rad(5.0)):
                continue
            got = meeting(np.linalg.solve(m, off[[k, j]]), bool(dark[k]))
            if got.sum() > best.sum():
                best = got
    if best.sum() < MIN_DIAL:
        return []
    best = [idx[k] for k in np.flatnonzero(best)]
    p = dial_centre(cands, best)
    best = [q for q in idx if cands[q].dark == cands[best[0]].dark and meets(cands[q], p)[0]]
    dirs = np.array([wrap_angle(cands[q].angle_rad) for q in best])
    # At least 3 distinct directions (parallel lines "meet" anywhere along their normal).
    if len(best) < MIN_DIAL or np.ptp(np.sort(dirs)) < DIAL_MIN_SPREAD:
        return []
    # Ordered round the centre.
    theta = np.array([np.arctan2(-(m[1] - p[1]), m[0] - p[0])
                      for m in (line_middle(cands[q]) for q in best)])
    order = np.argsort(theta)
    # A graduation: neighbours at least DIAL_MIN_STEP apart, few steps missing. Lines that
    # merely converge (a photograph's vanishing point) are spaced anyhow.
    th = theta[order]
    gaps = np.diff(np.append(th, th[0] + 2 * np.pi))
    gaps = np.delete(gaps, np.argmax(gaps))  # the open side of a partial dial
    g0 = float(np.min(gaps))
    steps = np.rint(gaps / g0)
    if (g0 < DIAL_MIN_STEP or np.sum(steps) > DIAL_MAX_SKIP * len(gaps)
            or np.max(np.abs(gaps / g0 - steps)) > 0.25):
        return []
    return [best[k] for k in order]
