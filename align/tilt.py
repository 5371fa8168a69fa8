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

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from align.calibration import read_readings
from axisbase.console import captured_warnings
from axisbase.output import csv_text
from axisbase.table import Table


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


FAR_FROM_1G = 0.1
"""|1 - |a|| [g] beyond which a reading is flagged: tilt assumes the specific force is
gravity alone. A calibrated static triad reads 1 g within ~1e-3 g (calibration residuals of
micro-g, local gravity within ±0.3 % of the calibration's), so no static reading trips it, while
free fall, a shock, the wrong unit or the wrong calibration (|a| off by far more) do."""


@dataclass(frozen=True)
class TiltOfReadings:
    """Roll and pitch of every reading through a calibration.

    Attributes
    ----------
    t : numpy.ndarray or None
        Times [s] (None when the readings have none).
    a : numpy.ndarray
        The calibrated specific force (N, 3) [g] (in ``frame``).
    roll, pitch : numpy.ndarray
        Per reading [rad].
    method : str
        ``exact`` or ``paper`` (the tilt paper's regularised roll); unit —.
    mu : float
        The paper's regularisation — dimensionless.
    warnings : tuple of str
        What the user must know about the result; unit —.
    frame : str
        ``platform`` (a platform calibration: its misalignment applied) or ``triad`` (a triad
        calibration alone: the triad's own calibration frame); unit —.
    """

    t: np.ndarray | None
    a: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    method: str
    mu: float
    warnings: tuple[str, ...] = ()
    frame: str = "triad"
    """``platform`` (a platform calibration: its misalignment applied) or ``triad`` (a triad
    calibration alone: the triad's own calibration frame)."""

    @property
    def far_from_1g(self) -> int:
        """Readings with |1 - |a|| > :data:`FAR_FROM_1G`."""
        return int(np.count_nonzero(~(np.abs(np.linalg.norm(self.a, axis=1) - 1)
                                      <= FAR_FROM_1G)))

    def to_dict(self) -> dict:
        """The summary ``align tilt --json`` writes (degrees at this edge)."""
        return {"warnings": list(self.warnings), "frame": self.frame, "method": self.method,
                "mu": self.mu if self.method == "paper" else None,
                "samples": len(self.a),
                "roll_deg_mean": float(np.rad2deg(np.mean(self.roll))),
                "pitch_deg_mean": float(np.rad2deg(np.mean(self.pitch))),
                "roll_deg_std": float(np.rad2deg(np.std(self.roll))),
                "pitch_deg_std": float(np.rad2deg(np.std(self.pitch))),
                "norm_minus_1_ug": float((np.linalg.norm(self.a, axis=1) - 1).mean() * 1e6),
                "far_from_1g": self.far_from_1g}

    def csv_text(self) -> str:
        """``t,roll_deg,pitch_deg``; t blank on every row when the readings had no time."""

        return csv_text(["t", "roll_deg", "pitch_deg"],
                        [self.t, np.rad2deg(self.roll), np.rad2deg(self.pitch)], "%.9g",
                        exact=("t",))


SCALE_GAP_K = 100.0
"""Readings this far from the calibration's reference temperature [K] are on another scale
(°C against K: 273 K apart), not at another temperature a triad is used in."""


def model_time_warnings(model, t, temp) -> list[str]:
    """What a reader of readings without times (or temperatures) must know when the model
    has a drift (or a temperature term): it is taken at the model's reference value."""
    out = []
    if t is None and (np.any(model.drift != 0) or np.any(model.drift2 != 0)):
        out.append(f"the readings have no time but the calibration models a drift: it is "
                   f"taken at the calibration's reference time {model.t_ref:g} s (give a "
                   "t column or --rate)")
    if temp is None and np.any(model.temp_coeff != 0):
        out.append("the readings have no temperature but the calibration models one: "
                   f"taken at its reference {model.temp_ref:g} (give a temp column)")
    temp_model = np.any(model.temp_coeff != 0) or np.any(model.scale_temp != 0)
    if temp is not None and temp_model and np.nanmax(np.abs(temp - model.temp_ref)) > SCALE_GAP_K:
        out.append(f"the readings' temperatures ({np.nanmin(temp):g} to {np.nanmax(temp):g}) lie "
                   f"more than {SCALE_GAP_K:g} K from the calibration's reference "
                   f"{model.temp_ref:g} K: one file in °C, the other in K? say the unit in both "
                   "headers (temp [K] or temp [degC])")
    return out


