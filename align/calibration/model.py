"""The calibrated triad model, its maximum-likelihood refinement and its residual loop.

Inverse model (the forward one is u_i = k_i (x_i + K2_i x_i^2), x = R (a + b(t, T))):

    x_i = v_i - K2_i v_i^2,   v = u / k                 (first-order inverse of K2; K2 x ~ 1e-4)
    a   = R^-1 x - b - bdot (t - t_ref) - bddot (t - t_ref)^2 - c_T (T - T_ref)

The refinement minimises sum_p ((|a_p| - 1) / sigma_p)^2 over (k, beta, b) and whatever
effects the loop added, with scipy's least_squares (plain loss), starting from the algebraic
Li–Griffiths solution. sigma_p is each pose mean's standard deviation of |a| propagated from
its samples' scatter when samples are given; with per-pose means only the noise is unknown and
the loop works without a chi2 test.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from align.calibration.ellipsoid import extract, li_griffiths, r_matrix
from align.errors import InputError
from align.loop import Candidate, LoopReport, StageFit, Term, run_loop

NONLIN = "nonlinearity_k2"
DRIFT = "bias_drift"
TEMP = "bias_temperature"
WARMUP = "bias_warmup"
EFFECT_UNITS = {NONLIN: "1/g", DRIFT: "g/s", TEMP: "g/K", WARMUP: "g/s^2"}
# Parameters each effect adds, and the TriadModel fields they fill.
EFFECT_FIELDS = {NONLIN: ("k2",), DRIFT: ("drift",), TEMP: ("temp_coeff",),
                 WARMUP: ("drift", "drift2")}


@dataclass(frozen=True)
class Poses:
    """Per-pose means of a static test: u (N, 3) [V or counts], t [s], temp [K], sigma of the
    mean output per component (N, 3) or None, sample counts, and labels."""

    u: np.ndarray
    t: np.ndarray
    temp: np.ndarray | None
    sigma_u: np.ndarray | None
    count: np.ndarray
    labels: tuple[str, ...]


def poses_from_samples(pose: np.ndarray, u: np.ndarray, t: np.ndarray,
                       labels: Sequence[str] | None = None) -> Poses:
    """Per-pose means (and their standard errors) from samples tagged with pose ids 0..N-1."""
    ids = np.unique(pose)
    sel = [pose == i for i in ids]
    return Poses(np.array([u[s].mean(0) for s in sel]), np.array([t[s].mean() for s in sel]),
                 None, np.array([u[s].std(0, ddof=1) / np.sqrt(s.sum()) for s in sel]),
                 np.array([s.sum() for s in sel]),
                 tuple(labels) if labels is not None else tuple(str(i) for i in ids))


@dataclass(frozen=True)
class TriadModel:
    """A calibration: parameters and optional effects; ``cov`` is over ``names``."""

    k: np.ndarray
    beta: np.ndarray
    bias: np.ndarray
    k2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    temp_coeff: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drift2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t_ref: float = 0.0
    temp_ref: float = 0.0
    cov: np.ndarray | None = None
    names: tuple[str, ...] = ()

    def specific_force(self, u: np.ndarray, t: np.ndarray | float = 0.0,
                       temp: np.ndarray | float | None = None) -> np.ndarray:
        """Specific force a (N, 3) [g] in the unit's convenient frame from outputs u."""
        v = np.asarray(u, float) / self.k
        x = v - self.k2 * v * v
        a = np.linalg.solve(r_matrix(self.beta), x.T).T
        dt = np.asarray(t, float) - self.t_ref
        a = (a - self.bias - np.multiply.outer(dt, self.drift)
             - np.multiply.outer(dt * dt, self.drift2))
        if temp is not None:
            a = a - np.multiply.outer(np.asarray(temp, float) - self.temp_ref, self.temp_coeff)
        return a

    def u_of(self, name: str) -> float:
        if self.cov is None or name not in self.names:
            return float("nan")
        i = self.names.index(name)
        return float(np.sqrt(self.cov[i, i]))


