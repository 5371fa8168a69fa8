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

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from align.calibration.ellipsoid import extract, li_griffiths, r_matrix, row_norms
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

    def sensitivity(self) -> np.ndarray:
        """Scale factor along each sensitive axis: output per g along s_i [output/g].

        The model's ``k`` is the paper's K of u = K R (a + b), whose R (eq. 5) has rows of
        length 1 + O(beta^2): k_i |r_i| is what the axis reads per g along itself (what a
        metrology user calls the scale factor; differs from k_i by ~beta^2/2, ~1e-5 at 15').
        """
        return self.k * row_norms(self.beta)[0]

    def sensitivity_u(self) -> np.ndarray:
        """Standard uncertainty of :meth:`sensitivity`, propagated from the covariance of
        (k, beta) (nan where not determined or without a covariance)."""
        names = [f"{p}_{ax}" for p in ("k", "beta") for ax in "xyz"]
        if self.cov is None or any(n not in self.names for n in names):
            return np.full(3, np.nan)
        idx = [self.names.index(n) for n in names]
        n, dn = row_norms(self.beta)
        J = np.hstack([np.diag(n), self.k[:, None] * dn])
        var = np.einsum("ij,jk,ik->i", J, self.cov[np.ix_(idx, idx)], J)
        return np.where(var >= 0, np.sqrt(np.abs(var)), np.nan)

    def u_of(self, name: str) -> float:
        if self.cov is None or name not in self.names:
            return float("nan")
        i = self.names.index(name)
        v = float(self.cov[i, i])
        return float(np.sqrt(v)) if v >= 0 else float("nan")  # nan: not determined

    def to_dict(self) -> dict:
        """The model as JSON-ready numbers (SI/radians/g), covariance included."""
        return {"k_v_per_g": self.k.tolist(), "beta_rad": self.beta.tolist(),
                "bias_g": self.bias.tolist(), "k2_per_g": self.k2.tolist(),
                "drift_g_per_s": self.drift.tolist(), "drift2_g_per_s2": self.drift2.tolist(),
                "temp_coeff_g_per_k": self.temp_coeff.tolist(), "t_ref_s": self.t_ref,
                "temp_ref_k": self.temp_ref, "parameter_names": list(self.names),
                "covariance": None if self.cov is None else self.cov.tolist()}

    @classmethod
    def from_dict(cls, d: dict, where: str = "calibration") -> TriadModel:
        """Read :meth:`to_dict`'s output back (clear error for anything else, or for a
        model that cannot be applied: see :func:`_checked`)."""
        try:
            cov = d.get("covariance")
            m = cls(
                np.array(d["k_v_per_g"], float), np.array(d["beta_rad"], float),
                np.array(d["bias_g"], float), np.array(d.get("k2_per_g", [0, 0, 0]), float),
                np.array(d.get("drift_g_per_s", [0, 0, 0]), float),
                np.array(d.get("temp_coeff_g_per_k", [0, 0, 0]), float),
                np.array(d.get("drift2_g_per_s2", [0, 0, 0]), float),
                float(d.get("t_ref_s", 0.0)), float(d.get("temp_ref_k", 0.0)),
                None if cov is None else np.array(cov, float),
                tuple(d.get("parameter_names", ())))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: not a calibration model ({exc!s}); expected the "
                             "'model' block that 'align calibrate --json' writes") from None
        return _checked(m, where)


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
        self.condition: dict[tuple[str, ...], float] = {}
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


SCALE_FACTOR_DEFINITION = (
    "scale_factors_*: output per g along each sensitive axis, k_i |r_i(beta)|, u propagated "
    "from (k, beta); model.k_v_per_g is the model's K of u = K R(beta) (a + b), whose R has "
    "rows of length 1 + O(beta^2)")
