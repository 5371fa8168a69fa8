"""Synthetic images of a graduated dial: radial grooves around a centre, with known truth.

A dial's graduations are straight grooves on radii of one centre, at a uniform angle
increment, every 5th longer (medium) and every 10th longer still (long), all starting on one
inner circle. Rendered by :func:`synth.marks.render_marks` (each groove integrated over the
pixel area through a Gaussian PSF, shot and read noise, quantisation, dust). Truth: the
centre [px, relative to the frame centre, x right, y down], the increment [rad] and every
graduation's direction from the centre [rad, from +x towards -y]. Nothing here comes from the
measurement packages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.marks import ImageSpec, MarkSpec, SynthImage, full_well_for_snr, render_marks
from synth.optics import wrap_half_turn


@dataclass(frozen=True)
class DialSpec:
    """One dial image: ``centre_px`` (x, y) from the frame centre [px]; graduations from
    ``first_rad`` every ``increment_rad`` [rad], ``n_lines`` of them, starting at
    ``inner_px`` from the centre, ``lengths_px`` (short, medium, long) [px];
    ``increment_error_rad`` RMS error of each graduation's direction [rad]; groove, optics
    and sensor as :class:`synth.marks.ImageSpec`."""

    centre_px: tuple[float, float] = (0.0, 0.0)
    first_rad: float = 0.1
    increment_rad: float = np.deg2rad(10.0)
    n_lines: int = 36
    inner_px: float = 120.0
    lengths_px: tuple[float, float, float] = (100.0, 120.0, 140.0)
    line_width_px: float = 4.0
    contrast: float = -0.6
    snr: float = 40.0
    increment_error_rad: float = 0.0
    blur_px: float = 1.5
    dust: int = 10
    width: int = 800
    height: int = 800
    bits: int = 12
    seed: int = 0

    def directions(self) -> np.ndarray:
        """Each graduation's direction from the centre [rad] (with its ruling error)."""
        rng = np.random.default_rng([self.seed, 2])
        k = np.arange(self.n_lines)
        return self.first_rad + k * self.increment_rad + \
            self.increment_error_rad * rng.standard_normal(self.n_lines)

    def marks(self) -> tuple[MarkSpec, ...]:
        out = []
        cx, cy = self.centre_px
        for k, th in enumerate(self.directions()):
            length = self.lengths_px[2 if k % 10 == 0 else 1 if k % 5 == 0 else 0]
            # Along the radius (cos th, -sin th) in (x right, y down); the mark's angle is
            # the radius's, wrapped to a half turn (its normal and t flip with it).
            a = wrap_half_turn(float(th))
            u = np.array([np.cos(a), -np.sin(a)])
            n = np.array([np.sin(a), np.cos(a)])
            d = np.array([np.cos(th), -np.sin(th)])
            mid = np.array([cx, cy]) + (self.inner_px + length / 2) * d
            out.append(MarkSpec(a, float(mid @ n), length, self.line_width_px,
                                float(mid @ u), "round", self.contrast))
        return tuple(out)


def render_dial(spec: DialSpec) -> SynthImage:
    """Render the dial (truth: one :class:`synth.marks.MarkTruth` per graduation, in order)."""
    img = ImageSpec(marks=spec.marks(), width=spec.width, height=spec.height,
                    blur_px=spec.blur_px, full_well_e=full_well_for_snr(spec.snr, spec.contrast),
                    bits=spec.bits, supersample=4, dust=spec.dust, seed=spec.seed)
    return render_marks(img, with_crlb=False)
