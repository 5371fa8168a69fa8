"""The declared grid-phase term (``align/grid_phase.py``, ``--blur-after-pixels``).

user6's frame-edge marks blurred after the pixels, with and without the declaration, are in
``tests/align/test_independent_user6.py``; here: what the term does to marks it should not
touch, and that it only widens u."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from align import LensRanges, measure_image, with_grid_phase
from align.grid_phase import TERM, sharp_fraction
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks


def _marks(angle_deg: float, seed: int = 1):
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(angle_deg), 5.0, 200.0, 4.0, contrast=-0.6),),
                     width=320, height=240, full_well_e=full_well_for_snr(50, -0.6), seed=seed)
    return measure_image(render_marks(spec, with_crlb=False).image, ranges=LensRanges.none())


def test_a_mark_crossing_many_phase_cycles_is_left_alone():
    """5 deg on 200 px is 17 phase cycles: the grid's phase averages out, term 0, u as it was,
    no note."""
    (r,) = _marks(5.0)
    (d,) = with_grid_phase([r])
    assert d.u_terms[TERM] == 0.0 and d.angle_u_rad == r.angle_u_rad and d.notes == r.notes


def test_a_near_axis_mark_only_gains_u_and_a_note():
    """0.2 deg on 200 px (0.7 cycles): the angle is the same, u = hypot(u, term) > u, the
    note says what was declared."""
    (r,) = _marks(0.2)
    (d,) = with_grid_phase([r])
    t = d.u_terms[TERM]
    assert t > 0 and d.angle_rad == r.angle_rad
    assert d.angle_u_rad == pytest.approx(np.hypot(r.angle_u_rad, t), rel=1e-12)
    assert any("blurred after the pixels (declared)" in n for n in d.notes), d.notes


def test_a_failed_entry_passes_unchanged():
    (r,) = measure_image(np.full((120, 160), 2000, np.uint16), "blank.png")
    assert not r.found and with_grid_phase([r]) == [r]


@pytest.mark.parametrize("angle", [0.0, np.deg2rad(0.3), np.deg2rad(20.0), np.deg2rad(45.0)])
def test_sharp_fraction_integrates_the_strip_exactly(angle):
    """Against a 400 x 400 sub-pixel count: each pixel's covered fraction, and the band's
    total = the width (per unit length), at any angle."""
    _, n = np.cos(angle), np.array([-np.sin(angle), np.cos(angle)])
    e = np.linspace(-4.0, 4.0, 41)
    got = sharp_fraction(e, 3.0, angle)
    s = (np.arange(400) + 0.5) / 400 - 0.5
    sx, sy = np.meshgrid(s, s)
    d = sx * n[0] + sy * n[1]   # sub-pixel's distance from the pixel centre along the normal
    want = [np.mean(np.abs(ei + d) <= 1.5) for ei in e]
    assert np.allclose(got, want, atol=5e-3)


@pytest.mark.slow  # a whole session (~3 s); its key's parsing is in test_bad_inputs
def test_a_session_camera_declared_blurred_after_its_pixels_carries_the_term(session21, tmp_path):
    """``[cameras.A] blur_after_pixels = true`` in session.toml is ``--blur-after-pixels`` for
    camera A's images: their near-axis marks carry ``grid_phase``, camera B's do not."""
    from align.session import load_session, run_session

    folder = tmp_path / "unit7"
    shutil.copytree(session21, folder)
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace("[cameras.A]\n", "[cameras.A]\nblur_after_pixels"
                                             " = true\n", 1))
    s = load_session(folder)
    marks = run_session(s).marks
    term = {cam: [r.u_terms.get(TERM, 0.0) for im, r in marks if s.views[im.view].camera == cam]
            for cam in ("A", "B")}
    assert term["A"] and max(term["A"]) > 0, term
    assert term["B"] and max(term["B"]) == 0, term
