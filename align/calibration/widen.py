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

When the loop chose an effect but the poses cannot tell it from another candidate, the
parameters are averaged over the plausible models (:func:`ambiguity_term`): each alternative's
shift of the parameters from the chosen fit (as the half-width of a rectangular distribution)
and whatever u the alternative's own fit has beyond the chosen one's. An alternative is
plausible when either

* it explains the data within :data:`AMBIGUOUS_BIC` of the chosen set (the noise cannot tell
  them apart), or
* it is *aliased* with the effect it replaces on these poses: its regressors reproduce at
  least :data:`ALIASED` of what the chosen effect explained (its chi2 drop from the fit
  without either, over the chosen effect's: the squared correlation of the alternative's
  regressors with the chosen effect's fitted signal, the model's own parameters projected
  out). Then only the last fraction tells the two apart, and a model error of that size —
  a real triad's effect is never exactly one candidate's shape — decides between them
  whatever the BIC says: on the seed paper's 14 poses a cross-axis product, K2 and a bias
  drift each explain 99.9 % of one another's signal, and the wrong one won by 12 in BIC.
Measured on the effects of issue 19 (cross-axis products, bias hysteresis, scale-factor drift
and warm-up): docs/calibration-effects.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from align.calibration.triad import TriadModel

RECTANGULAR = np.sqrt(3.0)
"""Half-width of a rectangular distribution over its standard deviation (GUM 4.3.7)."""
AMBIGUOUS_BIC = 10.0
"""An alternative effect within this BIC of the one the loop chose is as plausible (Kass and
Raftery's 'strong' evidence starts at 6-10): the data cannot tell the two apart."""
ALIASED = 0.99
"""An alternative that reproduces this fraction of the chosen effect's chi2 drop is aliased
with it on these poses (squared correlation of the regressors along the fitted signal; the
poses of ``align calibrate --plan 28`` keep the candidates of issue 19 below it)."""
USEFUL_FACTOR = 10.0
"""The ambiguity term may widen u of a scale factor, an axis angle or a bias to at most this
many times what the noise allows: beyond, the number covers the effects' spread but is no
measurement of the triad (a hysteresis on the paper's 14 poses: u of k 1.2 %, 1.5e4 x its
noise u) and the result is marked not ok with the pose order that tells them apart."""
STRUCTURE = "unexplained_structure"
AMBIGUITY = "effect_ambiguity"


NO_EFFECT = "the declared model (no effect added)"


