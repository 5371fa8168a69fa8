"""imaging.texture: a noise-free background holds no texture (issue 18: never a confident wrong
answer), and a noisy one is measured as before."""

from __future__ import annotations

import numpy as np
import pytest

import imaging.texture
from imaging import measure_marks
from tests.conftest import angle_error, mark_image

# The case: a 1000 px, 4 px wide mark in a 1024 x 1024 frame, blur 1.2 px.
FRAME = {"length_px": 1000.0, "offset_px": 9.3, "size": (1024, 1024), "blur_px": 1.2,
         "with_crlb": False}


# Near each pixel axis and at a general angle in the default run; the rest slow.
@pytest.mark.parametrize("angle", [0.25, pytest.param(10.0, marks=pytest.mark.slow), 37.0,
                                   pytest.param(60.0, marks=pytest.mark.slow), 89.9])
def test_noise_free_render_gives_the_angle_within_its_u(angle):
    """The expected electrons (no photon noise): the replicas beside the band hold only
    float rounding, and the texture's control variate was a ratio of rounding errors
    (37 deg came out 1571" off at u 0.0019"). Now no texture is found and the angle is right
    within 3 u (the u is the groove model's misfit, the only "noise" left)."""
    s = mark_image(angle, seed=0, **FRAME)
    (m,) = measure_marks(s.mean_e)
    err = angle_error(m.line.angle_rad, s.truth.marks[0].image_angle_rad)
    assert abs(err) <= 3 * m.line.angle_u_rad
    tex = m.centres.texture
    assert tex is not None and tex.acf is None and tex.coupling_px2 == 0.0
    # No correlation from texture (nor from removed stripes: none on this image).
    assert m.chol is None and m.centres.offsets_cov is None


@pytest.mark.parametrize("snr", [3000.0])
def test_noisy_render_is_untouched_by_the_noise_free_guard(snr, monkeypatch):
    """With photon noise the replicas hold ~the white variance (1e6 x the guard's level):
    the measurement is the same to the bit with the guard switched off, the coupling is
    estimated (non-zero), and the angle is within its u."""
    s = mark_image(37.0, seed=1, snr=snr, **FRAME)
    img = s.image.astype(float)
    (m,) = measure_marks(img)
    monkeypatch.setattr(imaging.texture, "QUIET", 0.0)
    (m0,) = measure_marks(img)
    assert m.line.angle_rad == m0.line.angle_rad
    assert m.line.angle_u_rad == m0.line.angle_u_rad
    assert m.centres.texture.coupling_px2 != 0.0
    # 4.5 sigma: a 1-in-150000 event for an honest u.
    err = angle_error(m.line.angle_rad, s.truth.marks[0].image_angle_rad)
    assert abs(err) < 4.5 * m.line.angle_u_rad
    assert np.isfinite(m.line.angle_u_rad)


def test_control_variate_is_not_moved_by_a_segment_without_contrast():
    """A segment of almost no contrast (a JPEG-coded end of user 13's q75 mark, seed 2) has
    a ring regressor of ~1e12 /px and a centre u of ~1e14 px. In a plain mean of the
    regressor it moved every centre of the mark by ~1e11 px (CI: LinAlgError downstream);
    weighted as the line weighs the centres, the control is the shading-free one the other
    segments give alone, to rounding."""
    rng = np.random.default_rng(3)
    reg = 1e-3 + 2e-4 * rng.normal(size=40)
    sigma = np.full(40, 0.05)
    ok = np.ones(40, bool)
    tex = imaging.texture.TextureModel.__new__(imaging.texture.TextureModel)
    object.__setattr__(tex, "coupling_px2", 0.7)
    rest = ok.copy()
    rest[0] = False
    clean = imaging.texture.texture_control(tex, reg, rest, sigma)
    reg2, sigma2 = reg.copy(), sigma.copy()
    reg2[0], sigma2[0] = 1.3e12, 2.0e14
    got = imaging.texture.texture_control(tex, reg2, ok, sigma2)
    assert np.all(np.abs(got[1:] - clean[1:]) < 1e-9 * np.abs(clean).max()), got[1:5]
    # The centred control takes out no mean shading (weighted as the line weighs them).
    assert abs(np.sum(clean[1:] / sigma[1:]**2)) < 1e-12 * np.sum(np.abs(clean) / sigma**2)
