"""Opaque things lying over grooves: dust particles and printed ink, rendered exactly.

A particle or an ink stroke on the surface replaces the reflectance under it (grooves
included) by its own, ``level`` (0: black, absorbing; above 1: bright, scattering into the
lens), over the fraction ``opacity`` of the light. The camera sees the product blurred:
blur(R * (1 - o M) + o M b) = blur(R) + blur(o M (b - R)), with R the sharp reflectance of the
surface (grooves), M the occluder's sharp mask. blur(R) is the scene already rendered; the
second term is computed here on a supersampled patch around the occluder (sharp grooves,
sharp mask, a Gaussian PSF by convolution, then integration over each pixel's area). This is
what an additive blob cannot render: a speck on a groove's end hides the end (the groove is
not darker under a black speck), so where the groove ends under it is unknowable from the
image.

Frame coordinates: pixels (x right, y down) relative to the image centre, as
:mod:`synth.marks`. Nothing here comes from the measurement packages.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter

from synth.marks import MarkSpec
from synth.optics import CameraGeometry
from synth.profiles import along_profile, blurred_profile

Mask = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""Sharp occluder mask (0..1) at points (x, y) of the frame [px, relative to the centre]."""


@dataclass(frozen=True)
class Occluder:
    """One opaque thing over the surface.

    ``mask``: its sharp coverage at frame points; ``box``: (x0, y0, x1, y1) [px, relative to
    the centre] that holds it; ``level``: its reflectance (relative to the surface's 1);
    ``opacity``: fraction of the surface's light it blocks (1: fully opaque)."""

    mask: Mask
    box: tuple[float, float, float, float]
    level: float = 0.0
    opacity: float = 1.0


def disk(x0: float, y0: float, r: float, level: float = 0.0, opacity: float = 1.0
         ) -> Occluder:
    """A round particle of radius ``r`` [px] centred at (x0, y0) [px, from the centre]."""
    return Occluder(lambda x, y: (np.hypot(x - x0, y - y0) <= r).astype(float),
                    (x0 - r, y0 - r, x0 + r, y0 + r), level, opacity)


def strokes(segs: Sequence[tuple[np.ndarray, np.ndarray]], width: float, level: float = 0.0,
            opacity: float = 1.0) -> Occluder:
    """Printed ink: straight strokes (p0, p1) [px, from the centre] of ``width`` [px]."""
    segs = [(np.asarray(p0, float), np.asarray(p1, float)) for p0, p1 in segs]
    pts = np.array([p for s in segs for p in s])
    h = width / 2

    def mask(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.zeros(np.broadcast(x, y).shape, bool)
        for p0, p1 in segs:
            d = p1 - p0
            L = float(np.hypot(*d))
            u = d / L if L > 0 else np.array([1.0, 0.0])
            t = (x - p0[0]) * u[0] + (y - p0[1]) * u[1]
            e = -(x - p0[0]) * u[1] + (y - p0[1]) * u[0]
            out |= (t >= 0) & (t <= L) & (np.abs(e) <= h)
        return out.astype(float)

    return Occluder(mask, (pts[:, 0].min() - h, pts[:, 1].min() - h, pts[:, 0].max() + h,
                           pts[:, 1].max() + h), level, opacity)


def sharp_reflectance(marks: Sequence[MarkSpec], camera: CameraGeometry, x: np.ndarray,
                      y: np.ndarray) -> np.ndarray:
    """The surface's reflectance before the blur at frame points (grooves: 1 + contrast x
    depth)."""
    sx, sy = camera.sensor_to_scene(x, y)
    r = np.ones(np.shape(x))
    for m in marks:
        a = m.angle_rad
        e = sx * np.sin(a) + sy * np.cos(a) - m.offset_px
        t = sx * np.cos(a) - sy * np.sin(a) - m.centre_t_px
        r += m.contrast * blurred_profile(m.profile, m.width_px, 0.0)(e) * \
            along_profile(m.length_px, 0.0)(t)
    return r


def occlude(refl: np.ndarray, occluders: Sequence[Occluder], marks: Sequence[MarkSpec],
            blur_px: float, camera: CameraGeometry | None = None, supersample: int = 8
            ) -> None:
    """Add the occluders to ``refl`` (the blurred, pixel-integrated reflectance of the
    surface, modified in place): blur(o M (b - R)) on a supersampled patch per occluder."""
    camera = camera or CameraGeometry()
    h, w = refl.shape
    cx, cy = (w - 1) / 2, (h - 1) / 2
    ss = supersample
    pad = 5 * max(blur_px, 0.3) + 2
    for oc in occluders:
        x0, y0, x1, y1 = oc.box
        c0, c1 = int(max(0, np.floor(x0 - pad + cx))), int(min(w, np.ceil(x1 + pad + cx) + 1))
        r0, r1 = int(max(0, np.floor(y0 - pad + cy))), int(min(h, np.ceil(y1 + pad + cy) + 1))
        if c1 <= c0 or r1 <= r0:
            continue
        off = (np.arange(ss) + 0.5) / ss - 0.5
        xs = (np.arange(c0, c1)[:, None] + off[None, :]).ravel() - cx
        ys = (np.arange(r0, r1)[:, None] + off[None, :]).ravel() - cy
        X, Y = np.meshgrid(xs, ys)
        # Only the grooves near the patch matter (their sharp depth is 0 elsewhere).
        near = [m for m in marks if _near_box(m, camera, (xs[0], ys[0], xs[-1], ys[-1]))]
        delta = oc.opacity * oc.mask(X, Y) * (oc.level - sharp_reflectance(near, camera, X, Y))
        if blur_px > 0:
            delta = gaussian_filter(delta, blur_px * ss, mode="constant", truncate=5.0)
        refl[r0:r1, c0:c1] += delta.reshape(r1 - r0, ss, c1 - c0, ss).mean(axis=(1, 3))


def _near_box(m: MarkSpec, camera: CameraGeometry, box: tuple[float, ...]) -> bool:
    """Whether a groove can reach the box (by its scene extent; a generous test)."""
    x0, y0, x1, y1 = box
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
    sx, sy = camera.sensor_to_scene(corners[:, 0], corners[:, 1])
    a = m.angle_rad
    e = sx * np.sin(a) + sy * np.cos(a) - m.offset_px
    t = sx * np.cos(a) - sy * np.sin(a) - m.centre_t_px
    reach_e = m.width_px / 2 + 1
    reach_t = m.length_px / 2 + 1
    return bool(e.min() < reach_e and e.max() > -reach_e
                and t.min() < reach_t and t.max() > -reach_t)
