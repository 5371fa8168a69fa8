"""The background beside a mark: its slope across the mark per segment, from a ring of pixels
outside the band (used by the profile fit and by the texture's replicas alike)."""

from __future__ import annotations

import numpy as np


def ring_geometry(e: np.ndarray, seg: np.ndarray, nseg: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :func:`ring_slope` needs of the ring's pixels besides their values: per segment
    the pixel count, each pixel's e less its segment's mean e [px], and their sum of squares
    [px^2]. The same for every replica of a ring whose pixels are all usable (computed once)."""
    no = np.bincount(seg, minlength=nseg)
    me = np.bincount(seg, e, minlength=nseg) / np.maximum(no, 1)
    ec = e - me[seg]
    return no, ec, np.bincount(seg, ec**2, minlength=nseg)


def ring_slope(vals: np.ndarray, e: np.ndarray, seg: np.ndarray, nseg: int,
               full_scale: float,
               geometry: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Background slope across the mark [DN/px] per segment from its ring pixels (clipped
    pixels left out; 0 where a segment has too few). ``geometry``: :func:`ring_geometry` of
    (e, seg), used when no pixel is left out."""
    sel = (vals < full_scale) & (vals > 0)
    if geometry is None or not sel.all():
        vals, e, seg = vals[sel], e[sel], seg[sel]
        geometry = ring_geometry(e, seg, nseg)
    no, ec, see = geometry
    mr = np.bincount(seg, vals, minlength=nseg) / np.maximum(no, 1)
    ser = np.bincount(seg, ec * (vals - mr[seg]), minlength=nseg)
    return np.where(see > 0, ser / np.maximum(see, 1e-12), 0.0)
