"""Oriented periodic background (issue 18 item 4): stripes at any angle to a mark — a turned
or ground surface's lay — found on the background, divided out, named, and what the removal
may leave carried in u; clean and randomly textured backgrounds left alone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

import imaging.oriented as oriented
from align.lens import LensRanges
from align.marks import measure_image
from imaging import detect_lines, measure_frame
from imaging.band import band_indices, band_mask
from imaging.oriented import Wave, _fit, _resid_jac, find_oriented
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error


def _striped(seed: int, mark_deg: float, rel_deg: float, amp: float, period: float,
             phase: float = 0.0, **kw):
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(mark_deg), kw.pop("offset", 0.0), 300.0, 4.0),),
                     width=640, height=480, full_well_e=full_well_for_snr(40, -0.6), seed=seed,
                     stripes=amp, stripes_period_px=period,
                     stripes_angle_rad=np.deg2rad(mark_deg + rel_deg), stripes_phase=phase, **kw)
    return render_marks(spec, with_crlb=False)


def _z(sample) -> tuple[float, object]:
    (r,) = measure_image(sample.image, ranges=LensRanges.none())
    return angle_error(r.angle_rad, sample.truth.marks[0].image_angle_rad) / r.angle_u_rad, r


def test_shallow_stripes_are_found_removed_and_named():
    """Stripes of 4 % at 10 deg to a 300 px mark, period 25 px: the frame names them (period
    within 0.5 px, direction within 0.5 deg of the render's), the angle is within 3 u, and u
    holds the named Type B term."""
    s = _striped(4, 30.0, 10.0, 0.04, 25.0, 1.0)
    fr = measure_frame(s.image)
    (w,) = fr.oriented.waves
    assert abs(w.period_px - 25.0) < 0.5
    assert abs(np.rad2deg(angle_error(w.angle_rad, np.deg2rad(40.0)))) < 0.5
    assert any("striped background: period 25.0 px at 40.0 deg" in n for n in fr.notes)
    z, r = _z(s)
    assert abs(z) <= 3.0
    assert "striped_background" in r.u_terms


def test_stripes_along_a_mark_that_hide_it_are_removed_first():
    """Stripes of 7 % at 2 deg to the mark, period 59 px: the detector alone finds no line;
    with the pattern divided out the mark is found, named and within 3 u."""
    s = _striped(35, 30.9, -2.0, 0.077, 58.6, 2.0, offset=20.0)
    z, r = _z(s)
    assert any("striped background" in n for n in r.notes)
    assert abs(z) <= 3.0


def test_a_texture_lay_is_not_a_periodic_background():
    """Machining streaks (a random 1-D profile along 0.3 rad, 8 %): a whole ray of the
    spectrum, not a peak — not flagged, the image returned untouched."""
    spec = ImageSpec(marks=(MarkSpec(1.0, 0.0, 300.0, 4.0),), width=640, height=480,
                     full_well_e=full_well_for_snr(40, -0.6), seed=3, texture=0.08,
                     texture_scale_px=3.0)
    im = render_marks(spec, with_crlb=False).image
    det = detect_lines(im)
    out, found = find_oriented(im, band_mask(im.shape, [band_indices(im, c) for c in det.marks]),
                               65535)
    assert not found.found and out is im


def _wave_background(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A relative background: 3 % stripes (period 23 px, 35 deg) in 1 % noise, a band left
    out; and the true wave vector [rad/px]."""
    rng = np.random.default_rng(seed)
    k = 2 * np.pi / 23.0 * np.array([np.cos(0.6), np.sin(0.6)])
    y, x = np.mgrid[:160, :200]
    rel = 0.03 * np.cos(k[0] * x + k[1] * y + 0.7) + 0.01 * rng.standard_normal(x.shape)
    valid = np.abs(y - 0.4 * x - 40) > 12
    return rel.astype(np.float32), valid, k


def test_fit_jacobian_is_the_residual_derivative_and_finds_the_same_wave():
    """The analytic Jacobian of the projected residual matches central differences (to 1e-5
    of its scale) off and at the optimum, the normal equations' amplitudes are lstsq's, and
    the fit (Levenberg-Marquardt on the compressed 3-row problem) lands where one on all the
    rows with a finite-difference Jacobian does (k within 1e-9 rad/px, a and b within
    1e-9)."""
    rel, valid, k_true = _wave_background(3)
    yy, xx = np.nonzero(valid)
    z = rel[yy, xx].astype(float)
    X, Y = xx.astype(float), yy.astype(float)
    for k in (k_true * 1.01 + [2e-3, -1e-3], k_true):
        _, J, _ = _resid_jac(k, X, Y, z)
        h = 1e-6
        fd = np.column_stack([(_resid_jac(k + e, X, Y, z)[0] - _resid_jac(k - e, X, Y, z)[0])
                              / (2 * h) for e in np.eye(2) * h])
        assert np.abs(J - fd).max() <= 1e-5 * np.abs(fd).max()
        ph = k[0] * X + k[1] * Y
        c_ls = np.linalg.lstsq(np.column_stack([np.cos(ph), np.sin(ph), np.ones_like(ph)]), z,
                               rcond=None)[0]
        assert np.abs(_resid_jac(k, X, Y, z)[2] - c_ls).max() < 1e-12
    f0 = tuple(k_true * 1.005 / (2 * np.pi))
    k, ab, cov = _fit(rel, valid, f0, (0, 0))

    def resid(kk: np.ndarray) -> np.ndarray:
        return _resid_jac(kk, X, Y, z)[0]

    ref = optimize.least_squares(resid, 2 * np.pi * np.asarray(f0), x_scale=2 * np.pi / 200,
                                 method="lm")
    c_ref = _resid_jac(ref.x, X, Y, z)[2]
    assert np.abs(k - ref.x).max() < 1e-9
    assert np.abs(ab - c_ref[:2]).max() < 1e-9
    # And it is the wave that is there: k's u is ~6e-5 rad/px (1 % noise on 3 % over ~25k px).
    assert np.abs(k - k_true).max() < 3e-4


def test_fit_with_a_singular_jacobian_runs():
    """A background with no wave at all (flat): c = 0, so J = 0 and J^T J is singular —
    the compressed problem falls back on J's QR and the fit returns its start, finite,
    with zero amplitudes (no LinAlgError)."""
    rel, valid, k_true = _wave_background(4)
    k, ab, _ = _fit(np.zeros_like(rel), valid, tuple(k_true / (2 * np.pi)), (0, 0))
    assert np.allclose(k, k_true) and np.all(ab == 0.0)


def test_wave_pattern_is_the_plane_wave():
    """The pattern divided out (by the angle-addition formulas) is a cos(k.r) + b sin(k.r)
    at every pixel of a frame, to 1e-12 of its amplitude, for waves at any angle."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[:97, :131]
    for _ in range(5):
        k = rng.uniform(-0.8, 0.8, 2)
        ab = rng.uniform(-0.1, 0.1, 2)
        w = Wave(float(np.hypot(*ab)), 0.0, 1.0, 0.0, (float(k[0]), float(k[1])),
                 (float(ab[0]), float(ab[1])), 1.0)
        ph = k[0] * x + k[1] * y
        assert np.abs(w.pattern((97, 131)) - (ab[0] * np.cos(ph) + ab[1] * np.sin(ph))
                      ).max() <= 1e-12 * np.hypot(*ab)


@pytest.mark.slow
def test_oriented_stripes_over_seeds_are_flagged_and_covered():
    """40 seeds: mark at any angle, stripes 0-90 deg from it (either side), 1-8 %, period
    8-60 px, any phase: every one flagged, every |z| <= 3 and the RMS of z below 1.3
    (measured: 40 flagged, RMS 0.99, max 2.03; before: the pattern moved the angle by up to
    0.6 deg, unflagged)."""
    zs, flagged = [], 0
    for s in range(40):
        r = np.random.default_rng(9000 + s)
        a = r.uniform(-89, 89)
        rel = r.uniform(0, 90) * r.choice([-1, 1])
        amp, per = r.uniform(0.01, 0.08), r.uniform(8, 60)
        sample = _striped(s, a, rel, amp, per, r.uniform(0, 2 * np.pi),
                          offset=r.uniform(-40, 40))
        z, res = _z(sample)
        flagged += any("striped background" in n for n in res.notes)
        zs.append(z)
    zs = np.array(zs)
    assert flagged == 40
    assert np.abs(zs).max() <= 3.0 and np.sqrt(np.mean(zs**2)) < 1.3, zs


@pytest.mark.slow
def test_clean_backgrounds_are_rarely_flagged():
    """300 stripe-free frames (plain; a texture lay of 2-10 % at any angle and scale; dust,
    scratches, labels, shading and vignetting; 8/12/16-bit; 480-800 px): at most 3 flagged
    (the test's level is 1e-3 per frame; 1 % is the bound asked; measured: 0 of 400, the largest
    peak 0.92 of its threshold)."""
    flags = 0
    for s in range(300):
        r = np.random.default_rng(20000 + s)
        kind = s % 4
        kw = (dict(texture=r.uniform(0.02, 0.1), texture_angle_rad=r.uniform(0, np.pi),
                   texture_scale_px=r.uniform(1, 4)) if kind in (1, 3) else {})
        if kind >= 2:
            kw.update(dust=int(r.integers(0, 20)), scratches=int(r.integers(0, 6)),
                      text=int(r.integers(0, 3)),
                      gradient=(r.uniform(-.3, .3), r.uniform(-.3, .3)),
                      vignetting=r.uniform(0, 0.4))
        bits = int(r.choice([8, 12, 16]))
        a = r.uniform(-89, 89)
        spec = ImageSpec(marks=(MarkSpec(np.deg2rad(a), r.uniform(-60, 60), r.uniform(200, 400),
                                         r.uniform(2, 6)),),
                         width=int(r.choice([480, 640, 800])),
                         height=int(r.choice([360, 480, 600])),
                         full_well_e=full_well_for_snr(r.uniform(15, 80), -0.6), seed=s,
                         bits=bits, blur_px=r.uniform(0.8, 2.5), **kw)
        im = render_marks(spec, with_crlb=False).image
        top = float(2**bits - 1)
        det = detect_lines(im, top=top)
        bands = [band_indices(im, c) for c in (*det.marks, *det.unreported)]
        _, found = find_oriented(im, band_mask(im.shape, bands), top)
        flags += found.found
    assert flags <= 3, flags


def test_the_float32_square_gives_the_float64_answers(monkeypatch):
    """The test on a float64 frame of whole pixels (any image read from an integer file) runs
    on a float32 copy of its square when the square is cut from a wider frame: the same
    finding and the same frame back, to the bit, as on the float64 square itself (shallow
    stripes found and divided out; a clean frame)."""
    for sample in (_striped(4, 30.0, 10.0, 0.04, 25.0, 1.0), _striped(5, 30.0, 10.0, 0.0, 25.0)):
        im = np.asarray(sample.image, float)
        wide = np.hstack([im, im[:, ::-1]])  # 1280 px wide: the 1024 px square is a view
        assert np.array_equal(wide, np.round(wide))
        assert oriented._exact_float32(wide[:, 128:1152], 65535.0).dtype == np.float32
        fast = find_oriented(wide, None, 65535.0)
        with monkeypatch.context() as m:
            m.setattr(oriented, "_exact_float32", lambda raw, full_scale: raw)
            slow = find_oriented(wide, None, 65535.0)
        assert fast[1] == slow[1] and np.array_equal(fast[0], slow[0])
    assert fast[1].found is False and slow[1].waves == ()
    # Fractional pixels are not held by float32: the square is tested as it is.
    frac = (wide + 0.3)[:64, :64]
    assert oriented._exact_float32(frac, 65535.0) is frac
