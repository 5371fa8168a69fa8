"""Segment fits of the groove's centres (imaging.centres): which segments are solved."""

from __future__ import annotations

import numpy as np

from imaging import measure_marks
from imaging.centres import (
    MIN_CV_REPLICAS,
    RCOND,
    _conditioned,
    _surely_conditioned,
    sample_centres,
)
from imaging.groove import centres_half
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
