"""Gratings beside measured marks (imaging.grating, through align.marks.measure_image): named
with their pitch, direction and pixel region; nothing named beside a lone mark nor for a
ruled scale whose graduations were measured as a family."""

from __future__ import annotations

import re

import numpy as np

from align.marks import measure_image
from align.warnings import mark_warnings
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from synth.grating import GratingSpec


def _scene(grating: GratingSpec | None, seed: int = 1) -> np.ndarray:
    marks = (MarkSpec(grating.line_angle_rad if grating else 0.3, -120.0, 400.0, 4.0,
                      contrast=-0.6),) + (grating.marks() if grating else ())
    spec = ImageSpec(marks=marks, width=800, height=600, blur_px=1.5, bits=8, seed=seed,
                     full_well_e=full_well_for_snr(40, -0.5), dust=10)
    return render_marks(spec, with_crlb=False).image


def test_grating_beside_a_mark_is_named_with_its_region():
    """A 150 x 150 px grating (8 px pitch) beside a 400 px scribe mark: the mark measured,
    the grating named in the warnings with its pitch, direction and a pixel box that holds
    its middle."""
    g = GratingSpec(pitch_px=8.0, line_angle_rad=0.3, length_px=150.0, span_px=150.0,
                    offset_px=150.0)
    res = measure_image(_scene(g))
    assert [r.found for r in res] == [True]
    said = [w for w in mark_warnings(res) if "a grating" in w]
    assert len(said) == 1, said
    m = re.search(r"pitch ([\d.]+) px, lines at ([-\d.]+)°, in pixels x (\d+)–(\d+), "
                  r"y (\d+)–(\d+)", said[0])
    assert m is not None, said[0]
    pitch, ang, x0, x1, y0, y1 = (float(v) for v in m.groups())
    assert abs(pitch - 8.0) < 0.3 and abs(ang - np.rad2deg(0.3)) < 1.0
    # The grating's middle: offset 150 px along the normal (sin a, cos a) from the centre.
    cx, cy = 399.5 + 150 * np.sin(0.3), 299.5 + 150 * np.cos(0.3)
    assert x0 <= cx <= x1 and y0 <= cy <= y1


def test_no_grating_beside_a_lone_mark():
    """(A measured scale's ruling is not named either: tests/imaging/test_families.py,
    test_family_block_saved_validated_and_read_back.)"""
    res = measure_image(_scene(None))
    assert res[0].found and not any("grating" in w for w in mark_warnings(res))
