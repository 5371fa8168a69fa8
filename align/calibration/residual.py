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


def _d_r(beta: np.ndarray) -> np.ndarray:
    """dR/d(beta_i) (3, 3, 3) of :func:`align.calibration.ellipsoid.r_matrix`."""
    bx, by, bz = beta
    sx, cx, sy, cy, sz, cz = (np.sin(bx), np.cos(bx), np.sin(by), np.cos(by), np.sin(bz),
                              np.cos(bz))
    d = np.zeros((3, 3, 3))
    d[0, 1, 2], d[0, 2, 2] = cy * cx, -sx * cy
    d[1, 0, 2], d[1, 1, 2], d[1, 2, 2] = cz * cy, -sy * sx, -sy * cx
    d[2, 0, 1], d[2, 1, 1], d[2, 0, 2] = cz, -sz, -sz * sy
    return d


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
    return stage_functions(stage, effects)[0]


def stage_jacobian(stage: _Stage, effects: Sequence[str]
                   ) -> Callable[[np.ndarray, float], np.ndarray]:
    """The Jacobian (N, P) of :func:`stage_residual`'s residuals in theta, at (theta, tau).

    Written out (the chain rule through |a|, R(beta)^-1, the nonlinear terms and the scale
    factor's divisors): least_squares' differences called the residual P + 1 times per
    iteration, half the default test run's calibration time. ``sign(v)`` (the asymmetry's
    branch) is held, as the residual's differences do away from v = 0.
    test_stage_jacobian_is_the_differences checks it for every effect.
    """
    return stage_functions(stage, effects)[1]


