"""Tilt: the exact form against truth, and the paper's regularised roll's bias."""

from __future__ import annotations

import numpy as np
import pytest

from align.tilt import gravity_from_angles, roll_pitch


def test_exact_form_recovers_angles_everywhere():
    rng = np.random.default_rng(0)
    roll = rng.uniform(-np.pi, np.pi, 100000)
    pitch = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6, 100000)
    G = gravity_from_angles(roll, pitch) * 9.81
    r, p = roll_pitch(G)
    assert np.max(np.abs(np.angle(np.exp(1j * (r - roll))))) < 1e-12
    assert np.max(np.abs(p - pitch)) < 1e-12


def test_paper_regularised_roll_is_biased_as_predicted():
    roll, pitch = np.deg2rad(45.0), np.deg2rad(45.0)
    G = gravity_from_angles(np.array([roll]), np.array([pitch]))
    r_paper, _ = roll_pitch(G, method="paper", mu=0.001)
    r_exact, _ = roll_pitch(G)
    predicted = -(0.001 / 2) * np.tan(pitch) ** 2 * np.tan(roll)
    assert r_paper[0] - roll == pytest.approx(predicted, rel=0.01)  # -5e-4 rad
    assert abs(r_exact[0] - roll) < 1e-12


def test_x_axis_vertical_is_defined():
    r, p = roll_pitch(np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]))
    assert np.all(r == 0) and np.allclose(p, [-np.pi / 2, np.pi / 2])
    r2, _ = roll_pitch(np.array([[1.0, 0.0, 0.0]]), method="paper")
    assert np.isfinite(r2).all()
    with pytest.raises(ValueError):
        roll_pitch(np.ones((1, 3)), method="guess")
