"""Where another mark crosses a mark: the stretch left out of its fit, or a clear refusal.

Separate from :mod:`imaging.crossing` (pure geometry, imported by the detector) because it
needs the groove's fitted profile window (:mod:`imaging.profile`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.crossing import crossing_stretch
from imaging.detect import MarkCandidate, line_frame, wrap_angle
from imaging.errors import ImageInputError
from imaging.profile import Centres, ProfileFit, centres_half

CROSSING_MAX_SHARE = 2 / 3
"""A mark whose length lies this much inside crossing marks' grooves is not measured."""


def crossing_skip(cen: Centres, pf: ProfileFit, crossing: Sequence[tuple[int, MarkCandidate]],
                  shape: tuple[int, int], where: str
                  ) -> tuple[np.ndarray | None, tuple[tuple[int, int], ...]]:
    """Segments of a mark over which another mark's groove lies inside its centres' band.

    There the fitted centre is pulled towards the other groove (at a shallow crossing over a
    long stretch: 2 (band + the other's half-width) / sin(angle) px), so those segments are
    left out of the fit. When they are most of the mark (:data:`CROSSING_MAX_SHARE`) the two
    cannot be told apart: an ImageInputError naming the pixel region.

    Returns (skip mask or None, ((other index, px left out), ...)).
    """
    if not crossing:
        return None, ()
    skip = np.zeros(len(cen.t), bool)
    crossed = []
    centre = np.array([(shape[1] - 1) / 2, (shape[0] - 1) / 2])
    for j, o in crossing:
        got = crossing_stretch(pf, o, centres_half(pf) + o.thickness_px / 2 + 1)
        if got is None:
            continue
        t0, t1, at = got
        share = (t1 - t0) / max(pf.t_end_px - pf.t_start_px, 1e-9)
        if share > CROSSING_MAX_SHARE:
            x, y = centre + at
            angle = np.rad2deg(abs(wrap_angle(o.angle_rad - pf.angle_rad)))
            raise ImageInputError(
                f"{where}: mark at offset {pf.offset_px:.0f} px crosses mark {j} near pixel "
                f"(x {x:.0f}, y {y:.0f}) at {angle:.1f}°: their grooves overlap over "
                f"{t1 - t0:.0f} of its {pf.t_end_px - pf.t_start_px:.0f} px; the two "
                "cannot be measured apart")
        skip |= (cen.t >= t0) & (cen.t <= t1)
        crossed.append((j, int(round(t1 - t0))))
    return skip, tuple(crossed)


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
