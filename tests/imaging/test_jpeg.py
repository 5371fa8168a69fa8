"""JPEG 8x8 blocks (issue 18 item 4): the encoder's quality read from the pixels, its effect on
a mark's angle carried in u."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from align.lens import LensRanges
from align.marks import measure_image
from imaging import CameraModel, JpegTables
from imaging.jpeg import (
    JpegBlocks,
    block_labels,
    find_jpeg,
    grid_phase,
    ijg_table,
    jpeg_note,
    jpeg_round_trip,
    jpeg_round_trips,
    precoding_noise,
    quality_candidates,
    requantised_quality,
    table_quality,
)
from imaging.jpeg_scatter import (
    block_phase_columns,
    block_scatter,
    jpeg_centre_scale,
    jpeg_noise_dof,
)
from imaging.jpeg_turn import TurnEstimate, jpeg_angle_shift, near_axis
from imaging.measure import measure_frame
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error


def _image(seed: int, quality: int, angle_deg: float = 90.3, snr: float = 40.0,
           size=(640, 480)):
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(angle_deg), 10.0, 400.0, 4.0),),
                     width=size[0], height=size[1], bits=8, jpeg_quality=quality,
                     exposure=0.4, full_well_e=full_well_for_snr(snr, -0.6, exposure=0.4),
                     seed=seed)
    return render_marks(spec, with_crlb=False)


def test_ijg_table_is_libjpegs():
    assert ijg_table(50)[0, 0] == 16 and ijg_table(50)[7, 7] == 99
    assert ijg_table(100).max() == 1 and ijg_table(1).min() == 255


@pytest.mark.parametrize("quality", [50, 70, 90])
def test_quality_is_read_from_the_pixels(quality):
    jb = find_jpeg(_image(1, quality, angle_deg=30.0).image)
    assert jb is not None and abs(jb.quality - quality) <= 6


@pytest.mark.parametrize("snr", [10, 40])
def test_raw_8_bit_images_show_no_jpeg(snr):
    assert find_jpeg(_image(2, 0, snr=snr).image) is None


def test_a_jpeg_mark_is_named_and_within_u():
    """Quality 50 on a near-vertical mark (the blocks' systematic: +16-20" at a line u of
    3.5"): the note names JPEG, u carries jpeg_blocks, the angle is within 3 u."""
    s = _image(0, 50)
    (r,) = measure_image(s.image, ranges=LensRanges.none())
    assert any("JPEG compression" in n for n in r.notes)
    assert "jpeg_blocks" in r.u_terms
    assert abs(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad)) <= 3 * r.angle_u_rad


def test_a_jpeg_mark_measured_again_under_a_shadow_keeps_its_jpeg_term():
    """A quality-70 JPEG whose mark a shadow's edge runs along (5 deg, 30 % deep): the mark
    is measured again on the light with the edge divided out (align.mark_shadow). Before,
    that measurement passed no JPEG and the reported mark had no jpeg_blocks term (the real
    left01.jpg's one mark, left06.jpg's first); now it carries the file's blocks."""
    a = 0.25
    spec = ImageSpec(marks=(MarkSpec(a, 0.0, 200.0, 5.0, contrast=-0.5),), width=320,
                     height=240, blur_px=1.0, bits=8, full_well_e=20000.0, jpeg_quality=70,
                     shadow=(a + np.deg2rad(5.0), 0.0, 3.0, 0.3), seed=0)
    s = render_marks(spec, with_crlb=False)
    (r,) = measure_image(s.image, ranges=LensRanges.none())
    assert any("a shadow's edge runs along the mark" in n for n in r.notes), r.notes
    assert "jpeg_blocks" in r.u_terms, r.u_terms
    assert any("JPEG compression" in n for n in r.notes), r.notes
    assert abs(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad)) <= 3 * r.angle_u_rad


def test_a_jpeg_read_before_its_background_is_divided_out():
    """A quality-70 JPEG with oriented stripes (5 %, 12 px): the frame's background is
    divided out (imaging.oriented) before its marks are measured. Before, the encoder was
    looked for on the divided image (no integer pixels left): none found, the mark had no
    jpeg_blocks term; now it is read on the file's own pixels (quality within 6)."""
    a = 0.25
    spec = ImageSpec(marks=(MarkSpec(a, 0.0, 200.0, 5.0, contrast=-0.5),), width=320,
                     height=240, blur_px=1.0, bits=8, full_well_e=20000.0, jpeg_quality=70,
                     stripes=0.05, stripes_period_px=12.0, stripes_angle_rad=1.2, seed=0)
    fr = measure_frame(render_marks(spec, with_crlb=False).image, where="striped")
    (m,) = fr.items
    assert fr.oriented.found
    assert m.jpeg is not None and abs(m.jpeg.quality - 70) <= 6, m.jpeg
    assert m.jpeg_turn is not None