def calibrated_force(cal, tab) -> tuple[np.ndarray | None, np.ndarray, list[str]]:
    """The one path from readings to specific force, shared by ``align tilt`` and ``align
    apply``: times (None when ``tab`` has none), the specific force (N, 3) [g] of readings
    ``tab`` (ux, uy, uz[, t][, temp]) through ``cal`` — a ``TriadModel`` or
    ``TriadCalibration`` (the triad's own calibration frame; a not-ok one warned) or a
    ``PlatformCalibration`` (the platform frame: its misalignment
    applied) — and the warnings of :func:`model_time_warnings`."""
    model = getattr(cal, "model", cal)
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    t, temp = tab.get("t"), tab.get("temp")
    warnings = model_time_warnings(model, t, temp)
    if hasattr(cal, "not_ok_warning"):  # a calibration file: was it (or its session) ok?
        warnings = cal.not_ok_warning() + warnings
    a = cal.specific_force(u, model.t_ref if t is None else t, temp)
    return t, a, warnings


def read_readings_noted(path: str | Path, columns=None, rate_hz: float | None = None,
                        time_unit: str | None = None) -> tuple[Table, list[str]]:
    """Readings ``ux,uy,uz[,t][,temp]`` as :func:`align.calibration.read_readings` reads them,
    with the warnings the reader gave on how it read the file (a median sample interval no
    logger has: "were the times in ms?", logger lines skipped before the header).

    Parameters
    ----------
    path : str or Path
        The readings CSV.
    columns : mapping of str to str, optional
        Header names for the format's columns (``--columns``).
    rate_hz : float, optional
        Sample rate [Hz] of a file without a time column.
    time_unit : str, optional
        The time column's unit when its header says none.

    Returns
    -------
    (Table, list of str)
        The readings, and the reader's warnings: taken off the log so that the result
        carries them (its JSON's ``warnings``) and the terminal says each once.
    """
    with captured_warnings() as read:
        tab = read_readings(path, columns, rate_hz, time_unit)
    return tab, list(read)


def tilt_of_readings(model, tab, method: str = "exact", mu: float = 0.001,
                     read_warnings: Sequence[str] = ()) -> TiltOfReadings:
    """Roll and pitch of readings ``tab`` (a table with ux, uy, uz[, t][, temp]) through
    ``model``: a triad model (``TriadModel`` or ``TriadCalibration``: roll and pitch of its own
    calibration frame) or a
    platform calibration (``PlatformCalibration``: the platform's roll and pitch, as ``align
    apply --tilt`` gives them, through :func:`calibrated_force`). Readings without times get
    none; if the model drifts, its drift is taken at the reference time and a warning says so
    (likewise a temperature model without temperatures). Readings far from 1 g are counted in
    a warning. ``read_warnings``: what the reader said of the file
    (:func:`read_readings_noted`), first among the result's warnings."""
    t, a, warnings = calibrated_force(model, tab)
    warnings = [*read_warnings, *warnings]
    frame = getattr(model, "tilt_frame", "triad")
    roll, pitch = roll_pitch(a, method=method, mu=mu)
    res = TiltOfReadings(t, a, roll, pitch, method, mu, frame=frame)
    far = res.far_from_1g
    if far:
        norm = np.linalg.norm(a, axis=1)
        warnings.append(f"{far} of {len(a)} readings have |a| more than {FAR_FROM_1G:g} g from "
                        f"1 g (|a| {np.nanmin(norm):.3g} to {np.nanmax(norm):.3g} g): not "
                        "static, free fall, a shock, the wrong unit or the wrong calibration; "
                        "their roll and pitch are not a tilt")
    return TiltOfReadings(t, a, roll, pitch, method, mu, tuple(warnings), frame)
