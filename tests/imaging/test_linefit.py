"""The line fit's direction-only form (``fit_line_only``) against the full fit."""

from __future__ import annotations

import numpy as np
import pytest

from imaging.linefit import fit_line, fit_line_only


@pytest.mark.parametrize("seed", range(12))
def test_fit_line_only_is_fit_line_to_the_bit(seed: int) -> None:
    """The same angle and offset as fit_line (reject_sigma None) to the last bit, with
    independent and with correlated points, at angles across the whole range (the wrap at
    +-90 deg flips the offset's sign)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 200))
    angle = rng.uniform(-np.pi / 2, np.pi / 2) if seed % 3 else np.pi / 2 - 1e-9 * seed
    u = np.array([np.cos(angle), -np.sin(angle)])
    t = np.sort(rng.uniform(-300, 300, n))
    sigma = rng.uniform(0.02, 0.2, n)
    pts = np.outer(t, u) + np.outer(rng.normal(0, sigma) + 7.5, [-u[1], u[0]])
    chol = None
    if seed % 2:
        lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        chol = np.linalg.cholesky(0.6 ** lag)
    full = fit_line(pts, sigma, reject_sigma=None, chol=chol)
    assert fit_line_only(pts, sigma, chol=chol) == (full.angle_rad, full.offset_px)


def test_fit_line_only_refuses_as_fit_line() -> None:
    """Too few points, or a non-finite one among correlated points: the same refusal."""
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, np.nan], [3.0, 0.0]])
    with pytest.raises(ValueError, match="too few"):
        fit_line_only(pts[:2], np.ones(2))
    with pytest.raises(ValueError, match="correlated"):
        fit_line_only(pts, np.ones(4), chol=np.eye(4))
    with pytest.raises(ValueError, match="correlated"):
        fit_line(pts, np.ones(4), reject_sigma=None, chol=np.eye(4))