def _pack_names(effects: Sequence[str]) -> tuple[str, ...]:
    names = [f"{p}_{ax}" for p in ("k", "beta", "bias") for ax in "xyz"]
    for e in effects:
        names += [f"{f}_{ax}" if len(EFFECT_FIELDS[e]) > 1 else f"{e}_{ax}"
                  for f in EFFECT_FIELDS[e] for ax in "xyz"]
    return tuple(names)


def _n_params(effects: Sequence[str]) -> int:
    return 9 + sum(3 * len(EFFECT_FIELDS[e]) for e in effects)


def _model_from(theta: np.ndarray, effects: Sequence[str], t_ref: float, temp_ref: float,
                cov: np.ndarray | None = None) -> TriadModel:
    kw: dict[str, np.ndarray] = {}
    i = 9
    for e in effects:
        for f in EFFECT_FIELDS[e]:
            # A later effect on the same field (warm-up after drift) adds to it.
            kw[f] = kw.get(f, np.zeros(3)) + theta[i:i + 3]
            i += 3
    return TriadModel(theta[:3], theta[3:6], theta[6:9], t_ref=t_ref, temp_ref=temp_ref,
                      cov=cov, names=_pack_names(effects), **kw)


def algebraic(poses: Poses, signs: Sequence[float]) -> TriadModel:
    """The seed paper's solution: Li–Griffiths + exact extraction (no refinement)."""
    k, beta, b = extract(li_griffiths(poses.u), np.asarray(signs, float))
    return TriadModel(k, beta, b, t_ref=float(np.mean(poses.t)),
                      temp_ref=float(np.mean(poses.temp)) if poses.temp is not None else 0.0)


def pose_sigma_g(model: TriadModel, poses: Poses) -> np.ndarray | None:
    """Standard deviation of |a| for each pose mean, from its output scatter [g]."""
    if poses.sigma_u is None:
        return None
    # One sensor, one noise: pool the per-pose estimates (each from a few hundred correlated
    # samples, so +-10 % each) into one per axis, scaled by each pose's sample count. Noisy
    # per-pose weights would cost the ML fit more than it gains.
    n = poses.count.astype(float)
    pooled = np.sqrt(np.sum((poses.sigma_u**2) * n[:, None] ** 2, 0) / np.sum(n))
    sigma_u = pooled[None, :] / np.sqrt(n)[:, None]
    a = model.specific_force(poses.u, poses.t, poses.temp)
    n = a / np.linalg.norm(a, axis=1, keepdims=True)
    G = np.linalg.inv(model.k[:, None] * r_matrix(model.beta))
    g = n @ G  # d|a|/du per pose
    return np.sqrt(np.sum((g * sigma_u) ** 2, axis=1))


