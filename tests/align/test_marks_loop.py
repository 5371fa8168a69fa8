"""The loop over mark line fits: undeclared distortion found and removed; clean images left."""

from __future__ import annotations

import numpy as np
import pytest

from align.lens import LensRanges
from align.marks import BEND, half_diagonal, measure_image
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error


@pytest.mark.parametrize("k1,offset,seed", [(-0.10, 180.0, 1), (0.06, -220.0, 2),
                                            (-0.05, 120.0, 3)])
def test_undeclared_radial_distortion_is_found_and_carried(k1, offset, seed):
    """One long off-centre mark through an undeclared radial lens: its bow determines k1
    (right sign, applied), but one line cannot tell a lens from a bent mark, so u covers the
    angle with and without the lens; the error is within that u."""
    f = 1000.0
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(2.0 + seed), offset, 600, 4.0,
                                     centre_t_px=90.0),), width=1024, height=768,
                     full_well_e=full_well_for_snr(40, -0.6), seed=seed,
                     camera=CameraGeometry(focal_px=f, k1=k1))
    s = render_marks(spec, with_crlb=False)
    r = measure_image(s.image.astype(float))[0]
    t = s.truth.marks[0]
    after = angle_error(r.angle_rad, t.image_angle_rad)
    k1n = k1 * (half_diagonal((768, 1024)) / f) ** 2
    p = r.lens["parameters"]["k1"]
    assert p["determined"] and p["applied"] and np.sign(p["value"]) == np.sign(k1n)
    assert abs(p["value"] - k1n) < max(5 * p["u_from_lines"], 0.05 * abs(k1n))
    assert "lens_or_bend" in r.u_terms and not r.lens["confirmed_by_other_lines"]
    assert abs(after) < 3 * r.angle_u_rad


@pytest.mark.slow
def test_no_false_effects_on_fifty_clean_images():
    rng = np.random.default_rng(2024)
    false, flagged, z = 0, 0, []
    for seed in range(50):
        ang = rng.uniform(-90, 90)
        spec = ImageSpec(marks=(MarkSpec(np.deg2rad(ang), rng.uniform(-80, 80), 400,
                                         rng.uniform(2, 8)),), width=640, height=480,
                         full_well_e=full_well_for_snr(rng.uniform(10, 100), -0.6), seed=seed)
        s = render_marks(spec, with_crlb=False)
        # The camera is declared distortion-free: this checks the noise model alone.
        r = measure_image(s.image.astype(float), ranges=LensRanges.none())[0]
        false += bool(r.loop.effects)
        flagged += r.unexplained_structure
        z.append(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad) / r.angle_u_rad)
    assert false <= 1, f"{false} false effects in 50 clean images"
    assert flagged <= 1
    assert 0.75 < np.sqrt(np.mean(np.square(z))) < 1.3


def _clean_marks(n_per_band: int, seed: int):
    """Normalised angle errors and false-effect flags over clean random marks per band."""
    rng = np.random.default_rng(seed)
    bands = {"0±1°": lambda: rng.uniform(-1, 1), "90±1°": lambda: 90 + rng.uniform(-1, 1),
             "any": lambda: rng.uniform(-90, 90)}
    out = {}
    for name, draw in bands.items():
        z, false = [], 0
        for k in range(n_per_band):
            mark = MarkSpec(np.deg2rad(draw()), rng.uniform(-80, 80), rng.uniform(200, 500),
                            rng.uniform(2, 8), profile=str(rng.choice(["box", "v", "round"])))
            spec = ImageSpec(
                marks=(mark,), width=640, height=480, blur_px=rng.uniform(0.8, 2.0),
                bits=int(rng.choice([8, 16])),
                full_well_e=full_well_for_snr(rng.uniform(10, 100), -0.6), seed=seed * 10000 + k)
            s = render_marks(spec, with_crlb=False)
            r = measure_image(s.image.astype(float), ranges=LensRanges.none())[0]
            false += bool(r.loop.effects) or r.unexplained_structure
            z.append(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad) / r.angle_u_rad)
        out[name] = (np.array(z), false)
    return out


@pytest.mark.slow
def test_no_pixel_locking_normalised_errors_per_angle_band():
    """>= 200 clean marks (issue 9 item 3): 0 +- 1 deg, 90 +- 1 deg and any angle.

    With n marks per band the RMS of N(0, 1) errors lies within 1 +- 3.3 / sqrt(2 n) at
    > 99.9 %; false effects (or unexplained structure) on <= 1 % of all marks.
    """
    n = 70
    res = _clean_marks(n, 9)
    for name, (z, _) in res.items():
        rms = float(np.sqrt(np.mean(z**2)))
        print(f"{name}: normalised-error RMS {rms:.2f}, mean {z.mean():+.2f}")
        assert abs(rms - 1) < 3.3 / np.sqrt(2 * n), name
    false = sum(f for _, f in res.values())
    print(f"false effects: {false} of {3 * n}")
    assert false <= 0.01 * 3 * n