def _groove_on_a_block_row(seed: int) -> np.ndarray:
    """A raw 8-bit image (noise 1.5 DN, never compressed) with one horizontal 256 px groove
    inside block row 12 whose across profile has its 8-point DCT at 4, -3 and -1 steps of the
    quality-41 table (as user 9's groove on row 100 had): every block along it alike."""
    T = ijg_table(41)[:, 0]
    k = np.arange(8)
    D = np.sqrt(2 / 8) * np.cos((2 * k[None, :] + 1) * k[:, None] * np.pi / 16)
    D[0] /= np.sqrt(2)
    coef = np.zeros(8)
    coef[[1, 3, 4]] = 4 * T[1], -3 * T[3], -1 * T[4]
    img = np.full((480, 640), 140.0)
    img[96:104, 72:328] += (D.T @ (coef / np.sqrt(8)))[:, None]
    rng = np.random.default_rng(seed)
    return np.clip(np.round(img + rng.normal(0, 1.5, img.shape)), 0, 255).astype(np.uint8)


def test_blocks_alike_along_a_groove_are_not_jpeg():
    """Blocks of one content share their coefficients, which may sit on some quality's
    multiples by chance; quantisation needs different contents on multiples (user 9: a PNG
    groove on row 100 was called 'JPEG quality ~41')."""
    for seed in range(4):
        assert find_jpeg(_groove_on_a_block_row(seed)) is None, seed


def _flattened_jpeg(quality: int | None, seed: int = 0) -> np.ndarray:
    """A 160x160 frame, background 140 DN with 1.3 DN noise (user 13's: the encoder at
    quality 75 flattens it), a dark 3 px groove at 30 deg, through OpenCV's encoder."""
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:160, 0:160]
    d = (xx - 80) * np.sin(0.52) + (yy - 80) * np.cos(0.52)
    img = 140.0 - 40.0 * np.exp(-0.5 * (d / 1.5) ** 2) + rng.normal(0, 1.3, d.shape)
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    if quality is None:
        return img
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)


def _blocks(img: np.ndarray):
    b = img.astype(float).reshape(20, 8, 20, 8).transpose(0, 2, 1, 3).reshape(-1, 8, 8)
    k = np.arange(8)
    D = np.sqrt(2 / 8) * np.cos((2 * k[None, :] + 1) * k[:, None] * np.pi / 16)
    D[0] /= np.sqrt(2)
    return b, np.einsum("ij,njk,lk->nil", D, b - 128.0, D)


@pytest.mark.parametrize("quality", [50, 75, 90])
def test_quality_of_a_flattened_jpeg_by_requantising(quality):
    """The blocks with content given back by their own table: the lowest quality that does
    is the encoder's or a few below (the steps round alike); a raw frame only by 100."""
    q = requantised_quality(*_blocks(_flattened_jpeg(quality)))
    assert q is not None and quality - 8 <= q <= quality, q
    assert requantised_quality(*_blocks(_flattened_jpeg(None))) is None


@pytest.mark.parametrize("quality", [75, 90])
def test_the_noise_before_coding_is_read_from_the_kept_coefficients(quality):
    """White noise of sigma 0.8-2.5 DN on a flat 320x240 frame through OpenCV's encoder
    (quality 75 flattens most of it: decoded scatter ~0.3 DN at 1.4): the share of each
    coefficient beyond its zero bin gives sigma back (with the 8-bit rounding's 1/12 DN^2)
    within 10 % (the counts' spread ~3 %, the likelihood's grid 1.7 %)."""
    cv2 = pytest.importorskip("cv2")
    for s in (0.8, 1.4, 2.5):
        rng = np.random.default_rng(int(10 * s))
        img = np.clip(np.round(140 + rng.normal(0, s, (240, 320))), 0, 255).astype(np.uint8)
        _, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
        dec = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
        got = precoding_noise(dec, ijg_table(quality))
        assert abs(got / np.sqrt(s**2 + 1 / 12) - 1) <= 0.1, (s, got, np.std(dec))
    assert precoding_noise(np.full((64, 64), 140, np.uint8), ijg_table(quality)) == 0.0

def test_quality_unknown_carries_the_largest_qualitys_turn():
    """Quality and table unknown (only flattened blocks show JPEG): the term is the largest
    over qualities 10-90 of each quality's own term (its renders coded by every encoder in
    one pass give each the same term as alone), and it is not 0 (the encoder moves the
    centres)."""
    from dataclasses import replace

    from imaging import measure_marks

    img = _image(3, 60, angle_deg=2.0).image.astype(float)
    (m,) = measure_marks(img)
    jb = JpegBlocks(None, float("nan"), 100, phase=(3, 5))
    each = [jpeg_angle_shift(img.shape, m.profile, replace(jb, quality=q))
            for q in range(10, 100, 10)]
    assert jpeg_angle_shift(img.shape, m.profile, jb) == max(each) > 0.0


def test_the_terms_own_spread_makes_the_angles_z_of_unit_variance():
    """The JPEG term's square is a mean over n draws (here 8 chi2_1 draws of T^2, the
    term alone in u): the error over u = the plain estimate is Student's t_8, variance
    8 / 6 = 1.33; :meth:`TurnEstimate.angle_u`, with the variance the draws themselves give,
    brings it to 1 within 4 standard errors (read from the same z), and a term far below
    the rest of u is left alone."""
    rng = np.random.default_rng(1)
    n, N = 8, 10000
    x = rng.normal(size=(N, n)) ** 2  # T = 1
    e = rng.normal(size=N)
    est = [TurnEstimate(float(np.sqrt(x_.mean())), float(x_.var(ddof=1) / n), n) for x_ in x]
    z_plain = e / np.sqrt(x.mean(1))
    z = e / np.array([t.angle_u(0.0) for t in est])
    assert np.mean(z_plain**2) > 1.25
    assert abs(np.mean(z**2) - 1) < 4 * np.std(z**2) / np.sqrt(N), np.mean(z**2)
    assert TurnEstimate(1e-6, 1e-24, 32).angle_u(1e-4) == pytest.approx(1e-4, rel=1e-4)
    assert TurnEstimate(1e-6).angle_u(1e-4) == float(np.hypot(1e-4, 1e-6))


