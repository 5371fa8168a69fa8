"""The triad's maximum-likelihood refinement (the loop's stage), its candidate effects and the
guard that keeps the loop from running away.

The model (:class:`align.calibration.triad.TriadModel`) maps outputs to specific force.
The refinement minimises sum_p ((|a_p| - 1) / sigma_p)^2 over (k, beta, b) and whatever
effects the loop added, with scipy's least_squares (plain loss), starting from the algebraic
Li–Griffiths solution. sigma_p is each pose mean's standard deviation of |a| propagated from
its samples' scatter when samples are given; with per-pose means only the noise is unknown and
the loop works without a chi2 test.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import least_squares

from align.calibration.ellipsoid import extract, li_griffiths
from align.calibration.triad import Poses, TriadModel, pose_sigma_g
from align.errors import InputError
from align.loop import Candidate, StageFit, Term

NONLIN = "nonlinearity_k2"
DRIFT = "bias_drift"
TEMP = "bias_temperature"
WARMUP = "bias_warmup"
EFFECT_UNITS = {NONLIN: "1/g", DRIFT: "g/s", TEMP: "g/K", WARMUP: "g/s^2"}
# Parameters each effect adds, and the TriadModel fields they fill.
EFFECT_FIELDS = {NONLIN: ("k2",), DRIFT: ("drift",), TEMP: ("temp_coeff",),
                 WARMUP: ("drift", "drift2")}


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


class CalibrationStage:
    """Maximum-likelihood ellipsoid refinement with optional effects (the loop's stage)."""

    def __init__(self, poses: Poses, signs: Sequence[float]):
        if len(poses.u) < 9:
            raise InputError(f"only {len(poses.u)} usable poses; the model needs at least 9 "
                             "(the paper's cube gives 14)")
        self.poses = poses
        self.condition: dict[tuple[str, ...], float] = {}
        # Per fitted effect list: the map from the weighted pose residuals to the parameters
        # (A = cov_unit J^T W^1/2, dtheta = A dr_w) and the weighted residuals, for the
        # widening of u when structure remains (align.calibration.widen).
        self.projection: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = {}
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
        # Separability: condition number of the Jacobian with unit-norm columns (scale-free).
        norms = np.linalg.norm(J, axis=0)
        self.condition[tuple(effects)] = (float(np.linalg.cond(J / np.where(norms > 0, norms,
                                                                          1.0)))
                                          if np.all(norms > 0) else float("inf"))
        dof = len(r) - len(theta0)
        # Columns scaled to unit norm first: the effects' columns (t^2 ~ 1e5 s^2) next to
        # k's made J^T J so ill-conditioned that its pseudo-inverse dropped k's directions
        # (u(k) came out 1e-6 counts/g after a warm-up term was added).
        d = 1.0 / np.where(norms > 0, norms, 1.0)
        cov = d[:, None] * np.linalg.pinv((J * d).T @ (J * d)) * d[None, :]
        self.projection[tuple(effects)] = (cov @ J.T, np.asarray(res.fun, float))
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


PRIOR_SCALE = 0.10
"""An effect may not move a scale factor by more than this fraction (physical prior)."""
PRIOR_ANGLE_RAD = 0.1
"""... nor a non-orthogonality angle by more than this [rad] ..."""
PRIOR_BIAS_G = 0.1
"""... nor a bias by more than this [g]."""
OVERFIT_CHI2 = 0.2
"""chi2/dof below this after adding an effect is an over-fit when the effect also moves a
quantity of interest by more than :data:`OVERFIT_SIGMA` of its own standard uncertainty."""
OVERFIT_SIGMA = 10.0
MAX_CONDITION = 1e7
"""Largest condition number of the (column-normalised) Jacobian: above it the data cannot
separate the effect from the model."""


def admissible(stage: CalibrationStage) -> Callable[[StageFit, StageFit, Term], str | None]:
    """The calibration's guard against a run-away loop: the reason to refuse an effect that
    the significance tests call for, or None (design: physical priors, over-fit, rank)."""

    def check(base: StageFit, trial: StageFit, term: Term) -> str | None:
        mb, mt = base.payload, trial.payload
        cond = stage.condition.get(tuple(t.name for t in [*_terms_of(base), term]),
                                   float("nan"))
        if not np.isfinite(cond) or cond > MAX_CONDITION:
            return (f"the poses cannot separate it from the model (condition number "
                    f"{cond:.3g} > {MAX_CONDITION:.0e})")
        rel = np.abs(mt.k / mb.k - 1)
        if rel.max() > PRIOR_SCALE:
            i = int(np.argmax(rel))
            return (f"it moves k_{'xyz'[i]} from {mb.k[i]:.6g} to {mt.k[i]:.6g} "
                    f"({rel[i]:.0%} > {PRIOR_SCALE:.0%}): outside the physical prior")
        db = np.abs(mt.beta - mb.beta)
        if db.max() > PRIOR_ANGLE_RAD:
            i = int(np.argmax(db))
            return (f"it moves beta_{'xyz'[i]} from {mb.beta[i]:.4g} to {mt.beta[i]:.4g} rad "
                    f"(> {PRIOR_ANGLE_RAD} rad): outside the physical prior")
        dbias = np.abs(mt.bias - mb.bias)
        if dbias.max() > PRIOR_BIAS_G:
            i = int(np.argmax(dbias))
            return (f"it moves bias_{'xyz'[i]} by {dbias[i]:.3g} g (> {PRIOR_BIAS_G} g): "
                    "outside the physical prior")
        if trial.sigma is not None and trial.dof > 0:
            red = trial.chi2 / trial.dof
            u = np.array([base.quantities[n][1] for n in mb.names[:9]])
            shift = np.abs(np.concatenate([mt.k - mb.k, mt.beta - mb.beta, mt.bias - mb.bias]))
            z = shift / np.where(u > 0, u, np.inf)
            if red < OVERFIT_CHI2 and z.max() > OVERFIT_SIGMA:
                i = int(np.argmax(z))
                return (f"over-fit: chi2/dof falls to {red:.3g} while {mb.names[i]} moves by "
                        f"{z[i]:.0f} of its standard uncertainty")
        return None

    return check


def _terms_of(fit: StageFit) -> list[Term]:
    """The effect terms a calibration fit carries (the names are all the guard needs)."""
    return [Term(n, "", np.zeros((0, 0))) for n in fit.effects]


