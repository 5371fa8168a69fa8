"""synth: physical rendering, truth and CRLB, independence from the pipeline."""

from __future__ import annotations

import ast
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from synth import CameraGeometry, ImageSpec, MarkSpec, crlb, render_marks, write_synth
from tests.conftest import mark_image


def test_synth_imports_nothing_from_the_pipeline():
    pipeline = {"imaging", "goniometry", "align"}
    for f in (Path(__file__).resolve().parents[2] / "synth").rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            assert not any(n.split(".")[0] in pipeline for n in names), f"{f}: {names}"


def test_box_groove_area_integrates_to_its_width():
    # Summed across the mark, the coverage of a box groove equals its width (area
    # integration, not a raster line): check on the noise-free mean.
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(17.0), 3.3, 300, 5.0, profile="box",
                                     contrast=-0.5),), width=400, height=400, read_noise_e=0)
    s = render_marks(spec, with_crlb=False)
    bg = spec.exposure * spec.full_well_e
    deficit = (bg - s.mean_e) / (0.5 * bg)
    # Integrated over area: width x length (blurred ends keep their integral).
    assert deficit.sum() == pytest.approx(5.0 * 300, rel=2e-3)


def test_noise_matches_shot_plus_read():
    spec = ImageSpec(marks=(MarkSpec(0.3, 150, 50, 3.0),), width=256, height=256,
                     full_well_e=20000, read_noise_e=20, bits=16, seed=3)
    s = render_marks(spec, with_crlb=False)
    patch = s.image[:100, :100].astype(float) * spec.full_well_e / 65535
    expected = np.sqrt(spec.exposure * spec.full_well_e + 20**2)
    assert patch.std() == pytest.approx(expected, rel=0.05)


@pytest.mark.slow  # three renders with their Fisher information (~2 s CPU)
def test_crlb_scales_inversely_with_snr_and_length():
    a = mark_image(10, 0, snr=20, with_crlb=True).truth.marks[0].crlb_angle_rad
    b = mark_image(10, 0, snr=40, with_crlb=True).truth.marks[0].crlb_angle_rad
    c = mark_image(10, 0, snr=20, length_px=250, with_crlb=True).truth.marks[0].crlb_angle_rad
    assert b == pytest.approx(a / 2, rel=0.05)
    # Angle information grows as length^3 (slope of a line): halving it costs 2^1.5.
    assert c == pytest.approx(a * 2**1.5, rel=0.1)


def test_crlb_with_k1_free_costs_only_off_the_centre():
    """A line through the principal point stays straight and unturned under k1: freeing k1
    costs its angle nothing. Off the centre (its middle off the foot of the perpendicular)
    the bow and the turn at its middle share k1, and the bound grows."""
    cam = CameraGeometry(focal_px=512.0, k1=-0.3)

    def bounds(offset: float, along: float) -> tuple[float, float]:
        spec = ImageSpec(marks=(MarkSpec(0.3, offset, 200.0, 4.0, centre_t_px=along),),
                         width=320, height=240, camera=cam, supersample=1)
        return crlb(spec)[0], crlb(spec, free_k1=True)[0]

    fixed, free = bounds(0.0, 0.0)
    assert free == pytest.approx(fixed, rel=0.01)
    fixed, free = bounds(70.0, 40.0)
    assert free > 1.1 * fixed


def test_truth_angle_follows_camera_roll():
    roll = np.deg2rad(30 / 3600)
    spec = ImageSpec(marks=(MarkSpec(0.2, 0, 300),), width=400, height=300,
                     camera=CameraGeometry(roll_rad=roll))
    t = render_marks(spec, with_crlb=False).truth.marks[0]
    assert t.image_angle_rad - t.angle_rad == pytest.approx(roll, rel=1e-6)


