"""The calibration fit's residual: the inverse model of ``TriadModel.specific_force`` written
out on the poses' arrays (``CalibrationStage._residual``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from align.calibration.effects import EFFECTS, FIELDS3, HYSTERESIS, PAIR_I, PAIR_J
from align.calibration.ellipsoid import r_matrix
from align.calibration.triad import Poses, TriadModel


class _Stage(Protocol):
    poses: Poses
    start: TriadModel
    sigma: np.ndarray | None
    whiten: np.ndarray | None
    turns: np.ndarray


def stage_residual(stage: _Stage, effects: Sequence[str]
                   ) -> Callable[[np.ndarray, float], np.ndarray]:
    """The weighted residuals (|a_p| - 1) / sigma_p of ``stage``'s poses as a function of
    (theta, tau): theta the stage's packed parameters (k [output unit/g], beta [rad], b [g],
    then the effects' slots), tau the scale warm-up's time constant [s].

    The inverse model of TriadModel.specific_force written out on the poses' arrays: the
    loop fits ~50 models of ~100 evaluations each, and building a TriadModel per evaluation
    was 2/3 of the calibration's time. test_stage_residual_is_the_model checks the two
    agree. The stage's whitening is read at each call (the walk's fit sets it later).
    """
    p = stage.poses
    s0 = stage.start
    w = 1.0 / stage.sigma if stage.sigma is not None else np.ones(len(p.u))
    hyst = HYSTERESIS in effects
    slots = [(fld, idx) for e in effects for fld, idx, _ in EFFECTS[e].slots]
    dt = p.t - s0.t_ref
    dT = p.temp - s0.temp_ref if p.temp is not None else np.zeros(len(p.t))
    uu = p.u
    # R(beta)^-1 by beta: a Jacobian by differences moves beta in 3 of its n + 1 calls.
    inv_r: dict[bytes, np.ndarray] = {}

    def resid(theta: np.ndarray, tau: float) -> np.ndarray:
        f = {n: np.zeros(3) for n in FIELDS3}
        f["cross"] = np.zeros((3, 3))
        for (fld, idx), v in zip(slots, theta[9:], strict=True):
            f[fld][idx] += v
        v = uu / theta[:3]
        if len(slots):
            sc = (1.0 + dt[:, None] * f["scale_drift"] + dT[:, None] * f["scale_temp"])
            if tau > 0:
                sc = sc + np.expm1(-dt / tau)[:, None] * f["scale_warmup"]
            v = v / sc / (1.0 + np.sign(v) * f["asymmetry"])
            x = v - f["k2"] * v * v - f["k3"] * v**3 - (
                v[:, PAIR_I] * v[:, PAIR_J]) @ f["cross"].T
        else:
            x = v
        key = theta[3:6].tobytes()
        if key not in inv_r:
            inv_r.clear()
            inv_r[key] = np.linalg.inv(r_matrix(theta[3:6])).T
        a = x @ inv_r[key] - theta[6:9]
        if len(slots):
            a = (a - dt[:, None] * f["drift"] - (dt * dt)[:, None] * f["drift2"]
                 - dT[:, None] * f["temp_coeff"])
            if hyst:
                a = a - stage.turns * f["hysteresis"]
        d = np.sqrt(np.einsum("ij,ij->i", a, a)) - 1.0
        return d * w if stage.whiten is None else stage.whiten @ d

    return resid
