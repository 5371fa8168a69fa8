"""Segment fits of the groove's centres (imaging.centres): which segments are solved, and
the stretch they are sampled on (to the groove's ends, short of what covers one)."""

from __future__ import annotations

import numpy as np
import pytest

from imaging import measure_marks
from imaging.centres import (
    MIN_CV_REPLICAS,
    RCOND,
    Centres,
    _conditioned,
    _surely_conditioned,
    sample_centres,
    sample_centres_batch,
)
from imaging.groove import centres_half
from imaging.jpeg import jpeg_round_trip
from synth.marks import ImageSpec, MarkSpec, _mark_band, mark_coverage
from synth.occlusion import disk, occlude
from tests.conftest import mark_image


def _normal(J: np.ndarray) -> np.ndarray:
    return J.T @ J


def test_a_nearly_singular_segment_is_not_solved_whatever_the_rounding():
    """A segment whose centre and contrast columns are the same to 1e-9 (its pixels on one
    flank: the two not separated) has det(N) > 0 by rounding, or < 0, depending on noise of
    1e-14 in its pixels: the old test (det > 0) flipped with it. Its reciprocal condition
    (~1e-18) is far below RCOND, so it is refused under every such perturbation; a
    well-posed segment (independent columns) is solved under all of them."""
    rng = np.random.default_rng(1)
    x = np.linspace(-1, 1, 60)
    base = np.column_stack([x, x * (1 + 1e-9 * x**2), np.ones_like(x), x**2])
    good = np.column_stack([np.tanh(3 * x), np.exp(-x**2), np.ones_like(x), x])
    dets = []
    for _ in range(20):
        noise = 1 + 1e-14 * rng.standard_normal(base.shape)
        N = np.stack([_normal(base * noise), _normal(good * noise)])
        dets.append(np.linalg.det(N[0]) > 0)
        assert _conditioned(N).tolist() == [False, True]
    assert set(dets) == {True, False}  # rounding alone decided the old test here


def test_rcond_is_scale_free():
    """The test reads the matrix at unit diagonal: the columns' units (px, DN, DN/px) or a
    contrast of 1e4 DN do not decide it."""
    x = np.linspace(-1, 1, 60)
    J = np.column_stack([np.tanh(3 * x), np.exp(-x**2), np.ones_like(x), x])
    N = _normal(J)
    D = np.diag([1e4, 1e-3, 1.0, 50.0])
    assert _conditioned(np.stack([N, D @ N @ D])).tolist() == [True, True]
    assert 0 < RCOND < 1e-6


def test_texture_coupling_from_too_few_replicas_is_not_applied():
    """The texture's coupling (a control variate on the centres) estimated from n replica
    series adds ~1/n of the centres' noise variance, not in their u: with lines beside the
    mark taking all but one series (avoid_px, as a dial's graduations 30 deg apart do) it is
    not applied (a graduation moved 0.9 u by it), and the centres are those without the
    texture model; from the 8 series of a free mark it is."""
    s = mark_image(23.0, seed=2, length_px=200.0, size=(640, 480), with_crlb=False,
                   texture=0.02)
    img = s.image.astype(float)
    (m,) = measure_marks(img)
    pf = m.profile
    shifts = [k * (centres_half(pf) + 4) for k in (2, 4, 6, 8)]
    one = sample_centres(img, pf, texture=True,
                         avoid_px=[x + 5.0 for x in shifts[1:]] + [-x for x in shifts])
    assert one.texture.replicas == 1 and one.texture.coupling_px2 == 0.0
    assert np.array_equal(one.xy, sample_centres(img, pf).xy)
    full = sample_centres(img, pf, texture=True)
    assert full.texture.replicas >= MIN_CV_REPLICAS and full.texture.coupling_px2 != 0.0


def test_conditioning_by_pivots_decides_as_the_eigenvalues():
    """The pivots' shortcut (_surely_conditioned) is only a proof: over segments from well
    posed to singular beyond rounding (a contrast column equal to the centre's to 1e-12 ..
    1), scaled columns, indefinite and NaN matrices, _conditioned says what the eigenvalue
    rule lam_min > RCOND lam_max at unit diagonal says, and the shortcut settles most."""
    rng = np.random.default_rng(3)
    n = 2000
    J = rng.normal(size=(n, 30, 4))
    J[:, :, 1] = J[:, :, 0] + 10 ** rng.uniform(-12, 0, size=(n, 1)) * J[:, :, 1]
    N = np.einsum("npi,npj->nij", J, J) * 10 ** rng.uniform(-3, 3, size=(n, 1, 1))
    N[:20] = -N[:20]
    N[20:30] = rng.normal(size=(10, 4, 4)) + np.swapaxes(rng.normal(size=(10, 4, 4)), 1, 2)
    N[30, 1, 2] = np.nan
    d = np.einsum("nii->ni", N)
    ok = np.all(d > 0, axis=1)
    s = 1.0 / np.sqrt(np.where(ok[:, None], d, 1.0))
    C = N * s[:, :, None] * s[:, None, :]
    with np.errstate(invalid="ignore"):
        lam = np.linalg.eigvalsh(np.nan_to_num(C))
    expect = ok & (lam[:, 0] > RCOND * lam[:, -1]) & np.isfinite(C).all(axis=(1, 2))
    got = _conditioned(N)
    assert got.tolist() == expect.tolist()
    assert 0.3 * n < expect.sum() < 0.9 * n  # both answers well represented
    assert _surely_conditioned(C).sum() > 0.5 * expect.sum()


