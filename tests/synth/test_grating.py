"""synth.grating: grooves at the pitch asked, the image periodic across them."""

from __future__ import annotations

import numpy as np

from synth.grating import GratingSpec, render_grating


def test_grating_pitch_and_period():
    s = render_grating(GratingSpec(pitch_px=8.0, blur_px=1.0, width=320, height=240,
                                   span_px=160.0, length_px=100.0, seed=3))
    offs = np.array([m.offset_px for m in s.truth.marks])
    assert np.allclose(np.diff(offs), 8.0)
    # Vertical grooves: a row through the middle is periodic at 8 px (its spectrum's peak).
    row = s.image[120, 80:240].astype(float)
    spec = np.abs(np.fft.rfft(row - row.mean()))
    assert np.isclose(160 / np.argmax(spec), 8.0, rtol=0.02)
