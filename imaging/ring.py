"""The background beside a mark: its slope across the mark per segment, from a ring of pixels
outside the band (used by the profile fit and by the texture's replicas alike)."""

from __future__ import annotations

import numpy as np


def ring_slope(vals: np.ndarray, e: np.ndarray, seg: np.ndarray, nseg: int,
               full_scale: float) -> np.ndarray:
    """Background slope across the mark [DN/px] per segment from its ring pixels (clipped
    pixels left out; 0 where a segment has too few)."""
    sel = (vals < full_scale) & (vals > 0)
    vals, e, seg = vals[sel], e[sel], seg[sel]
    no = np.bincount(seg, minlength=nseg)
    me = np.bincount(seg, e, minlength=nseg) / np.maximum(no, 1)
    mr = np.bincount(seg, vals, minlength=nseg) / np.maximum(no, 1)
    see = np.bincount(seg, (e - me[seg]) ** 2, minlength=nseg)
    ser = np.bincount(seg, (e - me[seg]) * (vals - mr[seg]), minlength=nseg)
    return np.where(see > 0, ser / np.maximum(see, 1e-12), 0.0)
