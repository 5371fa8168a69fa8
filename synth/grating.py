"""Synthetic images of a grating: many fine parallel grooves at a uniform pitch, with truth.

A ruled grating (or a fine scale's dense rulings) is a row of equal straight grooves, their
width a fraction of the pitch, seen through the optics' Gaussian PSF: at pitch ~ 4 blur
widths or less the image is near-sinusoidal. Rendered by :func:`synth.marks.render_marks`
(each groove integrated over the pixel area, shot and read noise, quantisation). Lengths in
pixels, angles in radians (from +x towards -y). Nothing here comes from the measurement
packages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.marks import ImageSpec, MarkSpec, SynthImage, full_well_for_snr, render_marks


@dataclass(frozen=True)
class GratingSpec:
    """One grating image: ``pitch_px`` between grooves [px], ``duty`` groove width / pitch,
    ``length_px`` each groove's length [px], ``line_angle_rad`` their direction [rad],
    ``blur_px`` the PSF's sigma [px], ``snr`` contrast / noise, ``contrast`` (negative:
    dark grooves), frame, bits and seed as :class:`synth.marks.ImageSpec`; ``offset_px``
    and ``centre_t_px`` move the grating from the frame's centre across and along its lines
    [px] (beside a scribe mark: :meth:`marks` into an :class:`~synth.marks.ImageSpec` with
    the mark's)."""

    pitch_px: float = 8.0
    duty: float = 0.5
    length_px: float = 200.0
    line_angle_rad: float = np.pi / 2
    span_px: float = 300.0
    blur_px: float = 1.5
    snr: float = 40.0
    contrast: float = -0.5
    width: int = 640
    height: int = 480
    bits: int = 8
    seed: int = 0
    offset_px: float = 0.0
    centre_t_px: float = 0.0

    def marks(self) -> tuple[MarkSpec, ...]:
        """The grooves, centred on the frame across ``span_px``."""
        n = int(self.span_px // self.pitch_px) + 1
        offs = (np.arange(n) - (n - 1) / 2) * self.pitch_px + self.offset_px
        return tuple(MarkSpec(self.line_angle_rad, float(o), self.length_px,
                              self.duty * self.pitch_px, self.centre_t_px, "box",
                              self.contrast)
                     for o in offs)


def render_grating(spec: GratingSpec) -> SynthImage:
    """Render the grating (its truth: one :class:`synth.marks.MarkTruth` per groove)."""
    img = ImageSpec(marks=spec.marks(), width=spec.width, height=spec.height,
                    blur_px=spec.blur_px, full_well_e=full_well_for_snr(spec.snr, spec.contrast),
                    bits=spec.bits, supersample=4, seed=spec.seed)
    return render_marks(img, with_crlb=False)
