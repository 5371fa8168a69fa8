"""The declared scale-factor stability: a Type B term for a scale wander the poses cannot show.

A scale factor that wanders with the room's temperature (an HVAC cycle of ±1 K at 100 ppm/K
is ±100 ppm over a quarter of an hour) changes every pose mean by a relative ε(t) of its
output, and the fit turns most of it into k and the biases: a common ε is k itself, an ε
that differs between a pose and its opposite (k g and −k g) is a bias of (ε₊ − ε₋)/2 g. Per
pose the change is a few σ at most, so neither the residual tests nor an effect in time
(linear, warm-up) need see it; only a temperature column (the loop's ``scale_temp``) or the
user's statement of how stable the scale is can bound it.

Propagation. The final fit is θ = θ̂ − A r_w, A = (JᵀJ)⁻¹Jᵀ the map from the weighted pose
residuals (:mod:`align.calibration.widen`). A relative change ε_pa of pose p's reading on
axis a changes its output by ε_pa u_pa, its residual |a_p| − 1 by (∂|a_p|/∂u_pa) u_pa ε_pa
and so, with the weights W (1/σ_p, or the whitening of a bias walk), every parameter by

    dθ = G ε,   G = A W D,   D[p, 3p + a] = (∂|a_p|/∂u_pa) u_pa      [parameter unit per 1]

(the known-pose fit is linear: G = ∂θ/∂y · diag(y)). The declaration "each axis's scale
stays within ±X of one value over the run" lets every ε_pa lie anywhere in [−X, X], in
any pattern in time; the worst case moves parameter j by X Σ |G_j·|, which is taken as
the half-width of a rectangular distribution (GUM 4.3.7): u_j = X Σ |G_j·| / √3, with the
correlations of G Gᵀ (the structure term's form, :func:`~align.calibration.widen.bound_cov`).
For k this is X k / √3 (k's row of G sums to k with one sign); for a bias about X g / √3
(the ±X pattern across opposite poses); for the angles β about X rad / √3 (a pattern that
differs between the axes of one pose tilts the fitted frame).

When the poses carry no temperature column and nothing is declared, no term is added and
the result *states* that the scale factors were assumed stable over the run (JSON
``scale_stability``, a line under the calibration table): :data:`TYPICAL_PPM` says why a
user should think about it.
"""

from __future__ import annotations

import math

import numpy as np

from align.errors import InputError

TYPICAL_PPM = 20.0
"""A scale-factor stability typical of a run in an air-conditioned room [ppm] (±, each axis),
quoted in the statement made when nothing is declared — not applied. The room: an air
conditioner holds ±1 K in a cycle of ~15 min. The sensor: a scale factor temperature
coefficient of 100 ppm/K (navigation-grade quartz servo accelerometers, QA-2000: < 180
ppm/°C; the better MEMS, ADXL355: ±100 ppm/°C; the BMI160 states ±300 ppm/K). Between them
the triad's own thermal mass: a block in its housing follows the air with a time constant of
10-20 min, which passes 1/sqrt(1 + (2 pi tau / P)^2) = 0.16-0.23 of a 15-min cycle: ±0.2 K
inside, ±20 ppm.

Why it is not the default: the term is a worst case over *any* pattern of the wander across
the poses (each pose's reading anywhere within ±X), and such patterns mimic the angles β as
well as k and the biases — on the demo's 14 poses ±20 ppm widens k ×23, the biases ×25 and β
×23 (1.5 → 35 µrad). A wander that is smooth in time moves β far less; until the tool has a
smooth-wander model, it states the assumption and the user declares what their triad needs."""

MAX_PPM = 1e5
"""Largest stability a user may declare [ppm]: 10 %, the loop's physical prior on a scale
factor (:data:`align.calibration.model.PRIOR_SCALE`); beyond it the triad has no scale
factor to calibrate."""
PPM = 1e-6
STABILITY = "scale_stability"
"""The term's name in ``u_widening``."""
FLAG = "--scale-stability-ppm"
KEY = "[calibration] scale_stability_ppm"


def stability_ppm(value: object, where: str) -> float:
    """The one rule for a declared scale stability (the flag's and the session key's): a
    finite number of ppm in [0, :data:`MAX_PPM`]; :class:`InputError` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} = {value!r}: expected a number of ppm")
    v = float(value)
    if not math.isfinite(v) or not 0.0 <= v <= MAX_PPM:
        raise InputError(f"{where} = {value!r}: the scale factors' stability over the run "
                         f"must be a number of ppm in [0, {MAX_PPM:g}]")
    return v


def chosen_ppm(declared: float | None, has_temperature: bool) -> tuple[float, bool]:
    """The stability that applies [ppm] and whether it is *assumed* (nothing declared and no
    temperature column: 0, stated as an assumption — :data:`TYPICAL_PPM` says why)."""
    if declared is not None:
        return float(declared), False
    return 0.0, not has_temperature


def stability_statement(ppm: float, assumed: bool, has_temperature: bool) -> dict:
    """The JSON ``scale_stability`` record: what u assumes about the scale's wander."""
    if assumed:
        why = (f"no temperature column and no declaration: scale factors assumed stable over "
               f"the run (a ±1 K room cycle through a triad's thermal lag is typically "
               f"±{TYPICAL_PPM:g} ppm; declare it with {FLAG} or {KEY} to carry it in u)")
    elif ppm:
        why = f"scale factors declared stable to ±{ppm:g} ppm over the run (carried in u)"
    elif has_temperature:
        why = "temperature column: the scale's temperature coefficient is a loop candidate"
    else:
        why = "scale factors declared stable over the run"
    return {"ppm": None if assumed else float(ppm), "assumed": bool(assumed), "statement": why}


def stability_gain(projection: np.ndarray, weights: np.ndarray, gradient: np.ndarray,
                   u: np.ndarray) -> np.ndarray:
    """G of the module for the ellipsoid fit: each parameter's change per relative change
    of each pose-axis reading (n_params, 3 N) [parameter unit].

    Parameters
    ----------
    projection : A (n_params, N) [parameter unit per weighted residual].
    weights : W (N, N), weighted residuals per residual of |a| [1/g].
    gradient : ∂|a_p|/∂u_pa (N, 3) [g per output unit].
    u : the pose means (N, 3) [output unit].
    """
    n = len(u)
    D = np.zeros((n, 3 * n))
    for a in range(3):
        D[np.arange(n), 3 * np.arange(n) + a] = gradient[:, a] * u[:, a]
    return projection @ weights @ D


def stability_reason(ppm: float, default: bool) -> str:
    """Why the term is there (for ``u_widening.terms`` and the warning)."""
    del default  # a term is only added for a declared stability
    return (f"scale factors declared stable to ±{ppm:g} ppm over the run, each pose's reading "
            "anywhere within it")