def test_a_batch_of_images_gives_each_its_own_centres_to_the_bit():
    """sample_centres_batch (the JPEG term's draws measured in one pass) gives every image
    the very centres sample_centres gives it alone, every field to the bit: images at
    different noise (their own noise models and weights' floors), one re-encoded as a
    JPEG, one moved 1 px across the groove (more steps before it stops), one with dust on
    the groove (a segment that misfits: binned apart from the others), and one with a
    clipped pixel in the band (measured alone)."""
    s = mark_image(1.5, seed=4, length_px=200.0, size=(320, 240), bits=8)
    img = s.image.astype(float)
    (m,) = measure_marks(img)
    pf = m.profile
    rng = np.random.default_rng(7)
    images = [np.clip(np.round(img + rng.normal(0.0, sd, img.shape)), 1, 254)
              for sd in (0.5, 1.0, 1.0, 2.0, 4.0, 8.0)]
    images.append(jpeg_round_trip(images[1], 50))
    images.append(np.roll(images[1], 1, axis=0))
    dusty = images[2].copy()
    dusty[129:135, 150:156] = 20.0
    images.append(dusty)
    clipped = images[3].copy()
    clipped[131, 100] = 0.0
    images.append(clipped)
    batch = sample_centres_batch(np.stack(images), pf)
    for im, got in zip(images, batch, strict=True):
        alone = sample_centres(im, pf)
        for f in Centres.__dataclass_fields__:
            a, b = getattr(alone, f), getattr(got, f)
            assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True), f
    # The cases were there: moved 1 px, dust misfitting its segment.
    assert abs(np.median(batch[7].xy[:, 1] - batch[1].xy[:, 1]) - 1.0) < 0.1
    assert batch[8].chi2_red.max() > 3 * np.median(batch[8].chi2_red)


def _occluded_end(seed: int, level: float, r: float = 9.0):
    """A 300 px groove whose end lies 3 px under an opaque particle of radius ``r`` (level
    0.05: black; 1.6: bright), rendered by synth.occlusion, with shot and read noise: the
    image, the groove's direction and normal, and the particle's centre (frame px)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-np.pi / 2, np.pi / 2)
    m = MarkSpec(a, rng.uniform(-100, 100), 300.0, 4.0, rng.uniform(-40, 40), "box", -0.6)
    spec = ImageSpec(marks=(m,), width=640, height=480, blur_px=1.2)
    refl = np.ones((480, 640))
    rr, cc = _mark_band(spec, m, 7 * 1.2 + 3)
    refl[rr, cc] += m.contrast * mark_coverage(spec, m, rr, cc)
    ua, na = np.array([np.cos(a), -np.sin(a)]), np.array([np.sin(a), np.cos(a)])
    c = m.offset_px * na + (m.centre_t_px + m.length_px / 2 - 3.0) * ua
    occlude(refl, [disk(float(c[0]), float(c[1]), r, level=level)], [m], 1.2)
    full = 4000.0
    e = rng.poisson(refl * 0.6 * full) + rng.normal(0.0, 3.0, refl.shape)
    return np.clip(np.round(e * 65535 / full), 0, 65535), ua, na, m.offset_px, c


@pytest.mark.parametrize("level", [0.05, 1.6])
def test_centres_reach_a_clean_end_and_stop_short_of_a_particle(level):
    """The centres run over the whole groove (imaging.ends.centres_stretch), out to its
    clean end (within 10 px of it: a blurred end, ~4.4 px, short of its half-depth point, and
    the last segment's half; they stopped 20-25 px short, where the search's ridge
    faded), but none lies on or past the particle over its other end, black or bright
    (the nearest stays ~7 px clear of its edge: the blurred end is trimmed), and that end
    is said to be hidden."""
    r = 9.0
    img, ua, na, off, c = _occluded_end(0, level, r)
    (m,) = measure_marks(img)
    assert np.abs(m.points @ na - off).max() < 0.5  # the groove's own centres
    s = (m.points - c) @ ua  # along the groove from the particle's centre, outward
    assert s.max() < -r, s.max()
    assert s.min() < -(300.0 - 3.0) + 10.0, s.min()
    assert sum(m.ends_check.ends.hidden) == 1
