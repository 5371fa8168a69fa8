"""A family's ruling steps and the lines it misses (align/family.py)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from align.family import family_gaps, line_family, ruling_steps, shading_shift, t_sd
from align.warnings import family_warnings


def _positions(steps: np.ndarray, pitch: float, k1: float, half: float) -> np.ndarray:
    """Positions [px] of a ruling imaged through a barrel lens: each one's distance from
    the centre shrunk by (1 + k1 (x / half)^2)."""
    x = (steps - steps.mean()) * pitch
    return x * (1 + k1 * (x / half) ** 2)


def test_steps_through_a_barrel_lens_skip_nothing():
    """23 lines at 70 px through k1 -0.06 at the frame's half-width (the gaps shrink from
    70 to ~63 px at the sides): every step counted once. The smallest gap taken as the step
    for the whole ruling put a skipped step where no line was missing."""
    k = np.arange(23.0)
    q = _positions(k, 70.0, -0.06, 800.0)
    gaps = np.diff(q)
    assert gaps.min() < 0.93 * gaps.max()  # the case: the pitch varies across the frame
    old = np.rint((q - q[0]) / gaps.min())
    assert list(old) != list(k)  # what the old count did here
    assert list(ruling_steps(q)) == list(k)


def test_missing_lines_are_named_and_not_ok():
    """A ruling found on steps 0, 1, 3, 4, 6 of its pitch (the dense ruling's old result):
    steps 2 and 5 named as missing, on the family's line, in its warnings and its block,
    and the family's marks not ok; a complete ruling has none."""
    steps = np.array([0, 1, 3, 4, 6])
    rng = np.random.default_rng(3)
    q = 24.0 * steps + rng.normal(0, 0.05, steps.size)
    a = np.full(steps.size, np.deg2rad(89.7)) + rng.normal(0, 1e-5, steps.size)
    n = np.array([np.sin(a[0]), np.cos(a[0])])
    mids = q[:, None] * n[None, :]
    fam = line_family(range(5), a, np.full(5, 1e-5), mids, np.full(5, 0.05))
    assert fam.steps == tuple(steps)
    assert fam.missing_steps == (2, 5)
    assert abs(fam.pitch_px - 24.0) < 5 * fam.pitch_u_px
    assert "LINES MISSING at steps 2, 5" in fam.summary()
    assert fam.to_dict()["missing_steps"] == [2, 5]
    said = family_warnings("scale.tif", fam)
    assert any("step(s) 2, 5" in w and "not ok" in w for w in said), said
    assert family_gaps(SimpleNamespace(family=fam)) == (2, 5)
    assert family_gaps(SimpleNamespace(family=None)) == ()
    full = line_family(range(7), np.full(7, a[0]), np.full(7, 1e-5),
                       (24.0 * np.arange(7.0))[:, None] * n[None, :], np.full(7, 0.05))
    assert full.missing_steps == () and not family_warnings("scale.tif", full)


def test_lens_bounds_fitted_chi2_per_dof_one_whatever_the_lens():
    """15 members whose angles a bounded lens direction turns apart (a p1-like trend across
    the frame, 4 times their own u at the ends; a common turn, 10 times): chi2/dof ~1 over
    200 draws with no lens and with one at its bound, alike, and a tilted member still
    named. Carried as a u (the range as a spread) chi2/dof was 0.93 and 1.14 (400 draws):
    what the lens is, not whether the lines are parallel."""
    rng = np.random.default_rng(3)
    n = 15
    u = np.full(n, 1e-4)
    x = np.linspace(-1, 1, n)
    couplings = [{"lens_p1_range": 4e-4 * v, "lens_aspect_range": 1e-3, "lens_fit": 2e-5 * v}
                 for v in x]
    idx = list(range(n))
    mids = np.column_stack([x * 300, np.zeros(n)])
    means = []
    for lam in (0.0, np.sqrt(3)):
        chis = []
        for _ in range(200):
            a = 1.0 + u * rng.standard_normal(n) + lam * 4e-4 * x
            f = line_family(idx, a, u, mids, np.full(n, 0.1), lens_coupling=couplings)
            assert f.lens_fitted == 1 and f.dof == n - 2
            chis.append(f.chi2_dof)
        means.append(np.mean(chis))
    # 200 draws of chi2/13: each mean's sd is sqrt(2 / 13 / 200) = 0.028, their difference's
    # 0.039 (3.2 and 3 of them).
    assert abs(means[0] - 1) < 0.09 and abs(means[1] - 1) < 0.09, means
    assert abs(means[1] - means[0]) < 0.12, means
    a = 1.0 + u * rng.standard_normal(n) + np.sqrt(3) * 4e-4 * x
    a[5] += 1e-3  # a graduation tilted 10 u
    f = line_family(idx, a, u, mids, np.full(n, 0.1), lens_coupling=couplings)
    assert f.deviant == (5,) and not f.consistent()


def test_pitch_u_counts_its_scatter_dof_and_the_shading():
    """The pitch's u from 6 lines' residual scatter (4 dof) is taken times t's standard
    deviation sqrt(4 / 2); the background shading's moves of the members' centres (gamma M2
    along each one's normal, gamma growing across the scale as under vignetting) enter by
    their slope over the steps, in quadrature, and are said in the block."""
    steps = np.arange(6.0)
    a = np.full(6, 0.3)
    n = np.array([np.sin(0.3), np.cos(0.3)])
    res = np.array([0.02, -0.03, 0.01, 0.03, -0.02, -0.01])
    mids = (41.0 * steps + res)[:, None] * n[None, :]
    plain = line_family(range(6), a, np.full(6, 1e-5), mids, np.full(6, 1e-4))
    fitted = res - np.polyval(np.polyfit(steps, res, 1), steps)
    s = np.sqrt(np.sum(fitted**2) / 4)
    kc = steps - steps.mean()
    assert np.isclose(plain.pitch_u_px, s * np.sqrt(2) / np.sqrt(kc @ kc))
    # gamma from -4e-4 to +4e-4 /px across the scale, M2 3 px^2: moves -1.2e-3 .. 1.2e-3 px
    moves = np.array([shading_shift(0.3, 4.0, np.sqrt(3 - 16 / 12), 1000.0, g)
                      for g in np.linspace(-0.4, 0.4, 6)])
    assert np.allclose(moves @ n, 3e-3 * np.linspace(-0.4, 0.4, 6))
    shaded = line_family(range(6), a, np.full(6, 1e-5), mids, np.full(6, 1e-4), shading=moves)
    slope = 3e-3 * 0.8 / 5
    assert np.isclose(shaded.pitch_u_shading_px, slope)
    assert np.isclose(shaded.pitch_u_px, np.hypot(plain.pitch_u_px, slope))
    assert shaded.to_dict()["pitch_u_shading_px"] == shaded.pitch_u_shading_px
    assert t_sd(1) == t_sd(3) == np.sqrt(3) and np.isclose(t_sd(7), np.sqrt(7 / 5))
