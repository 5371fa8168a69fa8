"""A groove's hidden ends checked again at the blur each end has (a defocus gradient).

The end check (:func:`imaging.ends.groove_ends`) fits every bin along the line with the
band's one blur. When the blur changes along the mark (a tilted object plane: 0.8 -> 2.5 px,
:mod:`imaging.defocus`), that profile fits neither end: the sharp end's bins and the soft
end's leave residuals and a level biased along the mark, whose trend, extrapolated past the
ends, leaves the bare surface there "not quiet" — both clean ends were read as under an
obstruction reaching the whole look (a 275 px mark "up to 826 px hidden"). A groove whose
blur is found to change along it (:attr:`imaging.defocus.BlurTrend.found`) has each
hidden end checked again with the profile at that end's own blur (the trend's, out to that
end); an end still hidden then is under something that is not the groove — dust or
print change the surface's level and misfit any groove's profile, whatever its blur.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from imaging.centres import Centres
from imaging.defocus import BlurTrend
from imaging.ends import GrooveEnds, groove_ends, groove_path
from imaging.groove import ProfileFit


def ends_at_their_blur(image: np.ndarray, pf: ProfileFit, extent: tuple[float, float],
                       cen: Centres, trend: BlurTrend | None, ends: GrooveEnds) -> GrooveEnds:
    """``ends`` with each hidden end checked again at its own blur when the mark's blur
    changes along it (see the module docstring); unchanged otherwise.

    Parameters
    ----------
    image : (H, W) array
        The image [DN].
    pf : ProfileFit
        The groove's fitted profile and line (its one blur) [px].
    extent : (t0, t1)
        Its half-depth ends [px].
    cen : Centres
        Its centres (the band follows their path).
    trend : BlurTrend or None
        The blur along the mark (:func:`imaging.defocus.blur_trend`).
    ends : GrooveEnds
        The ends checked at the band's blur (:func:`imaging.ends.checked_ends`).

    Returns
    -------
    GrooveEnds
        The ends [px along the line]; a hidden end's visible end and bound are the
        re-check's.
    """
    hidden = ends.hidden
    if trend is None or not trend.found or not any(hidden):
        return ends
    out = [(ends.start_px, ends.start_min_px), (ends.end_px, ends.end_max_px)]
    # The trend's thirds sit a sixth of the mark in from its ends: out to each end along
    # the slope (1 -> 3 px over 300 px: the thirds read 1.65 / 2.63, the ends 1.36 / 2.92;
    # at the thirds' blur the sharp end still misfit in 2 of 6 seeds).
    reach = (extent[1] - extent[0]) / 6
    for k in (0, 1):
        blur = float(trend.ends_px[k] + (2 * k - 1) * trend.slope * reach)
        if not hidden[k] or not np.isfinite(blur) or blur <= 0:
            continue
        at = replace(pf, blur_px=blur)
        e = groove_ends(image, at, extent, path=groove_path(cen, at))
        # Hidden or not at its own blur, that check's end and bound are the ones to give
        # (the band's blur's biased level leaves a real speck's far side unquiet too).
        out[k] = (e.start_px, e.start_min_px) if k == 0 else (e.end_px, e.end_max_px)
    (s, s_min), (t, t_max) = out
    if t <= s:
        return ends
    return GrooveEnds(s, t, min(s_min, s), max(t_max, t))
