"""The phase-path model of the counters' quantisation against Monte Carlo: floors of a
steady phase with random per-face offsets and jitter, the variance of each mean angle over
many draws, at a dithered, a nearly period-2 and a nearly locked beat."""

from __future__ import annotations

import numpy as np
import pytest

from goniometry import beat


def floors(K: float, A: np.ndarray, R: int, sigma: float, rng
           ) -> tuple[np.ndarray, np.ndarray]:
    """Counts (R, n) of R revolutions, face k's phase r K + A_k + offset_k + jitter; and the
    true fractions of a revolution between consecutive faces."""
    n = len(A)
    a = A + rng.random(n)
    r = np.arange(R + 1)[:, None]
    th = r * K + a[None, :] + rng.normal(0, sigma, (R + 1, n))
    fl = np.floor(th)
    ends = np.concatenate([fl[:-1, 1:], fl[1:, :1]], axis=1)
    return ends - fl[:-1], np.diff(np.append(a, a[0] + K)) / K


@pytest.mark.parametrize("frac", [0.37, 0.48, 0.02])
def test_variance_of_mean_matches_monte_carlo(frac):
    rng = np.random.default_rng(int(frac * 100))
    K, R, sigma = 1000.0 + frac, 60, 0.05
    A = np.array([0.0, 250.3, 499.8, 751.6])
    draws = 3000
    err = np.empty((draws, 4))
    for i in range(draws):
        c, p = floors(K, A, R, sigma, rng)
        err[i] = K * ((c / c.sum(1, keepdims=True)).mean(0) - p)
    c, _ = floors(K, A, R, sigma, rng)
    model = beat.variance_of_mean(c, None, None, 0.0, sigma, dk=K - c.sum(1).mean())
    mc = err.var(0)
    # The Monte Carlo variance is known to sqrt(2 / draws) = 2.6 %; the model's spread of
    # dk (+-1/8R) and linearised closure add a few %.
    np.testing.assert_allclose(model, mc, rtol=0.15)


def test_jitter_fitted_from_the_pattern():
    """The jitter that the per-interval scatter (1/6 + 2 sigma^2) cannot see is read from
    the floors' steps: within its stated range over seeded logs of 200 revolutions."""
    hits = 0
    for seed in range(10):
        rng = np.random.default_rng(seed)
        K = 5000.0 + rng.random()
        A = np.array([0.0, 1250.3, 2499.8, 3751.6])
        c, _ = floors(K, A, 200, 0.06, rng)
        theta = np.arange(200)[:, None] * c.sum(1).mean() + np.zeros((1, 5))
        theta[:, 4] += c.sum(1).mean()
        _, _, (lo, best, hi) = beat.fit_pattern(c, theta, np.arange(200.0))
        hits += lo <= 0.06 <= hi
        assert 0.02 < best < 0.15
    assert hits >= 8  # a ~95 % range: 10 trials