class CalibrationStage:
    """Maximum-likelihood ellipsoid refinement with optional effects (the loop's stage)."""

    def __init__(self, poses: Poses, signs: Sequence[float]):
        if len(poses.u) < 9:
            raise InputError(f"only {len(poses.u)} usable poses; the model needs at least 9 "
                             "(the paper's cube gives 14)")
        self.poses = poses
        self.start = algebraic(poses, signs)
        self.sigma = pose_sigma_g(self.start, poses)

    def refine(self, effects: Sequence[str]) -> tuple[TriadModel, np.ndarray, np.ndarray]:
        p = self.poses
        s0 = self.start
        for e in effects:
            if e == TEMP and p.temp is None:
                raise ValueError("no temperature column")
        theta0 = np.concatenate([s0.k, s0.beta, s0.bias, np.zeros(_n_params(effects) - 9)])
        w = 1.0 / self.sigma if self.sigma is not None else np.ones(len(p.u))

        def resid(theta):
            m = _model_from(theta, effects, s0.t_ref, s0.temp_ref)
            return (np.linalg.norm(m.specific_force(p.u, p.t, p.temp), axis=1) - 1.0) * w

        if len(p.u) < len(theta0):
            raise ValueError("more parameters than poses")
        scale = np.concatenate([np.abs(s0.k) * 1e-3, np.full(3, 1e-4), np.full(3, 1e-4),
                                np.concatenate([_effect_scale(e, p) for e in effects])
                                if effects else []])
        res = least_squares(resid, theta0, x_scale=scale, method="lm", xtol=1e-14,
                            ftol=1e-14, gtol=1e-14, max_nfev=2000)
        r = res.fun / w
        J = res.jac
        dof = len(r) - len(theta0)
        cov = np.linalg.pinv(J.T @ J)
        if self.sigma is None:
            # Noise unknown: scale by the residual variance (Type A only).
            cov = cov * (np.sum(res.fun**2) / max(dof, 1))
        return _model_from(res.x, effects, s0.t_ref, s0.temp_ref, cov), r, res.x

    def fit(self, terms: Sequence[Term]) -> StageFit:
        effects = [t.name for t in terms]
        m, r, _ = self.refine(effects)
        p = self.poses
        a = m.specific_force(p.u, p.t, p.temp)
        d = a / np.linalg.norm(a, axis=1, keepdims=True)
        regs = {"ax": d[:, 0], "ay": d[:, 1], "az": d[:, 2], "t": p.t}
        if p.temp is not None and np.ptp(p.temp) > 0:
            regs["temp"] = p.temp
        eff = {}
        comps = {}
        for e in effects:
            # The effect's leading field (for warm-up: its curvature, the part drift lacks).
            fld = EFFECT_FIELDS[e][-1]
            vals = getattr(m, fld)
            prefix = fld if len(EFFECT_FIELDS[e]) > 1 else e
            us = np.array([m.u_of(f"{prefix}_{ax}") for ax in "xyz"])
            j = int(np.argmax(np.abs(vals) / np.where(us > 0, us, np.inf)))
            eff[e] = (float(vals[j]), float(us[j]))
            comps[e] = tuple((ax, float(v), float(uu)) for ax, v, uu in zip("xyz", vals, us,
                                                                             strict=True))
        q = {n: (float(v), m.u_of(n)) for n, v in zip(
            m.names[:9], np.concatenate([m.k, m.beta, m.bias]), strict=True)}
        return StageFit(r, self.sigma, _n_params(effects), regs, "t", eff, q,
                        components=comps, payload=m)


def _effect_scale(e: str, p: Poses) -> np.ndarray:
    span_t = max(float(np.ptp(p.t)), 1.0)
    if e == NONLIN:
        return np.full(3, 1e-5)
    if e == DRIFT:
        return np.full(3, 1e-5 / span_t)
    if e == WARMUP:
        return np.concatenate([np.full(3, 1e-5 / span_t), np.full(3, 1e-5 / span_t**2)])
    span_T = max(float(np.ptp(p.temp)) if p.temp is not None else 1.0, 1e-3)
    return np.full(3, 1e-5 / span_T)


def _term(name: str):
    def build(fit: StageFit) -> Term | None:
        if name == TEMP and "temp" not in fit.regressors:
            return None
        if name in (DRIFT, WARMUP) and np.ptp(fit.regressors["t"]) == 0:
            return None
        width = 3 * len(EFFECT_FIELDS[name])
        if fit.n - fit.n_params < width + 1:
            return None
        return Term(name, EFFECT_UNITS[name], np.zeros((fit.n, width)))
    return build


