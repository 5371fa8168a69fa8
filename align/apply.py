"""The platform-frame calibration of a triad and its application to readings.

The triad model (seed paper, u = K R (a_c + b) with its effects) gives the per-axis calibrated
reading w = R a_c = |r_i| s_i . a_P; the fusion gives where the axes point on the platform,
the unit rows s_i of M. Hence the specific force in the platform frame

    a_P = M^-1 (w / |r|)            [g]

which is the seed paper's calibration placed in the platform frame (the limitation its
authors state, removed).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from align.calibration import TriadModel, model_from_dict, model_to_dict, r_matrix
from align.errors import InputError
from align.fusion import E_NAMES, axes_from, e_matrix


@dataclass(frozen=True)
class PlatformCalibration:
    """Triad model plus the misalignment E [rad] (6 angles in ``E_NAMES`` order) and its
    6x6 covariance [rad^2]."""

    model: TriadModel
    e6: np.ndarray
    cov: np.ndarray

    @property
    def axes(self) -> np.ndarray:
        return axes_from(self.e6)

    def to_dict(self) -> dict:
        return {"frame": "platform: X, Y horizontal, Z up; row i = accelerometer i",
                "model": model_to_dict(self.model),
                "misalignment_rad": e_matrix(self.e6).tolist(),
                "misalignment_u_rad": e_matrix(np.sqrt(np.diag(self.cov))).tolist(),
                "angle_names": list(E_NAMES), "angles_rad": self.e6.tolist(),
                "angles_covariance_rad2": self.cov.tolist(),
                "axes": self.axes.tolist()}

    @classmethod
    def from_dict(cls, d: dict, where: str) -> PlatformCalibration:
        d = d.get("platform_calibration", d)
        try:
            model = model_from_dict(d["model"], where)
            e6 = np.array(d["angles_rad"], float).reshape(6)
            cov = np.array(d["angles_covariance_rad2"], float).reshape(6, 6)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: not a platform calibration ({exc!s}); expected the "
                             "JSON that 'align run --json' or '--calibration' writes") from None
        return cls(model, e6, cov)

    @classmethod
    def load(cls, path: str | Path) -> PlatformCalibration:
        p = Path(path)
        try:
            d = json.loads(p.read_text())
        except FileNotFoundError:
            raise InputError(f"{p}: no such file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{p}: not JSON ({exc})") from None
        if not isinstance(d, dict):
            raise InputError(f"{p}: not a platform calibration")
        return cls.from_dict(d, str(p))

    def specific_force(self, u: np.ndarray, t: np.ndarray | float = 0.0,
                       temp: np.ndarray | float | None = None) -> np.ndarray:
        """Specific force in the platform frame (N, 3) [g] from outputs u (N, 3)."""
        m = self.model
        R = r_matrix(m.beta)
        w = m.specific_force(u, t, temp) @ R.T
        w = w / np.linalg.norm(R, axis=1)
        return np.linalg.solve(self.axes, w.T).T
