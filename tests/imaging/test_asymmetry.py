"""imaging.asymmetry: the groove's odd departure segment by segment (issue 18, user 18's wear).

The per-segment estimator against a known one-sided depth change on a 1-D groove
rendered here (pixels as a list, Gaussian noise), and the test's false-alarm count on
segments whose asymmetry does not change (binomial at alpha). User 18's worn marks over
seeds: tests/align/test_independent_user18.py (wear) and the changelog.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import erf
from scipy.stats import binom

from imaging.asymmetry import ALPHA, SegmentAsymmetry, asymmetry_angle, segment_asymmetry


def _groove(eps_by_seg, rng, noise=0.01, width=3.0, blur=0.8):
    """Segments of a Gaussian-ish groove (depth 1), one side's depth changed by eps_k; each
    segment fitted (centre, contrast, level) by one linearised step at the truth.

    Returns the arrays segment_asymmetry takes and the centres' true bias per segment."""
    e1 = np.arange(-10.0, 10.0 + 1e-9, 0.25)
    nseg = len(eps_by_seg)
    seg = np.repeat(np.arange(nseg), len(e1))
    e = np.tile(e1, nseg)
    prof = np.exp(-0.5 * (e / width) ** 2)
    amp = -np.ones_like(e)
    side = erf(e / (np.sqrt(2.0) * blur))
    eps = np.asarray(eps_by_seg).take(seg)
    data = 1.0 + amp * prof * (1 + eps * side * 0.5) + rng.normal(0, noise, e.size)
    pe = -e / width ** 2 * prof
    J = [-(amp * pe), prof, np.ones_like(e)]
    wgt = np.full(e.size, 1 / noise ** 2)
    N = np.zeros((nseg, 3, 3))
    b = np.zeros((nseg, 3))
    r0 = data - (1.0 + amp * prof)
    for i in range(3):
        b[:, i] = np.bincount(seg, wgt * J[i] * r0, nseg)
        for j in range(3):
            N[:, i, j] = np.bincount(seg, wgt * J[i] * J[j], nseg)
    cov = np.linalg.inv(N)
    step = np.einsum("nij,nj->ni", cov, b)
    r = r0 - sum(step[seg, i] * J[i] for i in range(3))
    return (e, prof, r, amp, wgt, J, cov, np.ones(nseg, bool), seg), step[:, 0]


def test_segment_asymmetry_reads_a_one_sided_depth_change():
    """eps within 4 sigma of the truth on every segment, and its shift the centre's bias."""
    rng = np.random.default_rng(1)
    truth = np.array([0.0, 0.05, -0.05, 0.1])
    args, bias = _groove(truth, rng, noise=0.002)
    a = segment_asymmetry(*args, blur=0.8)
    z = (a.eps - truth) / np.sqrt(a.eps_var)
    assert np.all(np.abs(z) < 4), z
    # the centres' bias the fit absorbed, within the noise's share of it
    assert np.allclose(a.shift_per_eps * truth, bias, atol=4 * 0.002 * 3), (a.shift_per_eps, bias)


def test_asymmetry_angle_finds_a_step_and_not_a_constant():
    """A step in eps over 40 % of the mark tilts the line: found, its term covers the tilt;
    a constant eps (the offset only) and pure noise: found at most at the binomial count."""
    t = np.linspace(-130, 130, 61)
    sigma = np.full(61, 0.03)
    k = np.full(61, 1.9)
    var = np.full(61, 0.02 ** 2)
    step = np.where(t > 130 - 0.4 * 260, -0.05, 0.0)
    got = asymmetry_angle(SegmentAsymmetry(step, var, k), np.arange(61), t, sigma)
    w = np.ones(61)
    g = (t - t.mean()) / np.sum((t - t.mean()) ** 2) * w
    assert got.found and got.u_rad >= abs(g @ (k * step))
    const = asymmetry_angle(SegmentAsymmetry(np.full(61, -0.05), var, k), np.arange(61), t,
                            sigma)
    assert not const.found and const.u_rad == 0.0
    rng = np.random.default_rng(7)
    n = 1000
    found = sum(asymmetry_angle(SegmentAsymmetry(rng.normal(0, 0.02, 61), var, k),
                                np.arange(61), t, sigma).found for _ in range(n))
    # false alarms at alpha: more than the binomial's 1e-4 upper quantile would be a bug
    assert found <= binom.ppf(1 - 1e-4, n, ALPHA), found


@pytest.mark.slow
def test_clean_synth_marks_false_alarms_at_alpha():
    """synth's clean marks (no asymmetry; angles, widths, SNR, texture, gradients drawn per
    seed): the test rejects at most the binomial 1e-4 upper quantile of n at ALPHA, and its
    p-values are not piled up near 0 (seen: 0 of 150 found, p < 0.05 on 4.7 %)."""
    from imaging import measure_marks
    from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks

    ps = []
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        spec = ImageSpec(marks=(MarkSpec(np.deg2rad(rng.uniform(-89, 89)), rng.uniform(-40, 40),
                                         rng.uniform(250, 450), rng.uniform(2.5, 6)),),
                         width=640, height=480,
                         full_well_e=full_well_for_snr(rng.uniform(15, 60), -0.6),
                         texture=rng.choice([0.0, 0.01]),
                         gradient=(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)), seed=seed)
        for m in measure_marks(render_marks(spec, with_crlb=False).image.astype(float),
                               expect_one=True):
            if not isinstance(m, Exception) and m.asymmetry is not None:
                ps.append(m.asymmetry.p_tilt)
    ps = np.array(ps)
    assert len(ps) >= 50
    assert np.sum(ps < ALPHA) <= binom.ppf(1 - 1e-4, len(ps), ALPHA), ps.min()
    # (p uniform: below 0.05 on 5 %; more than the binomial 1e-4 quantile is not noise)
    assert np.sum(ps < 0.05) <= binom.ppf(1 - 1e-4, len(ps), 0.05), np.sort(ps)[:10]