def stage_functions(stage: _Stage, effects: Sequence[str]
                    ) -> tuple[Callable[[np.ndarray, float], np.ndarray],
                               Callable[[np.ndarray, float], np.ndarray]]:
    """:func:`stage_residual` and :func:`stage_jacobian` sharing their model pass: the fit
    asks for the Jacobian where it has just evaluated the residual, and the Jacobian takes
    that evaluation's arrays (the same numbers) instead of computing them again."""
    p = stage.poses
    s0 = stage.start
    w = 1.0 / stage.sigma if stage.sigma is not None else np.ones(len(p.u))
    hyst = HYSTERESIS in effects
    slots = [(fld, idx) for e in effects for fld, idx, _ in EFFECTS[e].slots]
    dt = p.t - s0.t_ref
    dT = p.temp - s0.temp_ref if p.temp is not None else np.zeros(len(p.t))
    uu = p.u
    n_pose = len(uu)
    # R(beta)^-1 by beta: the screen's differences move beta in 3 of its calls.
    inv_r: dict[bytes, np.ndarray] = {}
    # The last model pass, by (theta, tau).
    last: dict[tuple[bytes, float], tuple] = {}

    def forward(theta: np.ndarray, tau: float) -> tuple:
        """The model's arrays at (theta, tau): the effects' fields, v = u / k, the scale
        divisor, sign(v), the asymmetry's divisor (both None without effects), v2 = v over
        both, x, R(beta)^-T and a."""
        key = (theta.tobytes(), float(tau))
        if key in last:
            return last[key]
        f = {n: np.zeros(3) for n in FIELDS3}
        f["cross"] = np.zeros((3, 3))
        for (fld, idx), val in zip(slots, theta[9:], strict=True):
            f[fld][idx] += val
        v = uu / theta[:3]
        sc = sg = asy = None
        if len(slots):
            sc = (1.0 + dt[:, None] * f["scale_drift"] + dT[:, None] * f["scale_temp"])
            if tau > 0:
                sc = sc + np.expm1(-dt / tau)[:, None] * f["scale_warmup"]
            sg = np.sign(v)
            asy = 1.0 + sg * f["asymmetry"]
            v2 = v / sc / asy
            x = v2 - f["k2"] * v2 * v2 - f["k3"] * v2**3 - (
                v2[:, PAIR_I] * v2[:, PAIR_J]) @ f["cross"].T
        else:
            v2 = x = v
        bkey = theta[3:6].tobytes()
        if bkey not in inv_r:
            inv_r.clear()
            inv_r[bkey] = np.linalg.inv(r_matrix(theta[3:6])).T
        m = inv_r[bkey]
        a = x @ m - theta[6:9]
        if len(slots):
            a = (a - dt[:, None] * f["drift"] - (dt * dt)[:, None] * f["drift2"]
                 - dT[:, None] * f["temp_coeff"])
            if hyst:
                a = a - stage.turns * f["hysteresis"]
        last.clear()
        last[key] = (f, v, sc, sg, asy, v2, x, m, a)
        return last[key]

    def resid(theta: np.ndarray, tau: float) -> np.ndarray:
        a = forward(theta, tau)[-1]
        d = np.sqrt(np.einsum("ij,ij->i", a, a)) - 1.0
        return d * w if stage.whiten is None else stage.whiten @ d

    def jac(theta: np.ndarray, tau: float) -> np.ndarray:
        f, v, sc, sg, asy, v2, x, m, a = forward(theta, tau)
        if sc is None:  # no effect: no divisors
            sc, sg, asy = np.ones_like(v), np.sign(v), np.ones_like(v)
        k = theta[:3]
        warm = np.expm1(-dt / tau) if tau > 0 else np.zeros(n_pose)
        prod = v2[:, PAIR_I] * v2[:, PAIR_J]
        nrm = a / np.sqrt(np.einsum("ij,ij->i", a, a))[:, None]  # d|a|/da
        g = nrm @ m.T  # d|a|/dx
        # d|a|/dv2: x_c's own terms, then the cross products' v2_i v2_j.
        h = g * (1.0 - 2 * f["k2"] * v2 - 3 * f["k3"] * v2 * v2)
        gc = g @ f["cross"]  # (N, pairs): sum_c g_c cross[c, pair]
        for q, (i, j) in enumerate(zip(PAIR_I, PAIR_J, strict=True)):
            h[:, i] -= gc[:, q] * v2[:, j]
            h[:, j] -= gc[:, q] * v2[:, i]
        hv = h * v2  # d|a|/d(ln v2)
        # Each effect's column (the slots' fields only: most fits have one effect or none).
        cols = {"k2": lambda i: -g[:, i] * v2[:, i] * v2[:, i],
                "k3": lambda i: -g[:, i] * v2[:, i] ** 3,
                "drift": lambda i: -nrm[:, i] * dt, "drift2": lambda i: -nrm[:, i] * (dt * dt),
                "temp_coeff": lambda i: -nrm[:, i] * dT,
                "hysteresis": lambda i: -nrm[:, i] * stage.turns[:, i],
                "scale_drift": lambda i: -hv[:, i] * dt / sc[:, i],
                "scale_temp": lambda i: -hv[:, i] * dT / sc[:, i],
                "scale_warmup": lambda i: -hv[:, i] * warm / sc[:, i],
                "asymmetry": lambda i: -hv[:, i] * sg[:, i] / asy[:, i]}
        out = np.empty((n_pose, len(theta)))
        out[:, :3] = -hv / k
        # d(R^-1)/d beta_i = -R^-1 dR_i R^-1, transposed as m is.
        ri = m.T
        for i, dr in enumerate(_d_r(theta[3:6])):
            out[:, 3 + i] = np.einsum("nc,nc->n", nrm, x @ (-(ri @ dr @ ri)).T)
        out[:, 6:9] = -nrm
        for c, (fld, idx) in enumerate(slots):
            out[:, 9 + c] = (-g[:, idx[0]] * prod[:, idx[1]] if fld == "cross"
                             else cols[fld](idx[0]))
        return out * w[:, None] if stage.whiten is None else stage.whiten @ out

    return resid, jac