@pytest.mark.parametrize("k1,seed", [(0.0, 1), (-0.08, 2)])
def test_marks_of_one_frame_share_one_distortion(k1, seed):
    """Issue 9 item 4 / issue 18: one lens for the frame, fitted jointly over its marks
    (never one per line), confirmed by the line to spare, its u carried into every angle."""
    rng = np.random.default_rng(seed)
    marks = tuple(MarkSpec(np.deg2rad(rng.uniform(-3, 3) + (90 if j == 2 else 0)), off, 600, 4.0)
                  for j, off in enumerate((-250.0, 200.0, 300.0)))
    spec = ImageSpec(marks=marks, width=1024, height=768, full_well_e=full_well_for_snr(40, -0.6),
                     seed=seed, camera=CameraGeometry(focal_px=1000.0, k1=k1))
    s = render_marks(spec, with_crlb=False)
    res = [r for r in measure_image(s.image.astype(float)) if r.found]
    assert len(res) == 3
    lens = res[0].lens
    assert all(r.lens == lens for r in res) and lens["lines"] == 3
    k1n = k1 * (half_diagonal((768, 1024)) / 1000.0) ** 2
    p = lens["parameters"]["k1"]
    assert p["determined"] and p["applied"] == (k1 != 0)
    assert abs(p["estimate"] - k1n) < max(5 * p["u_from_lines"], 0.05 * abs(k1n))
    assert lens["confirmed_by_other_lines"]
    for r in res:
        t = min(s.truth.marks, key=lambda t: abs(angle_error(r.angle_rad, t.image_angle_rad)))
        assert abs(angle_error(r.angle_rad, t.image_angle_rad)) < 3 * r.angle_u_rad


def _session_like_marks(n: int, seed: int, horizontal_only: bool = False, k1: float = 0.0):
    """Marks as `align synth session` renders them (machining texture at 17 deg, dust,
    scratches, an illumination gradient), within 0.1 deg of 0 or 90 deg."""
    rng = np.random.default_rng(seed)
    z, base, false = [], [], 0
    for _ in range(n):
        b = 0.0 if horizontal_only else float(rng.choice([0.0, 90.0]))
        mark = MarkSpec(np.deg2rad(b + rng.uniform(-0.1, 0.1)), float(rng.uniform(-40, 40)),
                        380.0, 4.0, centre_t_px=float(rng.uniform(-30, 30)))
        spec = ImageSpec(marks=(mark,), width=640, height=480, seed=int(rng.integers(1 << 30)),
                         full_well_e=full_well_for_snr(40, -0.6), texture=0.01, dust=4,
                         scratches=2, gradient=(0.04, -0.02),
                         camera=CameraGeometry(focal_px=1.6 * 640, k1=k1))
        s = render_marks(spec, with_crlb=False)
        ranges = LensRanges.none() if k1 == 0 else None  # lens-free declared, or not
        r = [r for r in measure_image(s.image.astype(float), ranges=ranges) if r.found][0]
        false += bool(r.loop.effects) or r.unexplained_structure
        z.append(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad) / r.angle_u_rad)
        base.append(b)
    return np.array(z), np.array(base), false


def test_textured_horizontal_marks_get_no_false_effects():
    """Machining streaks crossing a horizontal mark at a shallow angle correlate its centres
    over tens of px; measured on replicas of the band, that correlation is in the fit and in
    u, not a periodic_wiggle or unexplained structure (before: 6 of 6 flagged here)."""
    z, _, false = _session_like_marks(6, 11, horizontal_only=True)
    assert false <= 1
    assert np.all(np.abs(z) < 4)


@pytest.mark.slow
def test_session_images_normalised_errors_and_false_effects():
    """Issue 9 item 3 on the images of `align synth session` (200 marks). The texture's
    covariance is estimated (replicas): the effect and structure tests use their null
    distributions with an estimated covariance (before: 3 of 200 flagged, two of them
    effects at p ~ 1e-3 under chi2 that are F-type p ~ 3e-3 and 6e-3)."""
    n = 200
    z, base, false = _session_like_marks(n, 5)
    for b in (0.0, 90.0):
        zb = z[base == b]
        rms = float(np.sqrt(np.mean(zb**2)))
        print(f"{b:.0f} deg: normalised-error RMS {rms:.2f} over {zb.size}")
        assert abs(rms - 1) < 3.3 / np.sqrt(2 * zb.size)
    print(f"false effects or unexplained structure: {false} of {n}")
    assert false <= 0.01 * n