def test_near_axis_is_a_few_block_rows_along_the_mark():
    """The noisy draws go to marks whose edge crosses at most 4 block rows (32 px across
    along its length): 300 px at 3 deg from either axis (15.7 px) is near, at 7 deg (36.6
    px) or 45 deg it is not."""
    from imaging.groove import ProfileFit

    def pf(deg, length=300.0):
        return ProfileFit(np.deg2rad(deg), 0.0, 3.0, 1.0, -40.0, 140.0, 0.0, (1.0, 0.0),
                          -length / 2, length / 2, 255.0)
    assert near_axis(pf(3.0)) and near_axis(pf(87.0)) and near_axis(pf(-93.0))
    assert not near_axis(pf(7.0)) and not near_axis(pf(45.0)) and near_axis(pf(7.0, 250))

def test_jpeg_centre_scale_takes_the_scatter_not_a_bow():
    """White residuals at 2.2x their sigma: the factor ~4.8 (within its 2 (n-1)/3 dof); a
    bow of 10 sigma on white residuals of sigma 1: the factor stays near 1."""
    rng = np.random.default_rng(3)
    n = 60
    z = 2.2 * rng.normal(size=(200, n))
    f = np.array([jpeg_centre_scale(r) for r in z])
    sd = np.sqrt(2 / jpeg_noise_dof(n)) * 4.84
    assert abs(f.mean() - 4.84) <= 4 * sd / np.sqrt(len(f)), f.mean()
    t = np.linspace(-1, 1, n)
    bowed = [jpeg_centre_scale(rng.normal(size=n) + 10 * (t**2 - 1 / 3)) for _ in range(50)]
    assert np.mean(bowed) <= 1.15, np.mean(bowed)


def _user13_jpeg_marks(quality: int, seeds, per_seed: int = 4):
    """User 13's renders (tests/imaging/user13_inputs.py: the real chessboard lens, shot and
    read noise, 8-bit, OpenCV's encoder at ``quality``), measured with the exact camera.
    Yields (error [rad], u [rad], ok, result) per found mark."""
    ui = pytest.importorskip("tests.imaging.user13_inputs")
    import json
    import os
    import tempfile

    from imaging import CameraModel
    if not os.path.isdir(ui.CHESS):
        pytest.skip(f"real data not found at {ui.CHESS}")
    K, d, size, _ = ui.real_lens("left")
    with tempfile.TemporaryDirectory() as tmp:
        cam = CameraModel.load(ui.camera_json(K, d, size, os.path.join(tmp, "cam.json")))
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for _ in range(per_seed):
            ang = np.radians(rng.uniform(-85, 85))
            c = (rng.uniform(170, 470), rng.uniform(150, 330))
            img = ui.mark_image((K, d, size), rng, c, ang, length=rng.uniform(180, 300),
                                width=3.0, jpeg_quality=quality)
            for r in measure_image(img.astype(float), "u13", cam):
                if not r.found:
                    continue
                ok = not (r.lens_limited or r.kinked or r.unexplained_structure
                          or any("NOT OK" in n for n in r.notes))
                json.dumps(r.to_dict())  # the result a user gets is writable
                yield angle_error(r.angle_rad, ang), r.angle_u_rad, ok, r


@pytest.mark.slow
@pytest.mark.parametrize("quality", [50, 75, 90])
def test_user13_jpeg_marks_mostly_ok_and_within_u(quality):
    """User 13: quality 75 with the exact camera had 6 of 6 marks 'unexplained structure',
    u 54-1268" against errors of 1-82" (the blocks' scatter read as structure, then as a
    bent mark or a lens, u x50-1000). Now the blocks' pattern is fitted (known columns,
    imaging.block_phase_columns), their scatter is the centres' (re-read from the mark,
    imaging.jpeg_centre_scale) and their systematic turn beyond it a Type B term: over 6
    seeds x 4 marks (lengths 180-300 px, any angle), at least 90 % ok, every ok mark within
    3 u, the z's RMS within [0.5, 1.2] (u neither short nor useless; before,
    0.26 at q50 over all marks). Measured over 12 seeds through the CLI (report): RMS z
    0.98 / 0.76 / 0.84 at q50 / 75 / 90, max |z| 2.62 / 1.83 / 2.16, ok 44 / 48 / 47 of 48
    (before 0 / 14 / 48)."""
    got = list(_user13_jpeg_marks(quality, range(1, 7)))
    z = np.array([e / u for e, u, ok, _ in got if ok])
    assert len(got) >= 22 and len(z) >= 0.9 * len(got), (len(got), len(z))
    assert np.max(np.abs(z)) <= 3.0, z
    assert 0.5 <= np.sqrt(np.mean(z**2)) <= 1.2, np.sqrt(np.mean(z**2))


