"""The background beside a mark: its slope across the mark per segment, from a ring of pixels
outside the band (used by the profile fit and by the texture's replicas alike)."""

from __future__ import annotations

import numpy as np

from imaging.groupsum import GroupSums


def ring_geometry(e: np.ndarray, seg: np.ndarray, nseg: int) -> tuple:
    """What :func:`ring_slope` needs of the ring's pixels besides their values: per segment
    the pixel count, each pixel's e less its segment's mean e [px], their sum of squares
    [px^2], and the per-segment sums (:class:`imaging.groupsum.GroupSums`). The same for
    every replica of a ring whose pixels are all usable (computed once)."""
    bc = GroupSums(seg, nseg, eager=True)  # (2 sums, 3 more per replica of the ring)
    no = bc.counts
    me = bc(e) / np.maximum(no, 1)
    ec = e - me[seg]
    return no, ec, bc(ec**2), bc


def ring_slope(vals: np.ndarray, e: np.ndarray, seg: np.ndarray, nseg: int,
               full_scale: float,
               geometry: tuple | None = None, usable: np.ndarray | bool | None = None
               ) -> np.ndarray:
    """Background slope across the mark [DN/px] per segment from its ring pixels (clipped
    pixels left out; 0 where a segment has too few). ``geometry``: :func:`ring_geometry` of
    (e, seg), used when no pixel is left out; ``usable``: the pixels not clipped, when the
    caller has them (True: all; a pixel it zeroed is clipped too)."""
    sel = (vals < full_scale) & (vals > 0) if usable is None else usable
    if geometry is None or not np.all(sel):
        sel = np.broadcast_to(sel, vals.shape)  # (``usable`` may be True: all of them)
        vals, e, seg = vals[sel], e[sel], seg[sel]
        geometry = ring_geometry(e, seg, nseg)
    no, ec, see, bc = geometry
    mr = bc(vals) / np.maximum(no, 1)
    ser = bc(ec * (vals - mr[seg]))
    return np.where(see > 0, ser / np.maximum(see, 1e-12), 0.0)