@pytest.mark.slow
@pytest.mark.parametrize("k1,seed", [(-0.3, 7), (0.2, 8)])
def test_undeclared_distortion_on_session_images_normalised_errors(k1, seed):
    """Issue 9 item 4: one camera with undeclared radial distortion (session-like textured
    images, one mark each): the angles' normalised errors are never understated. Since the lens
    belongs to the camera (issue 18), a single mark cannot determine it and the lens is carried
    as a Type B term over its plausible range: u is conservative here (the error is the
    lens's actual value and the principal point's, not draws from their ranges: most of u is
    lens_pp_cross over +-40 px in a scene whose principal point is the centre), bounded below
    so that it stays useful: u at most 3x the angles' RMS error (RMS z > 1/3). Centres out to
    the grooves' ends made these angles more accurate at the same u (k1 +0.2, seed 8: RMS error
    30.4 -> 26.0 arcsec, RMS u 59.5 -> 58.9, RMS z 0.43 -> 0.365; k1 -0.3, seed 7: 0.47 ->
    0.41); the principal point drawn over its range instead moves RMS z by < 0.05."""
    n = 40
    z, _, _ = _session_like_marks(n, seed, k1=k1)
    rms = float(np.sqrt(np.mean(z**2)))
    print(f"k1 {k1}: normalised-error RMS {rms:.2f}, max |z| {np.max(np.abs(z)):.2f}")
    assert 1 / 3 < rms < 1 + 3.3 / np.sqrt(2 * n)
    assert np.max(np.abs(z)) < 4.5


def _bowed_groove(offset_px: float, bow_px: float, seed: int, angle_deg: float = 20.0,
                  length_px: float = 300.0) -> np.ndarray:
    """A 4 px groove (blur 1.2 px, 4x4 sub-pixel integration) bowed by ``bow_px`` at its ends
    across itself, at ``offset_px`` from the image centre; 640x480, white noise 1/60 of the
    contrast."""
    from scipy.special import ndtr

    rng = np.random.default_rng(seed)
    h, w = 480, 640
    a = np.deg2rad(angle_deg)
    u, n = np.array([np.cos(a), -np.sin(a)]), np.array([np.sin(a), np.cos(a)])
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    # Only pixels within 40 px of the groove's centre line are integrated: beyond, every
    # sub-pixel's term is below 1e-100 (or exactly 0) and 0.5 minus it is 0.5, so the image
    # is the one integrated over the whole frame, bit for bit, at a tenth of the CPU.
    t0 = (xx - (w - 1) / 2) * u[0] + (yy - (h - 1) / 2) * u[1]
    near = np.abs((xx - (w - 1) / 2) * n[0] + (yy - (h - 1) / 2) * n[1] - offset_px
                  - bow_px * (t0 / (length_px / 2)) ** 2) < 40.0
    xx, yy = xx[near], yy[near]
    band = np.zeros(xx.shape)
    for sy in (np.arange(4) - 1.5) / 4:
        for sx in (np.arange(4) - 1.5) / 4:
            px, py = xx + sx - (w - 1) / 2, yy + sy - (h - 1) / 2
            t = px * u[0] + py * u[1]
            d = px * n[0] + py * n[1] - offset_px - bow_px * (t / (length_px / 2)) ** 2
            band += (ndtr((d + 2) / 1.2) - ndtr((d - 2) / 1.2)) * ndtr(
                (length_px / 2 - np.abs(t)) / 1.2)
    img = np.zeros((h, w))
    img[near] = band
    mu = 0.5 - 0.3 * img / 16 + rng.normal(size=(h, w)) * 0.005
    return np.round(np.clip(mu, 0, 1) * 65535).astype(np.uint16)


def test_mark_through_the_centre_gets_no_distortion():
    """A radial distortion leaves a line through the principal point straight: such a mark
    carries no k1. Clean: no effect, u not rescaled. Bowed on a camera declared
    distortion-free: a bent mark, named, u widened (never a lens)."""
    rng = np.random.default_rng(11)
    for seed in range(4):
        r = measure_image(_bowed_groove(rng.uniform(-0.5, 0.5), 0.0, seed,
                                        angle_deg=rng.uniform(-89, 90)))[0]
        assert not r.loop.effects and not r.loop.refused, r.loop.summary_lines()
        assert r.uncertainty_inflation == 1.0
        assert not r.lens["parameters"]["k1"]["applied"]
    r = measure_image(_bowed_groove(0.2, 0.3, 7), ranges=LensRanges.none())[0]
    assert [e.name for e in r.loop.effects] == [BEND]
    assert "bent_mark_chord_vs_fit" in r.u_terms and any("bent" in n for n in r.notes)


def test_loop_u_of_a_textured_mark_same_from_either_end():
    """The texture's amplitude re-read from the mark (whitened residuals' neighbour
    differences) is taken both ways along it: a causal whitening alone gave the same pixels
    rotated by 180 deg a u a few % different."""
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(2.6), 40.0, 370, 4.0),), width=640,
                     height=480, full_well_e=full_well_for_snr(40, -0.6), seed=5, texture=0.01)
    img = render_marks(spec, with_crlb=False).image
    a = measure_image(img)[0]
    b = measure_image(np.ascontiguousarray(np.rot90(img, 2)))[0]
    assert a.measurement.chol is not None and a.lens["lines"] == 1  # one mark, textured
    assert abs(a.angle_u_rad - b.angle_u_rad) < 1e-5 * a.angle_u_rad
    # The angle to the rounding of the sampling grid along the mark (nearest-pixel ties
    # fall differently in the rotated frame: ~1e-5 u once the search runs on 2 x 2 blocks).
    assert abs(a.angle_rad - b.angle_rad) < 1e-4 * a.angle_u_rad