def test_block_phase_columns_take_the_fast_pattern_not_a_tilt():
    """Centres 4 px apart along an axis hit two phases of the 8 px block: one column,
    alternating (a mark 1.7 deg off the axis: that and its slow turn); along a 45 deg mark
    (2.83 px a step) the period-8/3 harmonic, an alias that drifts like a tilt, is left
    out. Every column is mean-free and nearly orthogonal to the position along the mark
    (the angle's column)."""
    t = np.arange(60) * 4.0
    assert block_phase_columns(100.3 + t).shape == (60, 1)
    for x, k in ((100.3 + t * np.cos(0.03), 2), (100.3 + t * np.cos(np.pi / 4), 4)):
        C = block_phase_columns(x)
        assert C.shape == (60, k), C.shape
        assert np.allclose(C.mean(axis=0), 0, atol=1e-9)
        tc = (t - t.mean()) / np.linalg.norm(t - t.mean())
        assert np.all(np.abs(tc @ C) / np.linalg.norm(C, axis=0) < 0.25), tc @ C
    alt = block_phase_columns(100.3 + t)[:, 0]
    assert np.all(np.sign(alt[1:]) == -np.sign(alt[:-1]))


def test_block_scatter_reads_the_within_block_correlation():
    """Centres two to a block sharing part of its error (rho 0.6, s 2): over 150 marks of 60
    centres the within-block correlation and the variance factor on the angle come back
    (rho's spread from ~30 pairs each, 4 sigma of the mean), and the factor is the exact
    ratio of the line's slope variance under the model to the independent one."""
    rng = np.random.default_rng(5)
    n, rho, s = 60, 0.6, 2.0
    block = np.arange(n) // 2
    t = np.arange(n) * 4.0
    X = np.column_stack([np.ones(n), t - t.mean()])
    h = np.linalg.pinv(X)[1]
    R = (1 - rho) * np.eye(n) + rho * (block[:, None] == block[None, :])
    want = s**2 * (h @ R @ h) / (h @ h)
    got = []
    for _ in range(150):
        b = rng.normal(size=n // 2)[block]
        z = s * (np.sqrt(rho) * b + np.sqrt(1 - rho) * rng.normal(size=n))
        got.append(block_scatter(z, block, h))
    rhos = np.array([g.rho for g in got])
    f = np.array([g.factor for g in got])
    assert abs(rhos.mean() - rho) <= 4 * rhos.std() / np.sqrt(len(rhos)) + 0.02, rhos.mean()
    assert abs(f.mean() / want - 1) <= 4 * f.std() / want / np.sqrt(len(f)) + 0.03, (f.mean(), want)
    # Independent centres: rho ~ 0, the factor s^2 and what taking rho >= 0 adds: rho read
    # from 30 pairs has a spread ~0.26, its positive part a mean ~0.1, i.e. ~+10 %.
    z = s * rng.normal(size=(150, n))
    f0 = np.mean([block_scatter(r, block, h).factor for r in z]) / s**2
    assert 0.97 <= f0 <= 1.15, f0


def _block_model_z(n: int, rho: float, draws: int, seed: int):
    """Angles' z (error / u from ``u_factor``) and dofs of ``draws`` marks of ``n`` centres
    two to a block sharing part of its error (rho, s 2), the line fitted as the pipeline
    does (independent centres), the scatter read from its residuals."""
    rng = np.random.default_rng(seed)
    block = np.arange(n) // 2
    t = 4.0 * np.arange(n)
    X = np.column_stack([np.ones(n), t - t.mean()])
    h = np.linalg.pinv(X)[1]
    z, dof = [], []
    for _ in range(draws):
        e = 2.0 * (np.sqrt(rho) * rng.normal(size=n // 2)[block]
                   + np.sqrt(1 - rho) * rng.normal(size=n))
        bs = block_scatter(e - X @ np.linalg.lstsq(X, e, rcond=None)[0], block, h)
        assert bs.u_factor >= bs.factor
        z.append((h @ e) / np.sqrt(bs.u_factor * (h @ h)))
        dof.append(bs.dof)
    return np.array(z), np.array(dof)


def test_block_scatter_u_carries_its_factors_own_spread():
    """A short mark's factor read from a dozen pairs is noisy (1 / F-hat's mean exceeds
    1 / F) and rho's clip at 0 halves its spread where rho ~ 0: the angle's u takes the
    factor with its estimate's spread as the block model gives it at the mark's own
    (s^2, rho) (one nu: the loop's tests take it too). 24 centres at rho 0 and 0.9 over
    150 marks: RMS z within 1 +- 3 / sqrt(2 n). Before (a Welch-Satterthwaite dof of the
    unclipped combination, bounded by the cross-boundary count): 0.72 and 1.13 (400 marks;
    after 0.94 and 1.12); the slow test has the rows."""
    for rho in (0.0, 0.9):
        z, _ = _block_model_z(24, rho, 150, 11)
        assert abs(np.sqrt(np.mean(z**2)) - 1) <= 3 / np.sqrt(2 * len(z)), (rho, z.std())


@pytest.mark.slow
@pytest.mark.parametrize("n", [24, 40, 60])
def test_block_scatter_u_covers_over_rho(n):
    """The block model over rho 0-1 (a row each, 400 marks of n centres): RMS z of the
    angle (u from ``u_factor``) within [0.8, 1.2] (the dof the loop takes printed).
    Measured (RMS z before -> after, rho 0 / 0.3 / 0.6 / 0.9 / 1):
    n 24 0.72 / 0.81 / 0.96 / 1.13 / 1.14 -> 0.94 / 1.00 / 1.09 / 1.12 / 1.11; n 40
    0.77 / 0.87 / 0.99 / 1.06 / 1.08 -> 0.98 / 1.00 / 1.02 / 1.04 / 1.06; n 60 0.83 / 0.99 /
    1.08 / 1.10 / 1.08 -> 0.97 / 1.08 / 1.10 / 1.08 / 1.06. (16 centres, a 64 px mark: up to
    1.25 at rho 0.6, rho's plug-in short there.)"""
    for rho in (0.0, 0.3, 0.6, 0.9, 1.0):
        z, dof = _block_model_z(n, rho, 400, 11)
        rms = np.sqrt(np.mean(z**2))
        print(f"n {n} rho {rho}: RMS z {rms:.2f} max |z| {np.max(np.abs(z)):.2f} "
              f"median dof {np.median(dof):.1f}")
        assert 0.8 <= rms <= 1.2, (n, rho, rms)


def test_block_labels_follow_the_grid_phase():
    xy = np.array([[0.0, 0.0], [7.0, 0.0], [8.0, 0.0], [2.0, 9.0]])
    assert len(set(block_labels(xy)[:2])) == 1 and block_labels(xy)[2] != block_labels(xy)[1]
    lab = block_labels(xy, (3, 0))  # boundaries at x = 3, 11, ...
    assert lab[0] != lab[1] and lab[1] == lab[2]


@pytest.mark.parametrize("quality,crop", [(75, (3, 5)), (50, (7, 1))])
def test_a_cropped_jpegs_grid_and_quality_are_found(quality, crop):
    """A JPEG cropped by (dx, dy) px (saved losslessly): its grid starts at (-dx, -dy) mod
    8, found from the block boundaries, and the quality is read on it (before: at the
    origin, quality ~94 for 75 or "unknown" for 50)."""
    img = _image(1, quality, angle_deg=30.0).image[crop[1]:, crop[0]:]
    jb = find_jpeg(img)
    assert jb is not None and jb.phase == ((-crop[0]) % 8, (-crop[1]) % 8), jb
    assert jb.quality is not None and abs(jb.quality - quality) <= 6, jb
    assert grid_phase(img) == jb.phase
    assert "not at the image's corner" in jpeg_note("m", jb, 1.0)


def _flat_groove_jpeg(seed: int, quality: int, crop=(3, 5)) -> np.ndarray:
    """A near-vertical groove on a flat background with 1.4 DN of noise (user 13's), a
    JPEG at ``quality`` decoded and cropped by ``crop`` (dx, dy) px: the encoder flattens
    most background blocks, and the quality is read by re-encoding the blocks."""
    import cv2

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:240, 0:320]
    img = 140 - 40 * np.exp(-0.5 * ((x - 160 - 0.02 * y) / 1.5) ** 2) + rng.normal(0, 1.4,
                                                                                  x.shape)
    _, buf = cv2.imencode(".jpg", np.clip(np.round(img), 0, 255).astype(np.uint8),
                          [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)[crop[1]:, crop[0]:]


@pytest.mark.parametrize("seed", [0, 3])
def test_a_quality_read_by_re_encoding_is_bounded_by_what_the_pixels_cannot_exclude(seed):
    """A quality-75 crop whose quality is read by re-encoding its blocks (1 DN tolerance:
    73-74 read): the qualities the coefficients' concentration on the steps cannot exclude
    run from the reading over the encoder's own, each with the noise read on its table;
    beyond it, a quality whose steps the coefficients fall between is excluded (before:
    the reading alone, the term computed on a table not the encoder's)."""
    a = _flat_groove_jpeg(seed, 75)
    jb = find_jpeg(a)
    qs = [q for q, _ in jb.candidates]
    assert np.isnan(jb.concentration) and jb.quality == qs[0] <= 74, jb
    assert 75 in qs and qs == sorted(qs) and len(qs) < 9 and qs[-1] <= qs[0] + 8, qs
    assert f"quality {qs[0]}-{qs[-1]} of the standard table" in jpeg_note("m", jb, 1.0)
    assert all(abs(n - precoding_noise(a, ijg_table(q), jb.phase)) < 1e-12
               for q, n in jb.candidates)
    # Qualities whose steps the coefficients fall between are excluded on the grid (66-68
    # read from a start of 66: their coarser (2, 0), (0, 3) steps); too few blocks to
    # tell: the reading alone.
    grid = a[jb.phase[1]:, jb.phase[0]:]
    assert not {66, 67, 68} & set(quality_candidates(grid, 66))
    assert quality_candidates(np.zeros((8, 8), np.uint8), 40) == (40,)


def test_the_files_own_table_is_taken():
    """A table read from a file's header is the encoder's: the IJG quality it is, or None
    with the table kept (another encoder's), whose round trip is its own."""
    luma = tuple(int(v) for v in ijg_table(60).ravel())
    jb = find_jpeg(np.zeros((64, 64), np.uint8), JpegTables(luma))
    assert jb.quality == 60 and jb.table == luma and table_quality(ijg_table(60)) == 60
    odd = ijg_table(60).copy()
    odd[0, 1] += 1
    assert table_quality(odd) is None
    rng = np.random.default_rng(0)
    a = np.clip(128 + 20 * rng.normal(size=(37, 45)), 0, 255)
    # The table's round trip is libjpeg's at the quality it is (the same encoder).
    by_table = jpeg_round_trip(a, None, luma, (3, 5))
    assert by_table.shape == a.shape
    assert np.mean(np.abs(by_table - jpeg_round_trip(a, 60, None, (3, 5)))) < 0.05


def test_a_stack_of_images_is_coded_as_each_alone(monkeypatch):
    """jpeg_round_trips codes a stack as one column of whole blocks: every image comes back
    as libjpeg gives it coded alone (the encoder's own padding of its partial blocks), to
    the bit, at any grid phase and size, through a quality or a table, in parts when the
    column would pass the format's height."""
    rng = np.random.default_rng(3)
    luma = tuple(int(v) for v in ijg_table(35).ravel())

    def alone(a, quality, phase):
        a = np.clip(np.round(a), 0, 255).astype(np.uint8)
        top, left = (8 - phase[1]) % 8, (8 - phase[0]) % 8
        a = np.pad(a, ((top, 0), (left, 0)), mode="edge")
        _, enc = cv2.imencode(".jpg", a, [cv2.IMWRITE_JPEG_QUALITY, quality])
        return cv2.imdecode(enc, cv2.IMREAD_GRAYSCALE).astype(float)[top:, left:]

    for k, h, w in ((5, 13, 21), (3, 8, 8), (4, 1, 30), (6, 29, 3)):
        stack = 128 + 60 * np.sin(np.arange(w) / 3.0) + rng.normal(0, 25, (k, h, w))
        phase = (int(rng.integers(8)), int(rng.integers(8)))
        out = jpeg_round_trips(stack, 35, None, phase)
        assert out.shape == stack.shape
        for a, b in zip(stack, out, strict=True):
            assert np.array_equal(b, alone(a, 35, phase))
        by_table = jpeg_round_trips(stack, None, luma, phase)
        for a, b in zip(stack, by_table, strict=True):
            assert np.array_equal(b, jpeg_round_trip(a, None, luma, phase))
        monkeypatch.setattr("imaging.jpeg.JPEG_MAX_ROWS", 2 * (h + 16))
        assert np.array_equal(jpeg_round_trips(stack, 35, None, phase), out)
        monkeypatch.undo()


def _user13_near_axis_files(quality: int, crop: bool, seeds=range(8), per_seed: int = 4,
                            as_file: bool = False):
    """User 13's renders (real lens, exact camera) of marks within 3 deg of an axis, 120-320 px
    long, written as the user has them: a JPEG file at ``quality`` (its table in the
    header), or a crop of the decoded JPEG by (dx, dy) in 0-7 px saved as PNG (``crop``: its
    grid off the corner, no table). ``as_file``: the crop sweep's marks (its seeds and
    draws) written as JPEG files instead, uncropped. Yields (error [rad], u [rad], ok,
    result) per mark."""
    ui = pytest.importorskip("tests.imaging.user13_inputs")
    import os
    import tempfile

    import cv2

    from align.marks import measure_file
    from imaging import CameraModel
    if not os.path.isdir(ui.CHESS):
        pytest.skip(f"real data not found at {ui.CHESS}")
    K, d, size, _ = ui.real_lens("left")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            rng = np.random.default_rng(1000 * quality + seed + (500 if crop else 0) + 7000)
            for _ in range(per_seed):
                ang = np.radians(rng.choice([0.0, 90.0, -90.0]) + rng.uniform(-3, 3))
                c = (rng.uniform(200, 440), rng.uniform(170, 310))
                img = ui.mark_image((K, d, size), rng, c, ang, length=rng.uniform(120, 320),
                                    width=3.0)
                dx, dy = (int(rng.integers(0, 8)), int(rng.integers(0, 8))) if crop else (0, 0)
                if as_file:
                    dx, dy = 0, 0
                K2 = K.copy()
                K2[0, 2] -= dx
                K2[1, 2] -= dy
                cam = CameraModel.load(ui.camera_json(K2, d, (size[0] - dx, size[1] - dy),
                                                      os.path.join(tmp, "cam.json")))
                _, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
                if crop and not as_file:
                    f = os.path.join(tmp, "m.png")
                    cv2.imwrite(f, cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)[dy:, dx:])
                else:
                    f = os.path.join(tmp, "m.jpg")
                    with open(f, "wb") as fh:
                        fh.write(buf.tobytes())
                for r in measure_file(f, cam):
                    if r.found:
                        ok = not (r.lens_limited or r.kinked or r.unexplained_structure
                                  or any("NOT OK" in n for n in r.notes))
                        yield angle_error(r.angle_rad, ang), r.angle_u_rad, ok, r


def _sweep_z(got, label: str) -> np.ndarray:
    """The ok marks' z (error / u) of a sweep's (error, u, ok, result) rows; its figures
    printed (RMS z, max |z|, median u) under ``label``."""
    z = np.array([e / u for e, u, ok, _ in got if ok])
    u = np.array([u for _, u, ok, _ in got if ok])
    alarms = sum(1 for *_, r in got if r.loop.effects or r.unexplained_structure)
    print(f"\n{label}: n {len(got)} ok {len(z)} RMS z {np.sqrt(np.mean(z**2)):.2f} max |z| "
          f"{np.max(np.abs(z)):.2f} median u {np.degrees(np.median(u)) * 3600:.0f}\" "
          f"loop alarms {alarms}")
    return z


@pytest.mark.slow
@pytest.mark.parametrize("quality,crop", [
    (50, False), (50, True), (75, False), (75, True),
    (90, False), (90, True)])
def test_near_axis_and_cropped_jpegs_within_u(quality, crop):
    """Marks within 3 deg of an axis (the blocks' correlated scatter: issue 18 item 4), as
    JPEG files (the table from the header) and as crops at a random grid phase (PNG): over
    8 seeds x 4 marks every ok mark within 3 u and the ok marks' RMS z within [0.5, 1.2].
    jpeg_blocks is the groove model on the mark's own path (its lens bow) put through the
    encoder 32 times with the noise read from the coefficients the encoder kept. Measured
    (before -> after: RMS z of ok marks, max |z|, ok of ~32, median u): q50 file 1.12 ->
    0.98, 3.00 -> 2.80, 27, 47 -> 48"; q50 crop 0.65 -> 0.67, 1.66 -> 1.67, 21, 141 -> 159";
    q75 file 1.27 -> 1.12, 3.03 -> 2.39, 30, 28 -> 26"; q75 crop 1.46 -> 1.35, 3.06 ->
    3.06, 30, 28 -> 31"; q90 file 0.77 -> 0.80, 1.83 -> 1.83, 32, 23 -> 22"; q90 crop 0.94
    -> 1.02, 2.96 -> 3.30, 32, 20 -> 19". Then (jcrop: a JPEG's replicas' correlation no
    longer narrows u below its own block scatter's; a quality read by re-encoding bounded
    over what the pixels cannot exclude): q50 file and crop unchanged; q75 file 1.12 ->
    1.11, 2.39 -> 2.39, 26 -> 30"; q75 crop 1.33 -> 1.33, 3.06 -> 3.09, 33 -> 29"; q90 file
    0.80 -> 0.76, 1.83 -> 1.77, 22 -> 23"; q90 crop 1.02 -> 0.91, 3.30 -> 2.51, 19 -> 21".
    Then (jq17: each coded draw's turn taken from the noise-free model's centres, the
    coding's turn and the noise's being correlated): q50 file 0.98 -> 0.87, 2.80 -> 2.38,
    52 -> 51"; q50 crop unchanged; q75 file 1.11 -> 1.01, 2.39 -> 2.29, 30 -> 30"; q75 crop
    1.33 -> 1.14, 3.09 -> 2.64, 28 -> 31"; q90 file 0.76 -> 0.70, 1.77 -> 1.77, 23 -> 24";
    q90 crop 0.91 -> 0.78, 2.51 -> 2.20, 21 -> 21". Then (jshort17: u takes the block
    scatter's factor with its estimate's spread): q50 file 0.87 -> 0.80, 2.38 -> 2.29,
    51 -> 57"; q50 crop 0.67 -> 0.61, 1.67 -> 1.53, 159 -> 169"; q75 file 1.01 -> 0.93,
    2.29 -> 2.26, 30 -> 35"; q75 crop 1.14 -> 1.03, 2.64 -> 2.53, 31 -> 35"; q90 file 0.70
    -> 0.61, 1.77 -> 1.41, 24 -> 25"; q90 crop 0.78 -> 0.74, 2.20 -> 2.11, 21 -> 23". Then
    (ju18: the factor's dof from the block model at the mark's own (s^2, rho)): q50 file
    0.80 -> 0.87, 2.29 -> 2.25, 57 -> 47"; q50 crop 0.61 -> 0.62, 1.53 -> 1.91, 169 -> 139";
    q75 file 0.93 -> 0.92, 2.26 -> 2.13, 35 -> 24"; q75 crop 1.03 -> 1.18, 2.53 -> 2.64,
    35 -> 30"; q90 file 0.61 -> 0.69, 1.41 -> 2.05, 25 -> 21"; q90 crop 0.74 -> 0.78, 2.11 ->
    2.31, 23 -> 19" (loop alarms, printed: 3 / 11 / 2 / 3 / 0 / 0)."""
    got = list(_user13_near_axis_files(quality, crop))
    z = _sweep_z(got, f"q{quality} {'crop' if crop else 'file'}")
    assert len(got) >= 28 and len(z) >= 0.6 * len(got), (len(got), len(z))
    assert np.max(np.abs(z)) <= 3.0, np.round(z, 2)
    assert 0.5 <= np.sqrt(np.mean(z**2)) <= 1.2, np.sqrt(np.mean(z**2))


def test_a_jpeg_marks_background_correlation_never_narrows_its_own_scatters_u():
    """A decoded JPEG's centres correlated by its background's replicas (``chol``): the
    replicas see the encoder's smoothing of a flat field, whose tapered correlation
    estimate at every lag narrowed a quality-90 crop's u to 0.76 of the independent fit's
    (|z| 3.30, the error the noise's). With a correlation that narrows u (lag-1 -0.4), the
    mark's u is not below its own block-correlated scatter's on the independent fit; a
    PNG's (no JPEG) stays the correlation's."""
    from dataclasses import replace

    from align.mark_stage import jpeg_correlated_floor, jpeg_scatter, noise_dof, texture_scale
    from imaging import fit_line

    (m,) = measure_frame(_image(0, 90, angle_deg=90.4).image).items
    assert m.jpeg is not None
    n = len(m.points)
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    L = np.linalg.cholesky(np.where(lag == 0, 1.0, np.where(lag == 1, -0.4, 0.0)))
    mc = replace(m, chol=L)
    plain = fit_line(m.points, m.sigma, reject_sigma=None).angle_u_rad
    gls = fit_line(m.points, m.sigma, reject_sigma=None, chol=L).angle_u_rad
    assert gls < 0.8 * plain  # the correlation narrows u: the floor has work to do
    ts = texture_scale(mc)
    assert ts == jpeg_correlated_floor(mc) > 1.0  # the floor binds
    u = fit_line(m.points, m.sigma * np.sqrt(ts), reject_sigma=None, chol=L).angle_u_rad
    assert u >= plain * np.sqrt(jpeg_scatter(mc).factor) * (1 - 1e-9)
    assert noise_dof(mc, ts) == jpeg_scatter(mc).dof  # the floor's estimate's dof
    png = replace(mc, around=replace(m.around, jpeg=None))
    assert jpeg_correlated_floor(png) == 1.0 and texture_scale(png) < ts


@pytest.mark.slow
def test_near_axis_short_marks_as_jpeg_files_within_u():
    """The quality-75 crop sweep's 32 marks (8 seeds x 4, 120-320 px, within 3 deg of an
    axis) written as JPEG files (the table in the header, the grid at the corner). A short
    mark's block-scatter factor is read from few pairs of centres across block boundaries
    (~20 on a 150 px mark): its estimate is noisy, and u from it is too small on average
    (1 / F's mean exceeds 1 / F's at F's mean). Tolerances from the noise: the ok marks'
    RMS z within 1 +- 3 / sqrt(2 n), every ok mark within 3.5 u (n = 32: P(|z| > 3.5) for
    one of 32 normal z is 1.5 %). Measured (before -> after the angle's u took the factor
    with its estimate's spread, BlockScatter.u_factor): RMS z 1.31 -> 1.14, max |z| 4.15
    -> 3.29 (seed 6 mark 3, 23 centres, -216"), ok 30 of 32, median u 30 -> 33". Then (ju18:
    the factor's dof from the block model at the mark's own (s^2, rho)): 1.14 -> 1.12, 3.29
    -> 2.41, ok 29, 33 -> 29"."""
    got = list(_user13_near_axis_files(75, True, as_file=True))
    z = _sweep_z(got, "q75 crop-sweep files")
    assert len(got) >= 28 and len(z) >= 0.6 * len(got), (len(got), len(z))
    assert np.max(np.abs(z)) <= 3.5, np.round(z, 2)
    assert abs(np.sqrt(np.mean(z**2)) - 1) <= 3 / np.sqrt(2 * len(z)), np.sqrt(np.mean(z**2))


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="slow correlated JPEG error (lag-1 r ~ +0.55, chi2/dof "
                   "~2.5 after the block columns) that the within-block model does not carry: "
                   "3 of 40 clean q75 marks 'unexplained structure' (seeds 24, 25, 30)")
