"""Which other lines run beside a mark: kept out of its texture's replicas
(:mod:`imaging.texture`), which would read their grooves as the surface's texture."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.candidate import MarkCandidate, line_frame, wrap_angle


def neighbours(cands: Sequence[MarkCandidate], i: int, tol_angle: float = np.deg2rad(5),
               reach_px: float = 40.0) -> tuple[float, ...]:
    """Signed distances along candidate i's normal of the other candidates that run beside it
    [px]: those within ``tol_angle`` of its direction overlapping it along its length (their
    middle's distance), and those at a larger angle that pass beside it without crossing it
    (every 2 px of their distance over the stretch they share, out to ``reach_px`` past the
    candidate's ends, where its centres may reach: :func:`imaging.ends.centres_stretch`).
    A dial's radial neighbours, 15 deg apart, came within 23 px of a graduation's inner end
    once its centres ran there: the texture's replicas lay on their grooves over a dozen
    segments and read them as texture (u x4-5 on 100 px lines, the dial's chi2/dof 0.05)."""
    c = cands[i]
    u, n = line_frame(c.angle_rad)
    out = []
    for j, o in enumerate(cands):
        if j == i:
            continue
        uo, no = line_frame(o.angle_rad)
        if abs(wrap_angle(o.angle_rad - c.angle_rad)) >= tol_angle:
            ts = np.arange(o.t_start_px, o.t_end_px + 1.0, 2.0)
            pts = o.offset_px * no + ts[:, None] * uo
            tt, dd = pts @ u, pts @ n - c.offset_px
            near = (tt >= c.t_start_px - reach_px) & (tt <= c.t_end_px + reach_px)
            d = dd[near]
            if d.size and (np.all(d > 0) or np.all(d < 0)):  # beside it, not across it
                out.extend(float(x) for x in np.unique(np.round(d)))
            continue
        ends = [o.offset_px * no + t * uo for t in (o.t_start_px, o.t_end_px)]
        ts = sorted(float(p @ u) for p in ends)
        if ts[1] < c.t_start_px or ts[0] > c.t_end_px:
            continue
        mid = o.offset_px * no + 0.5 * (o.t_start_px + o.t_end_px) * uo
        out.append(float(mid @ n) - c.offset_px)
    return tuple(out)