def effect_set(effects: str) -> str:
    """A set of effects as a message names it: ``effects`` (joined by " + "), or
    :data:`NO_EFFECT` when the set is empty (the loop added none)."""
    return effects or NO_EFFECT


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
    alternatives : tuple of Alternative
        The sets of effects the :data:`AMBIGUITY` term averages over; unit — (each names its
        own units).
    """

    reasons: tuple[tuple[str, str], ...]
    names: tuple[str, ...]
    u_noise: np.ndarray
    terms: tuple[tuple[str, np.ndarray], ...]
    u: np.ndarray
    alternatives: tuple[Alternative, ...] = ()

    @property
    def factor(self) -> np.ndarray:
        """u / u_noise per name."""
        return self.u / np.where(self.u_noise > 0, self.u_noise, np.nan)

    def to_dict(self) -> dict:
        return {"terms": {t: why for t, why in self.reasons},
                "parameters": {n: {"u_noise": float(self.u_noise[i]), "u": float(self.u[i]),
                                   "factor": float(self.factor[i]),
                                   **{t: float(v[i]) for t, v in self.terms}}
                               for i, n in enumerate(self.names)},
                "alternatives": [a.to_dict() for a in self.alternatives]}

    def undetermined(self, chosen: Sequence[str], plan_n: int, wander: str) -> str | None:
        """Why the result is not ok, when the alternative *effects* (not ``wander``, the
        bias's own instability: u then says what the sensor allows) widen u of one of the
        nine core parameters (k, beta, bias) beyond :data:`USEFUL_FACTOR` x its noise u (the
        alternative that moves it most named), else None."""
        alts = [a for a in self.alternatives if a.effects != wander]
        if not alts:
            return None
        var = sum(a.shift**2 / RECTANGULAR**2 + np.diag(a.excess) for a in alts)
        u0 = self.u_noise[:9]
        f = np.sqrt(1 + var / np.where(u0 > 0, u0, np.inf) ** 2)
        j = int(np.argmax(f))
        if not f[j] > USEFUL_FACTOR:
            return None
        ranked = sorted(alts, key=lambda a: -abs(a.shift[j]))
        alt = ranked[0]
        # Every alternative u covers is named, not only the one that moves the parameter
        # most: which one that is changes from seed to seed (a pure bias drift on user 14's
        # tumble named "nonlinearity_k2 and scale_drift", then "scale_drift and
        # scale_asymmetry", with bias_drift among the others), and the true effect may be any
        # of them.
        rest = [effect_set(a.effects) for a in ranked[1:]]
        nor = f", nor from {', '.join(rest)}" if rest else ""
        return (f"calibration NOT OK: {effect_set(' + '.join(chosen))} and "
                f"{effect_set(alt.effects)} cannot be told "
                f"apart on this pose order{nor} (u of {self.names[j]} widened x{f[j]:.3g} to "
                f"cover {'all' if rest else 'both'}, > {USEFUL_FACTOR:g}x its noise u; the JSON "
                f"keeps the widened u): measure with `align calibrate --plan {plan_n}`")

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
                   noise_known: bool, bound: bool = False) -> tuple[np.ndarray, float]:
    """The Type B covariance for unexplained structure (see the module) and m.

    Parameters
    ----------
    projection : A (n_params, n_poses), parameters per weighted pose residual.
    residuals_w : the final fit's weighted residuals (noise unknown: residuals [g]).
    dof : degrees of freedom of the final fit (> 0).
    noise_known : whether the weights are 1/sigma of each pose (else 1).
    bound : take the worst case itself as u, not as a rectangular half-width — for a fit
        with fewer residual degrees of freedom than parameters (the known-pose fit: 12
        parameters, 6 dof on six faces), where most of a systematic error lies in the
        parameters' span and the residual shows too little of it to judge its distribution
        (a 50 µg hysteresis on six faces: k_y, k_z 4 u off with the rectangular u).
    """
    chi2_dof = float(np.sum(residuals_w**2)) / dof
    m = np.sqrt(max(chi2_dof, 1.0)) if noise_known else np.sqrt(chi2_dof)
    return bound_cov(projection, m, 1.0 if bound else RECTANGULAR), float(m)


def bound_cov(gain: np.ndarray, half_width: float, divisor: float = RECTANGULAR
              ) -> np.ndarray:
    """The covariance of a systematic error bounded by ``half_width`` in each input of
    ``gain`` (parameters per input, (n_params, n_inputs)): the worst case moves parameter
    j by a_j = half_width sum_i |gain_ji|, u_j = a_j / ``divisor`` (rectangular: sqrt 3),
    with the correlations of gain gain^T [products of the parameters' units]."""
    u_b = half_width * np.sum(np.abs(gain), axis=1) / divisor
    aat = gain @ gain.T
    s = np.sqrt(np.clip(np.diag(aat), 1e-300, None))
    return u_b[:, None] * (aat / np.outer(s, s)) * u_b[None, :]


@dataclass(frozen=True)
class Alternative:
    """A set of effects that explains the data about as well as the loop's choice.

    Attributes
    ----------
    effects : str
        Its effects, joined by " + "; unit —.
    replaces : str
        The chosen effect it replaces ("" for another fit the loop tried); unit —.
    d_bic : float
        Its BIC minus the chosen set's — dimensionless.
    explained : float
        The fraction of the replaced effect's chi2 drop it reproduces (NaN when it replaces
        none) — dimensionless.
    shift : numpy.ndarray
        Its nine core parameters (k, beta, bias) minus the chosen fit's [their units].
    excess : numpy.ndarray
        (9, 9) its core covariance beyond the chosen fit's (the positive part) [products of
        their units].
    """

    effects: str
    replaces: str
    d_bic: float
    explained: float
    shift: np.ndarray
    excess: np.ndarray

    @property
    def aliased(self) -> bool:
        return bool(self.explained >= ALIASED)

    def to_dict(self) -> dict:
        return {"effects": self.effects, "replaces": self.replaces or None,
                "delta_bic": self.d_bic,
                "explained": None if not np.isfinite(self.explained) else self.explained,
                "aliased": self.aliased}


def positive_part(cov: np.ndarray) -> np.ndarray:
    """The positive semi-definite part of a symmetric matrix (negative eigenvalues to 0)."""
    w, v = np.linalg.eigh((cov + cov.T) / 2)
    return (v * np.clip(w, 0, None)) @ v.T


def ambiguity_term(alts: list[Alternative], n_params: int) -> np.ndarray:
    """The covariance for effects the data cannot tell apart (model averaging over the
    plausible alternatives, each counted in full whatever its BIC): each alternative's shift
    of the nine core parameters taken as the half-width of a rectangular distribution, and its
    own covariance beyond the chosen fit's, summed over the alternatives (the diagonal is at
    least the largest shift's square / 3)."""
    cov = np.zeros((n_params, n_params))
    for a in alts:
        cov[:9, :9] += np.outer(a.shift, a.shift) / RECTANGULAR**2 + a.excess
    return cov


def ambiguity_reason(chosen: tuple[str, ...], alts: list[Alternative], plan_n: int) -> str:
    """Why u was widened for the alternatives, and what to record when they are aliased."""
    close = [a for a in alts if not a.aliased]
    aliased = [a for a in alts if a.aliased]
    parts = []
    if aliased:
        by = {}
        for a in aliased:
            by.setdefault(a.replaces, []).append(a)
        parts.append("; ".join(
            f"these poses cannot tell {c} from " + ", ".join(
                f"{a.effects} ({a.explained:.2%} of its signal)" for a in group)
            for c, group in by.items())
                     + f": record the poses of `align calibrate --plan {plan_n}`")
    near = [a for a in close if a.d_bic < AMBIGUOUS_BIC]
    allowed = [a for a in close if not a.d_bic < AMBIGUOUS_BIC]  # (the wander, by its level)
    for group, why in ((near, f"within {AMBIGUOUS_BIC:g} of BIC"),
                       (allowed, "at a level the samples within the poses allow")):
        if group:
            parts.append("the data cannot tell the effects added (" + (" + ".join(chosen)
                                                                       or "none")
                         + ") from " + ", ".join(a.effects for a in group) + f" ({why})")
    return "; ".join(parts) + ": u covers the parameters' spread over them"


def widen(model: TriadModel, increments: list[tuple[str, str, np.ndarray]],
          alternatives: Sequence[Alternative] = ()) -> tuple[TriadModel, Widening]:
    """The model with ``increments`` (term, why, covariance) added to its covariance
    (``alternatives``: those the ambiguity term averages over, for the record)."""
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
                          tuple(terms), us(wide), tuple(alternatives))