"""What the reported scale factors are (in the JSON next to them)."""


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`: algebraic start, final model, loop report."""

    algebraic: TriadModel
    model: TriadModel
    loop: LoopReport
    signs: tuple[float, float, float]
    noise_known: bool
    method: str = "ellipsoid"
    known: object = None
    cross_check: dict | None = None
    notes: tuple[str, ...] = ()

    @property
    def residual_rms_g(self) -> float:
        return self.loop.after.rms

    def effect_lines(self, unit: str = "") -> list[str]:
        """The loop's summary with every effect's components by axis (one line each)."""
        out = []
        for line in self.loop.summary_lines():
            out.append(line)
            if line.startswith("added "):
                e = next(x for x in self.loop.effects if line.startswith(f"added {x.name}:"))
                out += [f"    {e.name}_{ax}: {v:+.4g} ± {u:.2g} {e.unit}"
                        for ax, v, u in e.components]
        return out

    def to_dict(self, poses: Poses) -> dict:
        m, a = self.model, self.algebraic
        return {
            "scale_factors_v_per_g": m.sensitivity().tolist(), "beta_rad": m.beta.tolist(),
            "bias_g": m.bias.tolist(),
            "scale_factors_u_v_per_g": m.sensitivity_u().tolist(),
            "scale_factor_definition": SCALE_FACTOR_DEFINITION,
            "beta_u_rad": [m.u_of(f"beta_{ax}") for ax in "xyz"],
            "bias_u_g": [m.u_of(f"bias_{ax}") for ax in "xyz"],
            "scale_sign": list(self.signs), "residual_rms_g": self.residual_rms_g,
            "dof": self.loop.after.dof,
            "effects": [e.to_dict() for e in self.loop.effects],
            "unexplained_structure": self.loop.unexplained_structure,
            "noise_known": self.noise_known,
            "algebraic": {"scale_factors_v_per_g": a.sensitivity().tolist(),
                          "beta_rad": a.beta.tolist(), "bias_g": a.bias.tolist()},
            "poses": [{"pose": lab, "dg_g": float(d)} for lab, d in
                      zip(poses.labels, delta_g(m, poses), strict=True)],
            "model": m.to_dict(),
            "method": self.method,
            "refused_effects": [r.to_dict() for r in self.loop.refused],
            "known_pose": self.known.to_dict() if self.known is not None else None,
            "cross_check": self.cross_check,
        }


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


def calibrate(poses: Poses, signs: Sequence[float] | None = None, alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES,
              fixture_error_rad: float | None = None) -> Calibration:
    """Calibrate the triad from its poses.

    * Fewer than 9 poses, or poses that are all faces, with the six faces (labelled
      ``+x,-x,...`` or imucal's ``x_p,x_a,...``, or recognised from the means): the
      known-pose (six-position) fit alone.
    * 9 or more: algebraic ellipsoid fit, ML refinement, the residual loop over the effects
      (each guarded by :func:`admissible`); when the six faces are among the poses, the
      known-pose fit runs too and the two are cross-checked (``cross_check``, ``notes``).

    ``signs``: the scale factors' signs; None: from labelled faces when the poses carry
    them, else +,+,+ (an explicit one that contradicts the labels is refused:
    :func:`align.calibration.known.resolve_signs`). ``fixture_error_rad``: declared placement
    error of the faces (default :data:`align.calibration.known.FIXTURE_ERROR_RAD`).
    """
    from align.calibration.known import (
        FIXTURE_ERROR_RAD,
        KnownPoseStage,
        cross_check,
        faces_of,
        fit_known,
        has_six_faces,
        labelled,
        recognise_directions,
        resolve_signs,
    )

    fe = FIXTURE_ERROR_RAD if fixture_error_rad is None else fixture_error_rad
    faces = faces_of(poses)
    signs = signs_t = resolve_signs(poses, faces, signs)
    six = has_six_faces(faces)
    # Poses that are all faces (however many) span six directions: the ellipsoid's nine
    # parameters are not determined by them, the known-pose fit is.
    if len(poses.u) < 9 or (six and all(f is not None for f in faces)):
        if not six:
            raise InputError(f"only {len(poses.u)} usable poses; the ellipsoid needs at least 9 "
                             "(the paper's cube gives 14), or the six faces labelled "
                             "+x,-x,+y,-y,+z,-z for the known-pose (six-position) method")
        kf = fit_known(poses, faces, signs, fe)
        rep = run_loop(KnownPoseStage(kf, poses), ())
        return Calibration(kf.model, kf.model, rep, signs_t, poses.sigma_u is not None,
                           "known-pose", kf)
    try:
        stage = CalibrationStage(poses, signs)
    except InputError as exc:
        from align.calibration.geometry import SURROUND_DEG, cone_estimate_deg

        cone = cone_estimate_deg(poses.u)
        if cone < SURROUND_DEG:  # the fit failed on poses clustered in a cone: say so
            raise InputError(f"geometry: the {len(poses.u)} poses span only a cone of "
                             f"~{cone:.0f}° about one direction ({exc}): {TUMBLE}") from None
        raise
    rep = run_loop(stage, candidates, alpha=alpha, admissible=admissible(stage))
    kf, cc, notes = None, None, _cone_notes(rep.after.payload, poses)
    if not labelled(poses):
        # Unlabelled: only poses the ellipsoid puts within 2° of an axis are faces here.
        a = rep.after.payload.specific_force(poses.u, poses.t, poses.temp)
        faces = recognise_directions(a)
    if has_six_faces(faces):
        kf = fit_known(poses, faces, signs, fe)
        cc, w = cross_check(rep.after.payload, kf.model)
        notes = (*notes, *w)
    return Calibration(stage.start, rep.after.payload, rep, signs_t, stage.sigma is not None,
                       "ellipsoid", kf, cc, notes)


TUMBLE = "tumble the unit over all directions (the six faces and the eight corners of a cube)"


def _cone_notes(m: TriadModel, poses: Poses) -> tuple[str, ...]:
    """Poses within one hemisphere: a warning with the cone and the largest uncertainties;
    an :class:`InputError` (geometry) when a parameter is not determined by them — its
    3u covers the physical range the loop's guard allows (:data:`PRIOR_SCALE`,
    :data:`PRIOR_ANGLE_RAD`, :data:`PRIOR_BIAS_G`): the data then say nothing about it
    beyond what any triad is, and the linear uncertainty itself no longer holds."""
    from align.calibration.geometry import HEMISPHERE_DEG, cone_deg

    cone = cone_deg(m.specific_force(poses.u, poses.t, poses.temp))
    if cone >= HEMISPHERE_DEG:
        return ()
    rel = {f"k_{ax}": (v / abs(k), PRIOR_SCALE, f"{v / abs(k):.2%}") for ax, v, k in
           zip("xyz", m.sensitivity_u(), m.sensitivity(), strict=True)}
    ang = {f"beta_{ax}": (m.u_of(f"beta_{ax}"), PRIOR_ANGLE_RAD,
                          f"{m.u_of(f'beta_{ax}'):.3g} rad") for ax in "xyz"}
    bias = {f"bias_{ax}": (m.u_of(f"bias_{ax}"), PRIOR_BIAS_G,
                           f"{m.u_of(f'bias_{ax}'):.3g} g") for ax in "xyz"}
    q = {**rel, **ang, **bias}
    bad = [n for n, (u, prior, _) in q.items() if not (3 * u < prior)]
    where = (f"geometry: the {len(poses.u)} poses span only a cone of ~{cone:.0f}° about one "
             "direction (no axis seen both up and down)")
    if bad:
        raise InputError(f"{where}: {', '.join(bad)} not determined by them (u "
                         + ", ".join(q[n][2] for n in bad) + f": 3u beyond the physical range "
                         f"{PRIOR_SCALE:.0%}, {PRIOR_ANGLE_RAD} rad, {PRIOR_BIAS_G} g): "
                         f"{TUMBLE}")
    worst_k = max(rel, key=lambda n: rel[n][0])
    worst_b = max(bias, key=lambda n: bias[n][0])
    return (f"calibration: {where}: its uncertainties are large for it (u({worst_k}) "
            f"{rel[worst_k][2]}, u({worst_b}) {bias[worst_b][2]}); {TUMBLE}",)


def delta_g(model: TriadModel, poses: Poses) -> np.ndarray:
    """|a| - 1 per pose through the model [g] (the paper's check-pose figure)."""
    return np.linalg.norm(model.specific_force(poses.u, poses.t, poses.temp), axis=1) - 1.0


MAX_BETA_RAD = np.pi / 4
"""Largest non-orthogonality a model file may hold: R (eq. 5) is singular at pi/2, and an
axis 45 deg off its place is no triad (real ones are within a degree)."""


def _checked(m: TriadModel, where: str) -> TriadModel:
    """Refuse a model that cannot be applied: a non-finite value anywhere, a zero scale
    factor, a non-orthogonality beyond :data:`MAX_BETA_RAD` (one line naming the key)."""
    keys = {"k_v_per_g": m.k, "beta_rad": m.beta, "bias_g": m.bias, "k2_per_g": m.k2,
            "drift_g_per_s": m.drift, "temp_coeff_g_per_k": m.temp_coeff,
            "drift2_g_per_s2": m.drift2, "t_ref_s": np.atleast_1d(m.t_ref),
            "temp_ref_k": np.atleast_1d(m.temp_ref)}
    for key, v in keys.items():
        if key not in ("t_ref_s", "temp_ref_k") and v.shape != (3,):
            raise InputError(f"{where}: model.{key}: {v.size} values, a triad has 3")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            at = f"[{bad[0]}]" if v.size > 1 else ""
            raise InputError(f"{where}: model.{key}{at} = {v[bad[0]]}: not a finite number")
    zero = np.flatnonzero(m.k == 0)
    if zero.size:
        raise InputError(f"{where}: model.k_v_per_g[{zero[0]}] = 0: a scale factor cannot be "
                         "zero")
    wide = np.flatnonzero(np.abs(m.beta) >= MAX_BETA_RAD)
    if wide.size:
        raise InputError(f"{where}: model.beta_rad[{wide[0]}] = {m.beta[wide[0]]:.4g} rad: "
                         f"beyond any triad's non-orthogonality (< {MAX_BETA_RAD:.4g} rad)")
    if m.cov is not None and (m.cov.ndim != 2 or m.cov.shape[0] != m.cov.shape[1]
                              or (m.names and m.cov.shape[0] != len(m.names))):
        raise InputError(f"{where}: model.covariance: shape {m.cov.shape} does not match "
                         f"its {len(m.names)} parameter_names")
    return m