def test_clean_near_axis_jpeg_marks_loop_false_alarms_at_alpha():
    """Clean straight marks within 3 deg of an axis (120-320 px, the synth's JPEG at quality
    75, exact camera): the loop adds no effect and finds no structure but at its alpha. Per
    mark at most ~5e-3 (alpha 1e-3 for the structure tests and each of the few candidates),
    so over 40 marks P(3 or more alarms) ~1e-3: at most 2. Measured: 3 of 40 before and
    after the block factor's dof (ju18; the alarms' tests are the chi2 and lag-1 ones at
    p 1e-7 to 1e-11, where no dof matters: their residuals keep a slow correlated part,
    lag-1 +0.55, that neighbour differences do not read: factor 1.0-1.15, rho 0)."""
    cam = CameraModel.from_dict({"camera_matrix": [[1000.0, 0, 319.5], [0, 1000.0, 239.5],
                                                   [0, 0, 1]],
                                 "dist_coeffs": [0.0] * 5, "image_size": [640, 480],
                                 "rms_px": 0.0, "views": 0})
    alarms, n = 0, 0
    for seed in range(40):
        rng = np.random.default_rng(seed + 4242)
        ang = np.deg2rad(rng.choice([0.0, 90.0]) + rng.uniform(-3, 3))
        length = rng.uniform(120, 320)
        spec = ImageSpec(marks=(MarkSpec(ang, rng.uniform(-20, 20), length, 4.0),),
                         width=640, height=480, bits=8, jpeg_quality=75, exposure=0.4,
                         full_well_e=full_well_for_snr(40.0, -0.6, exposure=0.4), seed=seed)
        for r in measure_image(render_marks(spec, with_crlb=False).image.astype(float), "a",
                               cam):
            if r.found:
                n += 1
                alarms += bool(r.loop.effects) or r.unexplained_structure
    print(f"\nclean q75 near-axis marks: {n}, loop alarms {alarms}")
    assert n >= 38
    assert alarms <= 2, alarms
