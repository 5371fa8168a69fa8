"""Gratings beside measured marks (imaging.grating, through align.marks.measure_image): named
with their pitch, direction and pixel region; nothing named beside a lone mark nor for a
ruled scale whose graduations were measured as a family."""

from __future__ import annotations

import re

import numpy as np

from align.marks import measure_image
from align.warnings import mark_warnings
from imaging import line_frame
from imaging.grating import explained_by_ruling, grating_regions
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


def test_a_measured_rulings_harmonics_are_no_grating():
    """A coarse ruling (7 lines, 65.6 px pitch, about the tiles' 64 px reach) shows in the
    tiles as a grating at its pitch or a harmonic of it (user 16: 30 of 64 fully measured
    micrometer frames drew one at 1/2, 1/4 or 1/5 of their pitch): with the measured
    family's pitch and direction given (``known``) none is named. A pitch that is no
    harmonic (20 px: 65.6 / 20 = 3.28), or another direction, is still another grating."""
    a = 0.4
    ruling = GratingSpec(pitch_px=65.6, duty=0.06, line_angle_rad=a, length_px=400.0,
                         span_px=6 * 65.6 + 4, offset_px=-60.0)
    spec = ImageSpec(marks=ruling.marks(), width=1024, height=768, blur_px=1.5, bits=8,
                     seed=3, full_well_e=full_well_for_snr(40, -0.5))
    image = render_marks(spec, with_crlb=False).image
    u, n = line_frame(a)
    c = np.array([511.5, 383.5])
    segs = [np.array([c + q * n - 200 * u, c + q * n + 200 * u])
            for q in -60.0 + 65.6 * (np.arange(7) - 3)]
    assert grating_regions(image, segs)  # the ruling's own spectrum, named alone
    assert grating_regions(image, segs, [(65.6, a)]) == []
    # 32.8 px 3.4° off a 65.6 px ruling: a 256 px tile's bin at that pitch is 7.3° wide
    assert explained_by_ruling(32.8, a + np.deg2rad(3.4), 65.6, a)
    assert explained_by_ruling(13.1, a, 65.6, a)
    assert not explained_by_ruling(20.0, a, 65.6, a)
    assert not explained_by_ruling(32.8, a + np.deg2rad(10.0), 65.6, a)
    assert not explained_by_ruling(131.2, a, 65.6, a)  # a sub-harmonic is other structure