def test_eight_and_sixteen_bit_files_and_no_overwrite(tmp_path):
    for bits, suffix in ((8, ".png"), (16, ".tif"), (16, ".png")):
        spec = ImageSpec(marks=(MarkSpec(0.1, 0, 200),), width=300, height=200, bits=bits)
        s = render_marks(spec, with_crlb=False)
        p, truth = write_synth(s, tmp_path / f"m{bits}{suffix}")
        assert p.exists() and truth.exists()
        assert s.image.dtype == (np.uint8 if bits == 8 else np.uint16)
        with pytest.raises(FileExistsError):
            write_synth(s, p)


def test_crlb_rejects_nothing_silently():
    spec = ImageSpec(marks=(MarkSpec(0.1, 0, 200),), width=300, height=200)
    a, d = crlb(spec)
    assert 0 < a < 1e-3 and 0 < d < 0.1
    with pytest.raises(ValueError):
        render_marks(ImageSpec(marks=(MarkSpec(0.1, 0, 200, profile="zigzag"),), width=64,
                               height=64))


def test_defocus_gradient_widens_the_groove_along_the_mark():
    """blur_gradient: the PSF's sigma grows along x; the groove's second moment across the
    mark grows with it (width^2/12 + sigma^2 for a box), measured on the noise-free mean."""
    g = 2.0 / 400
    spec = ImageSpec(marks=(MarkSpec(np.pi / 2, 0.0, 60, 4.0, profile="box", contrast=-0.5),),
                     width=440, height=120, read_noise_e=0, blur_px=2.0,
                     blur_gradient=(g, 0.0))
    bg = spec.exposure * spec.full_well_e
    for x in (-150.0, 0.0, 150.0):
        # A vertical mark at x: rendered as its own image, the blur there is 2 + g x.
        s = render_marks(_vertical_at(spec, x), with_crlb=False)
        prof = (bg - s.mean_e[50:70].mean(axis=0)) / (0.5 * bg)
        cols = np.arange(prof.size) - (spec.width - 1) / 2 - x
        m2 = (prof * cols**2).sum() / prof.sum()
        assert m2 == pytest.approx(4.0**2 / 12 + (2.0 + g * x) ** 2 + 1 / 12, rel=0.03)


def _vertical_at(spec: ImageSpec, x: float) -> ImageSpec:
    return spec.with_marks(MarkSpec(np.pi / 2, x, 60, 4.0, profile="box", contrast=-0.5))


def test_fixed_pattern_noise_is_fixed_per_column_and_row():
    """column_fpn / row_fpn: offsets of the stated rms (fraction of the surface signal), the
    same in every row (column), and the other random draws left as they were."""
    base = ImageSpec(marks=(MarkSpec(0.3, 0, 50, 3.0),), width=300, height=200,
                     full_well_e=2e5, read_noise_e=0, seed=4)
    plain = render_marks(base, with_crlb=False).image.astype(float)
    cols = render_marks(replace(base, column_fpn=0.02), with_crlb=False).image.astype(float)
    d = (cols - plain)[:, 100:]  # the mark is in the left part
    gain = 65535 / base.full_well_e
    signal = base.exposure * base.full_well_e * gain
    assert np.std(d.mean(axis=0)) == pytest.approx(0.02 * signal, rel=0.15)
    assert np.max(np.std(d, axis=0)) < 1.0  # the same in every row (rounding only)
    rows = render_marks(replace(base, row_fpn=0.02), with_crlb=False).image.astype(float)
    assert np.max(np.std((rows - plain)[:, 100:], axis=1)) < 1.0


def test_jpeg_round_trip_is_8_bit_and_blocky():
    spec = ImageSpec(marks=(MarkSpec(0.3, 0, 200, 4.0),), width=256, height=256, bits=8,
                     jpeg_quality=50, seed=2)
    img = render_marks(spec, with_crlb=False).image
    assert img.dtype == np.uint8
    raw = render_marks(replace(spec, jpeg_quality=0), with_crlb=False).image
    assert np.any(img != raw)
    with pytest.raises(ValueError, match="bits = 8"):
        render_marks(replace(spec, bits=16), with_crlb=False)
