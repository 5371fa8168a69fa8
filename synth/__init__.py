"""Synthetic data with known truth, independent of the measurement packages.

``synth`` imports nothing from ``imaging``, ``goniometry`` or ``align``: it renders physics
(optics, sensor noise) so that the pipeline can be checked against an independent truth.
"""

from synth.marks import (
    ImageSpec,
    ImageTruth,
    MarkSpec,
    MarkTruth,
    SynthImage,
    crlb,
    full_well_for_snr,
    render_marks,
    write_image,
    write_synth,
)
from synth.optics import CameraGeometry, wrap_half_turn

__all__ = [
    "CameraGeometry", "ImageSpec", "ImageTruth", "MarkSpec", "MarkTruth", "SynthImage", "crlb",
    "full_well_for_snr", "render_marks", "wrap_half_turn", "write_image", "write_synth",
]
