"""Roll and pitch from a static accelerometer (tilt paper), vectorised.

G = R_xyz g  ->  G/|G| = (-sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)).

``exact`` (default): phi = atan2(Gy, Gz), theta = atan2(-Gx, hypot(Gy, Gz)); phi is
undefined only when Gy = Gz = 0 (x axis vertical), where it is set to 0.
``paper``: the tilt paper's regularised roll phi = atan2(Gy, sign(Gz) sqrt(Gz^2 + mu Gx^2)),
mu = 0.001, sign(0) = +1. It is biased everywhere, by about -(mu/2) tan^2(theta) tan(phi)
rad: 5e-4 rad at 45 deg pitch and 45 deg roll, far above what the calibration reaches.
Angles in radians.
"""

from __future__ import annotations

import numpy as np


def roll_pitch(G: np.ndarray, method: str = "exact", mu: float = 0.001
               ) -> tuple[np.ndarray, np.ndarray]:
    """Roll phi in (-pi, pi] and pitch theta in [-pi/2, pi/2] [rad] for G (N, 3) (any unit)."""
    G = np.atleast_2d(np.asarray(G, float))
    gx, gy, gz = G[:, 0], G[:, 1], G[:, 2]
    pitch = np.arctan2(-gx, np.hypot(gy, gz))
    if method == "exact":
        roll = np.arctan2(gy, gz)
        # Only where the roll is truly undefined (x axis vertical) is a convention needed.
        roll = np.where((gy == 0) & (gz == 0), 0.0, roll)
    elif method == "paper":
        sign = np.where(gz >= 0, 1.0, -1.0)
        roll = np.arctan2(gy, sign * np.sqrt(gz * gz + mu * gx * gx))
    else:
        raise ValueError(f"unknown tilt method {method!r}: use 'exact' or 'paper'")
    return roll, pitch


def gravity_from_angles(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Unit G for given roll and pitch (the forward model of eq. 6)."""
    return np.column_stack([-np.sin(pitch), np.cos(pitch) * np.sin(roll),
                            np.cos(pitch) * np.cos(roll)])
