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
(the ±X pattern across opposite poses); the angles β move by X β only (second order).

The default, when the poses carry no temperature column and nothing is declared:
:data:`DEFAULT_PPM`, from the physics of the triads this tool calibrates.
"""

from __future__ import annotations

import math

import numpy as np

from align.errors import InputError

DEFAULT_PPM = 20.0
"""Scale-factor stability assumed over a run without a temperature column [ppm] (±, each
axis). The room: an air conditioner holds ±1 K in a cycle of ~15 min. The sensor: a scale
factor temperature coefficient of 100 ppm/K (navigation-grade quartz servo accelerometers,
QA-2000: < 180 ppm/°C; the better MEMS, ADXL355: ±100 ppm/°C; the BMI160 states ±300 ppm/K).
Between them the triad's own thermal mass: a block in its housing follows the air with a time
constant of 10-20 min, which passes 1/sqrt(1 + (2 pi tau / P)^2) = 0.16-0.23 of a 15-min
cycle: ±0.2 K inside, ±20 ppm. A triad bolted bare to a thin fixture, or one tempco of
300 ppm/K, declares more (a ±1 K cycle reaching the sensor: 100); a thermostat, less."""
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
    """The stability that applies [ppm] and whether it is the default: the declaration,
    else :data:`DEFAULT_PPM` without a temperature column, else 0 (the column lets the loop
    fit the scale's temperature coefficient)."""
    if declared is not None:
        return float(declared), False
    return (0.0, False) if has_temperature else (DEFAULT_PPM, True)


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
    why = (f"no temperature column: scale factors assumed stable to ±{ppm:g} ppm over the "
           f"run (the default: a ±1 K room cycle through the triad's thermal lag at 100 ppm/K; "
           f"declare it with {FLAG} or {KEY})"
           if default else f"scale factors declared stable to ±{ppm:g} ppm over the run")
    return why + ", each pose's reading anywhere within it"
