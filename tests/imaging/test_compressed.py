"""The compressed least-squares problem (imaging.compressed): what the solver sees is the
full problem's, so its steps and answer are too."""

from __future__ import annotations

import numpy as np
from scipy import optimize

from imaging.compressed import compressed


def test_compressed_keeps_norm_gradient_and_normal_matrix():
    """|f|, J'^T f and J'^T J' equal the full problem's |r|, J^T r and J^T J (to rounding),
    for a well-posed J and for a rank-deficient one (its QR path)."""
    rng = np.random.default_rng(0)
    r = rng.normal(size=500)
    for J in (rng.normal(size=(500, 4)), np.repeat(rng.normal(size=(500, 2)), 2, axis=1)):
        f, Jc = compressed(r, J)
        assert f.shape == (5,) and Jc.shape == (5, 4)
        assert np.isclose(f @ f, r @ r, rtol=1e-12)
        assert np.allclose(Jc.T @ f, J.T @ r, rtol=1e-9, atol=1e-9 * np.abs(J.T @ r).max())
        assert np.allclose(Jc.T @ Jc, J.T @ J, rtol=1e-9, atol=1e-9 * np.abs(J.T @ J).max())


def test_bounded_fit_on_the_compressed_problem_is_the_full_fit():
    """A bounded trust-region fit (a decaying exponential plus level, 2000 noisy samples,
    one start per seed) reaches the same parameters and cost from the compressed problem."""
    t = np.linspace(0, 5, 2000)
    for seed in range(5):
        rng = np.random.default_rng(seed)
        y = 2.0 * np.exp(-1.3 * t) + 0.5 + 0.01 * rng.normal(size=t.size)

        def resid(q, y=y):
            return q[0] * np.exp(-q[1] * t) + q[2] - y

        def jac(q):
            ex = np.exp(-q[1] * t)
            return np.column_stack([ex, -q[0] * t * ex, np.ones_like(t)])

        bounds = ([0, 0, -1], [10, 10, 1])
        x0 = [1.0, 0.5, 0.0]
        full = optimize.least_squares(resid, x0, jac=jac, bounds=bounds)
        comp = optimize.least_squares(lambda q: compressed(resid(q), jac(q))[0], x0,
                                      jac=lambda q: compressed(resid(q), jac(q))[1],
                                      bounds=bounds)
        assert np.allclose(comp.x, full.x, rtol=1e-8, atol=1e-10)
        assert np.isclose(comp.cost, full.cost, rtol=1e-10)
