"""Detection anywhere: short off-centre marks in large frames, never the frame border."""

from __future__ import annotations

import numpy as np
import pytest

from imaging import ImageInputError, check_roi, detect_marks, measure_marks
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error


def _spec(marks, size, snr, seed, **kw):
    return ImageSpec(marks=tuple(marks), width=size[0], height=size[1],
                     full_well_e=full_well_for_snr(snr, -0.6), seed=seed, **kw)


def _matches(found, truth, tol_px=6.0):
    """Which detected candidate lies on the true mark (angle within 2 deg, offset within tol)."""
    for c in found:
        if abs(angle_error(c.angle_rad, truth.image_angle_rad)) < np.deg2rad(2):
            flip = abs(c.angle_rad - truth.image_angle_rad) > np.pi / 2
            if abs((-c.offset_px if flip else c.offset_px) - truth.image_offset_px) < tol_px:
                return c
    return None


@pytest.mark.parametrize("seed,angle,length,snr", [
    pytest.param(1, 0.03, 150, 11.0, marks=pytest.mark.slow), (2, 89.97, 170, 14.0),
    pytest.param(3, 33.0, 300, 22.0, marks=pytest.mark.slow)])
def test_short_off_centre_mark_in_a_large_frame_near_the_edge(seed, angle, length, snr):
    """The misses of issue 9: 150-400 px marks, 6-7 px wide, SNR 11-22, 2448x2048 frames."""
    rng = np.random.default_rng(seed)
    w, h = 2448, 2048
    a = np.deg2rad(angle)
    # The mark wholly inside, in the top-right corner, 12 px from the nearer edge.
    n = np.array([np.sin(a), np.cos(a)])
    u = np.array([np.cos(a), -np.sin(a)])
    corner = np.array([(w - 1) / 2 - abs(length / 2 * np.cos(a)) - 12,
                       -(h - 1) / 2 + abs(length / 2 * np.sin(a)) + 12])
    off, ct = float(corner @ n), float(corner @ u)
    spec = _spec([MarkSpec(a, off, length, rng.uniform(6, 7), centre_t_px=ct)], (w, h), snr,
                 seed, vignetting=0.3, supersample=3)
    s = render_marks(spec, with_crlb=False)
    found = detect_marks(s.image.astype(float))
    c = _matches(found, s.truth.marks[0])
    assert c is not None, f"mark not found; got {found}"
    assert len(found) == 1


def test_border_padding_vignetting_and_saturated_edge_are_not_marks():
    s = render_marks(_spec([], (1280, 1024), 20, 4, vignetting=0.5, gradient=(0.2, 0.1)),
                     with_crlb=False)
    img = s.image.astype(float)
    img[:4] = 0  # dark padding rows (as on OpenCV's sample photos)
    img[-1] = 0
    img[:, -6:] = img.max() + 2000  # a saturated band along the right edge
    img[:, :3] = 20.0  # a dark band on the left
    assert detect_marks(img) == []
    # ...and with a mark 9 px inside the padded top edge, only the mark.
    spec = _spec([MarkSpec(np.deg2rad(0.02), -(1024 - 1) / 2 + 13, 400, 4.0)], (1280, 1024),
                 20, 4, vignetting=0.5)
    s = render_marks(spec, with_crlb=False)
    img = s.image.astype(float)
    img[:4] = 0
    found = detect_marks(img)
    assert len(found) == 1 and _matches(found, s.truth.marks[0]) is not None
    m = measure_marks(img)[0]
    assert not isinstance(m, Exception), m  # the clipped padding is not the mark's pixels


def test_short_faint_mark_beside_a_long_strong_one_is_found():
    """No relative-strength rule: an SNR-8 100-px mark counts beside a long strong one."""
    faint = MarkSpec(np.deg2rad(60), 250, 110, 4.0, contrast=-0.6 * 8 / 60)
    strong = MarkSpec(np.deg2rad(1), -200, 1100, 4.0)
    s = render_marks(_spec([strong, faint], (1280, 1024), 60, 5), with_crlb=False)
    found = detect_marks(s.image.astype(float))
    assert all(_matches(found, t) is not None for t in s.truth.marks)
    assert len(found) == 2


def test_roi_and_min_length_restrict_the_search():
    marks = [MarkSpec(0.2, -150, 500, 4.0), MarkSpec(1.3, 200, 180, 4.0)]
    s = render_marks(_spec(marks, (1024, 768), 30, 6), with_crlb=False)
    img = s.image.astype(float)
    assert len(detect_marks(img)) == 2
    assert len(detect_marks(img, min_length_px=300)) == 1
    # The second mark's middle is at about (512 + 200 sin 1.3, 384 + 200 cos 1.3).
    x, y = 512 + 200 * np.sin(1.3), 384 + 200 * np.cos(1.3)
    roi = (int(x - 60), int(y - 120), 120, 240)
    only = detect_marks(img, roi=roi)
    assert len(only) == 1 and _matches(only, s.truth.marks[1]) is not None
    with pytest.raises(ImageInputError, match="reaches outside"):
        detect_marks(img, roi=(1000, 0, 100, 100))
    with pytest.raises(ImageInputError, match="four whole numbers"):
        check_roi(["1", "2", "x", "4"], "--roi")
