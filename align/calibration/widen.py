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

so ``align apply`` and the fusion, which read the covariance, use the widened u.

When the loop chose an effect but another candidate explains the data within
:data:`AMBIGUOUS_BIC` (the 14 cube poses cannot tell a cross-axis product from K2), the
shifts of the parameters between the two fits enter the same way (:func:`ambiguity_term`).
Measured on the effects of issue 19 (cross-axis products, bias hysteresis, scale-factor drift
and warm-up): docs/calibration-effects.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from align.calibration.triad import TriadModel

RECTANGULAR = np.sqrt(3.0)
"""Half-width of a rectangular distribution over its standard deviation (GUM 4.3.7)."""
AMBIGUOUS_BIC = 10.0
"""An alternative effect within this BIC of the one the loop chose is as plausible (Kass and
Raftery's 'strong' evidence starts at 6-10): the data cannot tell the two apart."""
STRUCTURE = "unexplained_structure"
AMBIGUITY = "effect_ambiguity"


@dataclass(frozen=True)
class Widening:
    """How the calibration's u was widened.

    Attributes
    ----------
    reasons : tuple of (str, str)
        Per term, why (the structure test and what it saw; the alternatives); unit —.
    names : tuple of str
        Parameters, in the covariance's order (then ``scale_factor_x..z``); unit —.
    u_noise : numpy.ndarray
        u from the noise alone, per name [the parameter's unit].
    terms : tuple of (str, numpy.ndarray)
        Per term (:data:`STRUCTURE`, :data:`AMBIGUITY`), its u per name [the parameter's
        unit] (what it adds in quadrature).
    u : numpy.ndarray
        The widened u per name [the parameter's unit].
    """

    reasons: tuple[tuple[str, str], ...]
    names: tuple[str, ...]
    u_noise: np.ndarray
    terms: tuple[tuple[str, np.ndarray], ...]
    u: np.ndarray

    @property
    def factor(self) -> np.ndarray:
        """u / u_noise per name."""
        return self.u / np.where(self.u_noise > 0, self.u_noise, np.nan)

    def to_dict(self) -> dict:
        return {"terms": {t: why for t, why in self.reasons},
                "parameters": {n: {"u_noise": float(self.u_noise[i]), "u": float(self.u[i]),
                                   "factor": float(self.factor[i]),
                                   **{t: float(v[i]) for t, v in self.terms}}
                               for i, n in enumerate(self.names)}}

    def warning(self) -> str:
        """One line for the terminal and ``warnings``: why, and by how much."""
        f = self.factor
        worst = int(np.nanargmax(f))
        k = [i for i, n in enumerate(self.names) if n.startswith("scale_factor_")]
        b = [i for i, n in enumerate(self.names) if n.startswith("bias_")]
        return (f"calibration: u widened ({'; '.join(why for _, why in self.reasons)}): "
                f"scale factors x{np.nanmin(f[k]):.3g}-{np.nanmax(f[k]):.3g}, biases "
                f"x{np.nanmin(f[b]):.3g}-{np.nanmax(f[b]):.3g}, most {self.names[worst]} "
                f"x{f[worst]:.3g} (the JSON's u_widening has each term)")


def structure_term(projection: np.ndarray, residuals_w: np.ndarray, dof: int,
                   noise_known: bool) -> tuple[np.ndarray, float]:
    """The Type B covariance for unexplained structure (see the module) and m.

    Parameters
    ----------
    projection : A (n_params, n_poses), parameters per weighted pose residual.
    residuals_w : the final fit's weighted residuals (noise unknown: residuals [g]).
    dof : degrees of freedom of the final fit (> 0).
    noise_known : whether the weights are 1/sigma of each pose (else 1).
    """
    chi2_dof = float(np.sum(residuals_w**2)) / dof
    m = np.sqrt(max(chi2_dof, 1.0)) if noise_known else np.sqrt(chi2_dof)
    u_b = m * np.sum(np.abs(projection), axis=1) / RECTANGULAR
    aat = projection @ projection.T
    s = np.sqrt(np.clip(np.diag(aat), 1e-300, None))
    return u_b[:, None] * (aat / np.outer(s, s)) * u_b[None, :], float(m)


def ambiguity_term(shifts: np.ndarray, n_params: int) -> np.ndarray:
    """The covariance for effects the data cannot tell apart: each alternative's shift of the
    nine core parameters (rows of ``shifts``) taken as the half-width of a rectangular
    distribution, summed over the alternatives (sum of d d^T / 3: its diagonal is at least
    the largest shift's square / 3)."""
    cov = np.zeros((n_params, n_params))
    cov[:9, :9] = shifts.T @ shifts / RECTANGULAR**2
    return cov


def widen(model: TriadModel, increments: list[tuple[str, str, np.ndarray]]
          ) -> tuple[TriadModel, Widening]:
    """The model with ``increments`` (term, why, covariance) added to its covariance."""
    names = (*model.names, *(f"scale_factor_{ax}" for ax in "xyz"))

    def us(m: TriadModel) -> np.ndarray:
        return np.concatenate([[m.u_of(n) for n in m.names], m.sensitivity_u()])

    u0 = us(model)
    terms = []
    for term, _, cov in increments:
        alone = us(replace(model, cov=model.cov + cov))
        terms.append((term, np.sqrt(np.clip(alone**2 - u0**2, 0, None))))
    wide = replace(model, cov=model.cov + sum(c for _, _, c in increments))
    return wide, Widening(tuple((t, why) for t, why, _ in increments), names, u0,
                          tuple(terms), us(wide))
