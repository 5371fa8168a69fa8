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

from dataclasses import dataclass

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


@dataclass(frozen=True)
class TiltOfReadings:
    """Roll and pitch [rad] of every reading (times ``t`` [s]) through a calibration, and
    the calibrated specific force ``a`` (N, 3) [g]."""

    t: np.ndarray
    a: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    method: str
    mu: float

    def summary(self) -> dict:
        """The summary ``align tilt --json`` writes (degrees at this edge)."""
        return {"method": self.method, "mu": self.mu if self.method == "paper" else None,
                "samples": len(self.a),
                "roll_deg_mean": float(np.rad2deg(np.mean(self.roll))),
                "pitch_deg_mean": float(np.rad2deg(np.mean(self.pitch))),
                "roll_deg_std": float(np.rad2deg(np.std(self.roll))),
                "pitch_deg_std": float(np.rad2deg(np.std(self.pitch))),
                "norm_minus_1_ug": float((np.linalg.norm(self.a, axis=1) - 1).mean() * 1e6)}

    def csv_text(self) -> str:
        from axisbase.output import csv_text

        return csv_text(["t", "roll_deg", "pitch_deg"],
                        [self.t, np.rad2deg(self.roll), np.rad2deg(self.pitch)], "%.9g")


def tilt_of_readings(model, tab, method: str = "exact", mu: float = 0.001) -> TiltOfReadings:
    """Roll and pitch of readings ``tab`` (a table with ux, uy, uz[, t][, temp]) through a
    triad ``model`` (``TriadModel``); readings without times are taken at the model's
    reference time."""
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    t = tab["t"] if "t" in tab else np.full(len(u), model.t_ref)
    a = model.specific_force(u, t, tab.get("temp"))
    roll, pitch = roll_pitch(a, method=method, mu=mu)
    return TiltOfReadings(t, a, roll, pitch, method, mu)