CANDIDATES: tuple[Candidate, ...] = (
    Candidate(NONLIN, "1/g", "second-order scale-factor nonlinearity K2 per axis", _term(NONLIN)),
    Candidate(DRIFT, "g/s", "bias drifting linearly during the session", _term(DRIFT)),
    Candidate(TEMP, "g/K", "bias following the temperature", _term(TEMP)),
    Candidate(WARMUP, "g/s^2", "bias warming up: drift that slows or turns (quadratic in "
              "time)", _term(WARMUP)),
)


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`: algebraic start, final model, loop report."""

    algebraic: TriadModel
    model: TriadModel
    loop: LoopReport
    signs: tuple[float, float, float]
    noise_known: bool

    @property
    def residual_rms_g(self) -> float:
        return self.loop.after.rms


def calibrate(poses: Poses, signs: Sequence[float] = (1, 1, 1), alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES) -> Calibration:
    """Algebraic fit, ML refinement, residual loop over the calibration effects."""
    stage = CalibrationStage(poses, signs)
    rep = run_loop(stage, candidates, alpha=alpha)
    return Calibration(stage.start, rep.after.payload, rep, tuple(float(s) for s in signs),
                       stage.sigma is not None)


def delta_g(model: TriadModel, poses: Poses) -> np.ndarray:
    """|a| - 1 per pose through the model [g] (the paper's check-pose figure)."""
    return np.linalg.norm(model.specific_force(poses.u, poses.t, poses.temp), axis=1) - 1.0


def model_to_dict(m: TriadModel) -> dict:
    """The model as JSON-ready numbers (SI/radians/g), covariance included."""
    return {"k_v_per_g": m.k.tolist(), "beta_rad": m.beta.tolist(), "bias_g": m.bias.tolist(),
            "k2_per_g": m.k2.tolist(), "drift_g_per_s": m.drift.tolist(),
            "drift2_g_per_s2": m.drift2.tolist(),
            "temp_coeff_g_per_k": m.temp_coeff.tolist(), "t_ref_s": m.t_ref,
            "temp_ref_k": m.temp_ref, "parameter_names": list(m.names),
            "covariance": None if m.cov is None else m.cov.tolist()}


def model_from_dict(d: dict, where: str = "calibration") -> TriadModel:
    """Read :func:`model_to_dict`'s output back (clear error for anything else)."""
    try:
        cov = d.get("covariance")
        return TriadModel(
            np.array(d["k_v_per_g"], float), np.array(d["beta_rad"], float),
            np.array(d["bias_g"], float), np.array(d.get("k2_per_g", [0, 0, 0]), float),
            np.array(d.get("drift_g_per_s", [0, 0, 0]), float),
            np.array(d.get("temp_coeff_g_per_k", [0, 0, 0]), float),
            np.array(d.get("drift2_g_per_s2", [0, 0, 0]), float),
            float(d.get("t_ref_s", 0.0)), float(d.get("temp_ref_k", 0.0)),
            None if cov is None else np.array(cov, float),
            tuple(d.get("parameter_names", ())))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{where}: not a calibration model ({exc!s}); expected the 'model' "
                         "block that 'align calibrate --json' writes") from None


def calibration_json(cal: Calibration, poses: Poses) -> dict:
    """The calibration's JSON (contract of ``align calibrate``, also a session's stage)."""
    m, a = cal.model, cal.algebraic
    return {
        "scale_factors_v_per_g": m.k.tolist(), "beta_rad": m.beta.tolist(),
        "bias_g": m.bias.tolist(),
        "scale_factors_u_v_per_g": [m.u_of(f"k_{ax}") for ax in "xyz"],
        "beta_u_rad": [m.u_of(f"beta_{ax}") for ax in "xyz"],
        "bias_u_g": [m.u_of(f"bias_{ax}") for ax in "xyz"],
        "scale_sign": list(cal.signs), "residual_rms_g": cal.residual_rms_g,
        "dof": cal.loop.after.dof,
        "effects": [e.to_dict() for e in cal.loop.effects],
        "unexplained_structure": cal.loop.unexplained_structure, "noise_known": cal.noise_known,
        "algebraic": {"scale_factors_v_per_g": a.k.tolist(), "beta_rad": a.beta.tolist(),
                      "bias_g": a.bias.tolist()},
        "poses": [{"pose": lab, "dg_g": float(d)} for lab, d in
                  zip(poses.labels, delta_g(m, poses), strict=True)],
        "model": model_to_dict(m),
    }
