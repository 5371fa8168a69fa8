"""The reported scale factors are the triad's sensitivities: output per g along each sensitive
axis (k_i |r_i(beta)|), with their uncertainty propagated from (k, beta).

The triad here is written from the physics, not from the model's parametrisation: axis i reads
u_i = s_i (n_i . a) + o_i with n_i a unit vector and s_i its sensitivity.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration import calibrate, poses_from_samples
from align.calibration.ellipsoid import r_matrix, row_norms

ARCSEC = np.pi / 180 / 3600


def _triad(rng, e_arcsec):
    E = rng.normal(0, e_arcsec * ARCSEC, (3, 3))
    np.fill_diagonal(E, 0)
    n = np.eye(3) + E
    return n / np.linalg.norm(n, axis=1, keepdims=True), 1 + rng.normal(0, 1e-3, 3), \
        rng.normal(0, 5e-3, 3)


def _cube(rng):
    faces = np.vstack([np.eye(3), -np.eye(3)])
    corners = np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)],
                       float) / np.sqrt(3)
    d = np.vstack([faces, corners, rng.normal(size=(4, 3))]) + rng.normal(0, 4e-3, (18, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _fit(seed, e_arcsec, sigma, n=50):
    rng = np.random.default_rng(seed)
    axes, s, o = _triad(rng, e_arcsec)
    d = _cube(rng)
    pid = np.repeat(np.arange(len(d)), n)
    u = ((d @ axes.T) * s + o)[pid] + rng.normal(0, sigma, (len(pid), 3))
    return calibrate(poses_from_samples(pid, u, pid * 0.5)), s


def test_row_norm_jacobian_is_the_derivative():
    beta = np.array([3e-3, -0.2, 0.1])
    n, J = row_norms(beta)
    assert np.allclose(n, np.linalg.norm(r_matrix(beta), axis=1), rtol=0, atol=1e-15)
    h = 1e-6
    num = np.array([(np.linalg.norm(r_matrix(beta + h * e), axis=1)
                     - np.linalg.norm(r_matrix(beta - h * e), axis=1)) / (2 * h)
                    for e in np.eye(3)]).T
    assert np.allclose(J, num, rtol=0, atol=1e-9)


def test_noise_free_sensitivities_are_exact_where_the_models_k_is_not():
    """~17' non-orthogonality: K differs from the sensitivity by ~1e-5 (beta^2/2), the
    reported scale factors are the truth to rounding."""
    cal, s = _fit(1, 1000.0, 1e-12)
    m = cal.model
    assert np.abs(m.sensitivity() - s).max() < 1e-10
    assert np.abs(m.k - s).max() > 3e-6       # what was reported before
    d = cal.to_dict(poses_from_samples(np.zeros(3, int), np.eye(3), np.zeros(3)))
    assert np.allclose(d["scale_factors_v_per_g"], s, rtol=0, atol=1e-10)
    assert d["model"]["k_v_per_g"] == m.k.tolist()    # apply's model keeps its K
    assert "sensitive axis" in d["scale_factor_definition"]


@pytest.mark.slow
def test_sensitivities_against_truth_over_seeds():
    """20 seeded triads, ~17' non-orthogonality, 2e-5 per sample: z = (s - truth)/u has
    RMS ~1 (a 4.5 bound on 60 values: 7e-6 false-alarm chance for a normal z)."""
    z = []
    for seed in range(20):
        cal, s = _fit(100 + seed, 1000.0, 2e-5)
        z.append((cal.model.sensitivity() - s) / cal.model.sensitivity_u())
    z = np.array(z)
    assert np.abs(z).max() < 4.5, z
    assert 0.6 < np.sqrt(np.mean(z ** 2)) < 1.4, np.sqrt(np.mean(z ** 2))


@pytest.mark.parametrize("seed", [3, 4])
def test_sensitivity_u_is_at_least_k_u_scaled(seed):
    """At small beta the propagated u is k's u times |r| (beta adds only second order)."""
    cal, _ = _fit(seed, 60.0, 2e-5)
    m = cal.model
    uk = np.array([m.u_of(f"k_{ax}") for ax in "xyz"])
    assert np.allclose(m.sensitivity_u(), uk, rtol=1e-3)
