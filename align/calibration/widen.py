"""Widening the calibration's uncertainty for structure no effect explains (a Type B term).

When the residual loop ends with structure in the residual, the model lacks something; the
parameters then carry an error the noise-only covariance does not state. The unexplained part
is treated as a systematic error of each pose mean, of the size the residual implies:

    m = sqrt(max(chi2 / dof, 1))                [in units of each pose's sigma; noise unknown:
                                                 the residual's own RMS, weights 1]

A systematic error does not average out over the poses as noise does: the worst case of
|dr_p| <= m on every pose moves parameter j by at most a_j = m sum_p |A_jp|, where A is the
map from the (weighted) pose residuals to the parameters of the final fit (dtheta = A dr).
Taken as a rectangular distribution of half-width a_j (GUM 4.3.7), the Type B term is
u_B,j = a_j / sqrt(3); it enters the covariance with the correlations of A A^T:

    cov = cov_noise + D_B C D_B,   C = corr(A A^T),  D_B = diag(u_B)

so ``align apply`` and the fusion, which read the covariance, use the widened u. Measured on
the effects of issue 19 (cross-axis products, bias hysteresis, scale-factor drift and warm-up,
none of them in the model): |err| / u <= 2.5 for every parameter over seeds
(docs/calibration-effects.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from align.calibration.triad import TriadModel

RECTANGULAR = np.sqrt(3.0)
"""Half-width of a rectangular distribution over its standard deviation (GUM 4.3.7)."""


@dataclass(frozen=True)
class Widening:
    """How the calibration's u was widened for unexplained structure.

    Attributes
    ----------
    reason : the structure test that called for it and what it saw.
    misfit : m, the systematic error assumed on each pose [its sigma; with the noise unknown,
        g].
    noise_known : whether ``misfit`` is in sigma (True) or in g (False).
    names : parameters, in the covariance's order (then ``scale_factor_x..z``).
    u_noise : u from the noise alone, per name [the parameter's unit].
    u_unexplained : the Type B term u_B, per name [the parameter's unit].
    u : the widened u, sqrt(u_noise^2 + u_B^2), per name [the parameter's unit].
    """

    reason: str
    misfit: float
    noise_known: bool
    names: tuple[str, ...]
    u_noise: np.ndarray
    u_unexplained: np.ndarray
    u: np.ndarray

    @property
    def factor(self) -> np.ndarray:
        """u / u_noise per name."""
        return self.u / np.where(self.u_noise > 0, self.u_noise, np.nan)

    def to_dict(self) -> dict:
        return {"reason": self.reason, "term": "type B: unexplained systematic error per "
                "pose, worst case over the poses, rectangular", "misfit_per_pose": self.misfit,
                "misfit_unit": "sigma" if self.noise_known else "g",
                "parameters": {n: {"u_noise": float(a), "u_unexplained": float(b),
                                   "u": float(c), "factor": float(f)}
                               for n, a, b, c, f in zip(self.names, self.u_noise,
                                                        self.u_unexplained, self.u,
                                                        self.factor, strict=True)}}

    def warning(self) -> str:
        """One line for the terminal and ``warnings``: why, and by how much."""
        f = self.factor
        worst = int(np.nanargmax(f))
        k = [i for i, n in enumerate(self.names) if n.startswith("scale_factor_")]
        b = [i for i, n in enumerate(self.names) if n.startswith("bias_")]
        size = (f"{self.misfit:.3g} sigma" if self.noise_known
                else f"{self.misfit * 1e6:.3g} µg")
        return (f"calibration: u widened for the unexplained structure ({self.reason}): a "
                f"Type B term for a systematic error of {size} per pose; "
                f"scale factors x{np.nanmin(f[k]):.3g}-{np.nanmax(f[k]):.3g}, biases "
                f"x{np.nanmin(f[b]):.3g}-{np.nanmax(f[b]):.3g}, most {self.names[worst]} "
                f"x{f[worst]:.3g} (the JSON's u_widening has each)")


def widen(model: TriadModel, projection: np.ndarray, residuals_w: np.ndarray, dof: int,
          noise_known: bool, reason: str) -> tuple[TriadModel, Widening]:
    """The model with its covariance widened by the Type B term (see the module).

    Parameters
    ----------
    model : the final fit, its ``cov`` from the noise.
    projection : A (n_params, n_poses), parameters per weighted pose residual.
    residuals_w : the final fit's weighted residuals (noise unknown: residuals [g]).
    dof : degrees of freedom of the final fit (> 0).
    noise_known : whether the weights are 1/sigma of each pose (else 1).
    reason : what the structure test saw (for the warning).
    """
    chi2_dof = float(np.sum(residuals_w**2)) / dof
    m = np.sqrt(max(chi2_dof, 1.0)) if noise_known else np.sqrt(chi2_dof)
    u_b = m * np.sum(np.abs(projection), axis=1) / RECTANGULAR
    aat = projection @ projection.T
    s = np.sqrt(np.clip(np.diag(aat), 1e-300, None))
    corr = aat / np.outer(s, s)
    cov = model.cov + u_b[:, None] * corr * u_b[None, :]
    wide = replace(model, cov=cov)
    names = (*model.names, *(f"scale_factor_{ax}" for ax in "xyz"))
    u0 = np.concatenate([[model.u_of(n) for n in model.names], model.sensitivity_u()])
    u1 = np.concatenate([[wide.u_of(n) for n in model.names], wide.sensitivity_u()])
    ub = np.sqrt(np.clip(u1**2 - u0**2, 0, None))
    return wide, Widening(reason, float(m), noise_known, names, u0, ub, u1)
