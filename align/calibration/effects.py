"""The calibration loop's candidate effects: their names, the model fields their parameters
fill, their units and the regressor size the physical guard bounds them by; the turn signs
that are the hysteresis's regressor.

A table of its own (not in :mod:`align.calibration.model`): the fit, the guard, the plan and
the widening all read it, and the fit's module was at its size limit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

NONLIN = "nonlinearity_k2"
DRIFT = "bias_drift"
TEMP = "bias_temperature"
WARMUP = "bias_warmup"
SCALE_DRIFT = "scale_drift"
SCALE_TEMP = "scale_temperature"
SCALE_WARMUP = "scale_warmup"
HYSTERESIS = "bias_hysteresis"
K3 = "nonlinearity_k3"
ASYMMETRY = "scale_asymmetry"
IN_TIME = frozenset({DRIFT, WARMUP, TEMP, SCALE_DRIFT, SCALE_WARMUP, SCALE_TEMP})
"""The effects that change over the run (a temperature follows the time): a bias wandering
between the poses can take their shape (:mod:`align.calibration.walk`)."""
PAIRS = ("xy", "xz", "yz")
PAIR_I, PAIR_J = [0, 0, 1], [1, 2, 2]
"""The axes of each pair of PAIRS (columns of the products v_i v_j, in that order)."""
FIELDS3 = ("k2", "drift", "drift2", "temp_coeff", "scale_drift", "scale_temp",
           "scale_warmup", "hysteresis", "k3", "asymmetry")
"""The TriadModel fields of one value per axis that effects set (``cross`` is 3 x 3)."""
CROSS = tuple(f"cross_{ax}_{pq}" for ax in "xyz" for pq in PAIRS)
"""One candidate per cross-axis product K_i,jl (output axis i, inputs j l): nine at once
would leave the paper's 14 poses no degrees of freedom; the loop picks the one the data call
for, its search over nine counted as nine trials."""


@dataclass(frozen=True)
class Effect:
    """An effect's parameters: (TriadModel field, index in it, parameter name) each;
    ``report``: the slots whose values the loop reports (warm-up: its curvature, the part a
    drift lacks); ``size``: the regressor's largest magnitude over the poses' span (for the
    physical bound on the ``report`` slots, :data:`EFFECT_PRIOR_G`) given (time span [s],
    temperature span [K])."""

    unit: str
    slots: tuple[tuple[str, tuple[int, ...], str], ...]
    report: tuple[int, ...]
    size: Callable[[float, float], float]


def _per_axis(fld: str, prefix: str) -> tuple[tuple[str, tuple[int, ...], str], ...]:
    return tuple((fld, (i,), f"{prefix}_{ax}") for i, ax in enumerate("xyz"))


EFFECTS: dict[str, Effect] = {
    NONLIN: Effect("1/g", _per_axis("k2", NONLIN), (0, 1, 2), lambda t, T: 1.0),
    DRIFT: Effect("g/s", _per_axis("drift", DRIFT), (0, 1, 2), lambda t, T: t),
    TEMP: Effect("g/K", _per_axis("temp_coeff", TEMP), (0, 1, 2), lambda t, T: T),
    WARMUP: Effect("g/s^2", _per_axis("drift", "drift") + _per_axis("drift2", "drift2"),
                   (3, 4, 5), lambda t, T: t * t),
    SCALE_DRIFT: Effect("1/s", _per_axis("scale_drift", SCALE_DRIFT), (0, 1, 2),
                        lambda t, T: t),
    SCALE_TEMP: Effect("1/K", _per_axis("scale_temp", SCALE_TEMP), (0, 1, 2),
                       lambda t, T: T),
    SCALE_WARMUP: Effect("1", _per_axis("scale_warmup", SCALE_WARMUP), (0, 1, 2),
                         lambda t, T: 1.0),
    HYSTERESIS: Effect("g", _per_axis("hysteresis", HYSTERESIS), (0, 1, 2),
                       lambda t, T: 1.0),
    K3: Effect("1/g^2", _per_axis("k3", K3), (0, 1, 2), lambda t, T: 1.0),
    ASYMMETRY: Effect("1", _per_axis("asymmetry", ASYMMETRY), (0, 1, 2), lambda t, T: 1.0),
    **{name: Effect("1/g", (("cross", (i // 3, i % 3), name),), (0,), lambda t, T: 1.0)
       for i, name in enumerate(CROSS)},
}
EFFECT_UNITS = {n: e.unit for n, e in EFFECTS.items()}

TURN_G = 0.1
"""Smallest change of an axis's input [g] taken as a turn of that axis (hysteresis): a
fixture's wobble between two poses (1e-4 g) is not one; a tumble's turns are >= 0.4 g."""


def turn_signs(x: np.ndarray, t: np.ndarray, turn_g: float = TURN_G) -> np.ndarray:
    """Side (N, 3) of each axis's hysteresis loop at each pose, the poses held in the order of
    ``t``: the sign of the last change of the axis's input ``x`` [g] larger than ``turn_g``
    (0 before any). Hand-written: a running state of a few poses."""
    order = np.argsort(t, kind="stable")
    out = np.zeros_like(x)
    state = np.zeros(x.shape[1])
    for prev, p in zip(order[:-1], order[1:], strict=True):
        d = x[p] - x[prev]
        state = np.where(np.abs(d) > turn_g, np.sign(d), state)
        out[p] = state
    return out
