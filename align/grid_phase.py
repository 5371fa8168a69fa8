"""The Type B term ``grid_phase``: an image blurred *after* its pixels, declared by the user.

The groove model blurs the groove before the pixels integrate it, as a lens does. An image
filtered on the pixel grid after capture (demosaiced, sharpened, resampled; a sensor whose
pixels leak into each other) keeps the sharp groove's detail at the pixel frequency, and a
mark within a fraction of a degree of a pixel axis (crossing < 3 cycles of the sub-pixel
phase) samples it at a slowly drifting phase: its centres move with the phase and the line
tilts (user6's rounded grooves blurred after the pixels: RMS z 1.61, max 3.15 over 16 marks
6 px from the frame's edge, 1.66 / 3.06 at the frame's centre; the same scenes blurred
before the pixels 0.82 / 2.16).

Why it is declared, not detected (``benchmarks/grid_phase.py --what oracle``): on such marks
the two orders' images differ, beyond what any physical-order groove shape explains, by
d' = 2.9-3.3 noise units at 0.4-1.4 phase cycles and < 0.2 below 0.15 cycles, so the best
possible test at 1 % false alarms finds the filter with power <= 0.70-0.82 (<= 0.02): a gate
on the image would miss it or widen every near-axis mark of a raw camera.

The term: the fitted groove rendered twice on the image's own grid, blurred before its
pixels (the model) and sharp, integrated exactly over each pixel, then blurred on the grid;
both measured with the mark's own centres (:func:`imaging.jpeg.rendering_angle_shift`); the
difference d enters as |d| / sqrt(3) (a bias anywhere within +-|d|, uniform). About 12 ms a
mark.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from align.mark_result import MarkResult
from imaging.band import band_pixels
from imaging.detect import line_frame
from imaging.groove import ProfileFit, ProfileTable, centres_half
from imaging.jpeg import rendering_angle_shift
from imaging.shape import phase_cycles

TERM = "grid_phase"
MAX_CYCLES = 3.0
"""Beyond this many sub-pixel phase cycles along the mark the phase's bias averages out."""


def _strip_cdf(c: np.ndarray, a: float, b: float) -> np.ndarray:
    """P(a U1 + b U2 <= c) for U1, U2 uniform on [-1/2, 1/2], a >= b >= 0: the fraction of
    a pixel on one side of a line at distance c [px] from its centre (normal (a, b))."""
    h, g = (a + b) / 2, (a - b) / 2
    mid = 0.5 + c / a
    if b < 1e-9:  # along a pixel axis: the quadratic corners vanish
        return np.clip(mid, 0.0, 1.0)
    lo = (c + h) ** 2 / (2 * a * b)
    hi = 1.0 - (h - c) ** 2 / (2 * a * b)
    out = np.where(c < -g, lo, np.where(c > g, hi, mid))
    return np.where(c <= -h, 0.0, np.where(c >= h, 1.0, out))


def sharp_fraction(e: np.ndarray, width_px: float, angle_rad: float) -> np.ndarray:
    """The fraction of each pixel (its centre at signed distance ``e`` [px] from the groove's
    middle line) that a sharp groove of ``width_px`` [px] covers, integrated exactly
    (closed form: no library integrates a strip over a square)."""
    _, n = line_frame(angle_rad)
    a, b = sorted((abs(float(n[0])), abs(float(n[1]))), reverse=True)
    return _strip_cdf(width_px / 2 - e, a, b) - _strip_cdf(-width_px / 2 - e, a, b)


def renderings(shape: tuple[int, int], pf: ProfileFit) -> tuple[np.ndarray, np.ndarray]:
    """The fitted groove ``pf`` on a noise-free image of ``shape`` [DN]: the model (blur,
    then pixel) and the sharp groove pixel-integrated, then blurred by the model's sigma on
    the grid."""
    model = np.full(shape, pf.background_dn, dtype=float)
    sharp = np.zeros(shape, dtype=float)
    half = centres_half(pf) + 8.0
    e, idx = band_pixels(model, pf, half, 30.0)
    p, _ = ProfileTable(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)(e)
    model.flat[idx] += pf.contrast_dn * p
    sharp.flat[idx] = pf.contrast_dn * sharp_fraction(e, pf.width_px, pf.angle_rad)
    # Blur only the box about the band (the frame's edges stay where the image has them).
    r, c = np.unravel_index(idx, shape)
    m = int(np.ceil(4 * pf.blur_px)) + 2
    r0, r1 = max(int(r.min()) - m, 0), min(int(r.max()) + m + 1, shape[0])
    c0, c1 = max(int(c.min()) - m, 0), min(int(c.max()) + m + 1, shape[1])
    sharp[r0:r1, c0:c1] = cv2.GaussianBlur(sharp[r0:r1, c0:c1], (0, 0), pf.blur_px)
    return model, sharp + pf.background_dn


def grid_phase_shift(shape: tuple[int, int], pf: ProfileFit) -> float:
    """|angle of the sharp rendering - angle of the model's| [rad] of the fitted groove
    ``pf`` on an image of ``shape`` (0 beyond :data:`MAX_CYCLES` phase cycles)."""
    if phase_cycles(pf.angle_rad, pf.t_end_px - pf.t_start_px) >= MAX_CYCLES:
        return 0.0
    model, sharp = renderings(shape, pf)
    return rendering_angle_shift(model, sharp, pf)


def with_grid_phase(results: list[MarkResult]) -> list[MarkResult]:
    """One image's marks, each with the term ``grid_phase`` [rad] in its u (the user
    declared the image blurred after its pixels, ``--blur-after-pixels``) and a note where
    it is not zero; failed entries and marks without a measurement pass unchanged."""
    out = []
    for r in results:
        m = r.measurement
        if not r.found or m is None:
            out.append(r)
            continue
        t = grid_phase_shift(m.image_shape, m.profile) / np.sqrt(3.0)
        notes = r.notes + ((f"{r.image} mark {r.index}: blurred after the pixels (declared): "
                            f"the grid's phase may tilt this near-axis mark by up to ± "
                            f"{np.rad2deg(t * np.sqrt(3.0)) * 3600:.1f}″, carried in u as "
                            f"{TERM}",) if t > 0 else ())
        out.append(replace(r, angle_u_rad=float(np.hypot(r.angle_u_rad, t)),
                           u_terms={**r.u_terms, TERM: float(t)}, notes=notes))
    return out
