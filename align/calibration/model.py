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
from scipy.optimize import least_squares, minimize_scalar

from align.calibration.effects import (  # noqa: F401  (re-exported: the public names)
    ASYMMETRY,
    CROSS,
    DRIFT,
    EFFECT_UNITS,
    EFFECTS,
    HYSTERESIS,
    IN_TIME,
    K3,
    NONLIN,
    PAIRS,
    SCALE_DRIFT,
    SCALE_TEMP,
    SCALE_WARMUP,
    TEMP,
    TURN_G,
    WARMUP,
    Effect,
    turn_signs,
)
from align.calibration.ellipsoid import extract, li_griffiths
from align.calibration.residual import stage_functions, stage_residual
from align.calibration.triad import CORE, Poses, TriadModel, pose_gradient, pose_sigma_g
from align.calibration.walk import (
    WanderFit,
    allowed_fraction,
    walk_covariance,
    wander_fit,
    wander_shape,
)
from align.errors import InputError, NotApplicable
from align.loop import Candidate, StageFit, Term

WARMUP_TAUS = (0.1, 0.2, 0.4, 0.8)
"""Scale warm-up time constants first tried, as fractions of the poses' time span (the best
is then refined between its neighbours; one searched parameter in BIC). Not shorter: a
warm-up faster than a tenth of the run is one or two poses, not a trend."""


def _pack_names(effects: Sequence[str]) -> tuple[str, ...]:
    names = list(CORE)
    for e in effects:
        names += [n for _, _, n in EFFECTS[e].slots]
    return tuple(names)


def _n_params(effects: Sequence[str]) -> int:
    return 9 + sum(len(EFFECTS[e].slots) for e in effects)


def _model_from(theta: np.ndarray, effects: Sequence[str], t_ref: float, temp_ref: float,
                cov: np.ndarray | None = None, tau_s: float = 0.0) -> TriadModel:
    kw: dict[str, np.ndarray] = {"cross": np.zeros((3, 3))}
    i = 9
    for e in effects:
        for fld, idx, _ in EFFECTS[e].slots:
            # A later effect on the same field (warm-up after drift) adds to it.
            v = kw.setdefault(fld, np.zeros(3))
            v[idx] += theta[i]
            i += 1
    return TriadModel(theta[:3], theta[3:6], theta[6:9], t_ref=t_ref, temp_ref=temp_ref,
                      cov=cov, names=_pack_names(effects),
                      warmup_tau_s=tau_s if SCALE_WARMUP in effects else 0.0, **kw)


SCREEN_TRUST = 0.25
"""The screen predicts a candidate's chi2 only where the model's chi2 at the Gauss-Newton
step is the linear prediction to this fraction of the predicted drop (+1)."""
def algebraic(poses: Poses, signs: Sequence[float]) -> TriadModel:
    """The seed paper's solution: Li–Griffiths + exact extraction (no refinement)."""
    k, beta, b = extract(li_griffiths(poses.u), np.asarray(signs, float))
    return TriadModel(k, beta, b, t_ref=float(np.mean(poses.t)),
                      temp_ref=float(np.mean(poses.temp)) if poses.temp is not None else 0.0)


def walk_physical(rate_g: np.ndarray, t: np.ndarray) -> bool:
    """Whether a bias random walk of ``rate_g`` per axis [g²/s] stays within
    :data:`EFFECT_PRIOR_G` (one sigma) over the poses' time span ``t`` [s]: beyond, the
    samples within the poses move (turn chunks taken for poses), no bias wanders so."""
    return bool(np.sqrt(np.max(rate_g) * max(float(np.ptp(t)), 1.0)) <= EFFECT_PRIOR_G)


class CalibrationStage:
    """Maximum-likelihood ellipsoid refinement with optional effects (the loop's stage)."""

    def __init__(self, poses: Poses, signs: Sequence[float], walk: bool = True,
                 bounds: dict[str, float] | None = None):
        if len(poses.u) < 9:
            raise InputError(f"only {len(poses.u)} usable poses; the model needs at least 9 "
                             "(the paper's cube gives 14)")
        self.poses = poses
        self.bounds = dict(bounds or {})  # declared bounds replacing prior_bound's
        self.condition: dict[tuple[str, ...], float] = {}
        # Per fitted effect list: the map from the weighted pose residuals to the parameters
        # (A = cov_unit J^T W^1/2, dtheta = A dr_w) and the weighted residuals, for the
        # widening of u when structure remains (align.calibration.widen).
        self.projection: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray]] = {}
        self.solutions: dict[tuple[str, ...], np.ndarray] = {}
        self.jacobians: dict[tuple[str, ...], np.ndarray] = {}
        # Every fit made (the loop's trials too), for the alternatives that widen u.
        self.fits: dict[tuple[str, ...], tuple[StageFit, tuple[Term, ...]]] = {}
        self.start = algebraic(poses, signs)
        self.sigma = pose_sigma_g(self.start, poses)
        # The bias instability the samples show (align.calibration.walk): the poses'
        # residuals are correlated in time; the fit whitens them with the Cholesky factor of
        # their covariance (generalised least squares), and sigma is each pose's total.
        self.whiten: np.ndarray | None = None
        self._white: tuple[float, np.ndarray, np.ndarray] | None = None
        # The input along each sensing axis (u / k; its bias cancels in the changes).
        self.turns = turn_signs(poses.u / self.start.k, poses.t)
        self.walk_share = 0.0  # the fraction of the samples' walk rate in the noise model
        # The walk the samples show [g²] between the poses, and the least fraction of it
        # their estimate allows (None: no walk in the noise).
        self.walk: tuple[np.ndarray, float] | None = None
        if (walk and self.sigma is not None and poses.walk_rate is not None and poses.ordered
                and walk_physical(poses.walk_rate / self.start.k**2, poses.t)):
            # Each axis at least the axes' mean rate [g²/s]: one sensor technology, and
            # the per-axis estimates scatter by about their size at a few µg/√s.
            k2 = self.start.k**2
            rate = np.maximum(poses.walk_rate / k2, np.mean(poses.walk_rate / k2)) * k2
            C = np.diag(self.sigma**2) + walk_covariance(
                rate, pose_gradient(self.start, poses), poses.t)
            f = self.means_allow(C - np.diag(self.sigma**2))
            # ... when they allow the level the samples show, within its uncertainty (the
            # one-sided bound mirrored): less, and the samples' low frequencies are mostly
            # a settling, not a walk (the wander alternative still weighs one).
            low = np.mean(2 * poses.walk_rate - poses.walk_bound) / np.mean(poses.walk_rate)
            if f > 0 and f >= low:
                C = np.diag(self.sigma**2) + f * (C - np.diag(self.sigma**2))
                self.whiten = np.linalg.inv(np.linalg.cholesky(C))
                self.walk = (C - np.diag(self.sigma**2)) / f, float(low)
                self.sigma = np.sqrt(np.diag(C))
                self.walk_share = f

    def log_det(self) -> float:
        """log det of the pose residuals' covariance [ln g²] (the noise model's part of −2 log
        likelihood: two noise models are compared by chi2 + log det, not chi2 alone)."""
        if self.whiten is not None:
            return float(-2 * np.sum(np.log(np.abs(np.diag(self.whiten)))))
        return float(2 * np.sum(np.log(self.sigma))) if self.sigma is not None else 0.0

    def means_allow(self, walk: np.ndarray, effects: tuple[str, ...] | None = None) -> float:
        """The largest fraction f <= 1 of a walk's covariance ``walk`` (N, N) [g²] that the
        pose means allow: the declared model's white-noise chi2 not in the lower WALK_ALPHA
        tail of its distribution under diag(sigma²) + f walk (Σ λ_i χ²₁, λ the eigenvalues of
        the residual-space covariance; 20000 seeded draws: scipy has no such distribution);
        0 when even 1e-4 of it is excluded. A pose's own settling (a hand-placed unit)
        shows in its samples as a walk does but does not go on from pose to pose: the means
        then scatter as white noise, and the walk is not one.

        ``effects``: judged on the white fit with these effects instead (fitted before, the
        stage's noise white): a warming bias makes the declared model's chi2 large whatever
        the walk, and only the residual beyond the effects tells whether a walk goes on."""
        if effects is not None:
            if self.whiten is not None or effects not in self.jacobians:
                raise NotApplicable("the means are judged on a white-noise fit")
            J = self.jacobians[effects]
            q, _ = np.linalg.qr(J)
            r_w = self.projection[effects][1]
            return allowed_fraction(float(np.sum(r_w**2)), np.eye(len(r_w)) - q @ q.T,
                                 1.0 / self.sigma, walk)
        if self._white is None:
            # The white-noise fit of the declared model, leaving the stage's own as it was.
            whiten, self.whiten = self.whiten, None
            stores = (self.solutions, self.projection, self.condition, self.jacobians)
            kept = [st.pop((), None) for st in stores]
            _, r, _ = self.refine([])
            J = self.jacobians[()]
            for st, v in zip(stores, kept, strict=True):
                st.pop((), None)
                if v is not None:
                    st[()] = v
            self.whiten = whiten
            q, _ = np.linalg.qr(J)
            self._white = (float(np.sum((r / self.sigma) ** 2)),
                           np.eye(len(r)) - q @ q.T, 1.0 / self.sigma)
        return allowed_fraction(*self._white, walk)

    def _check_applies(self, effects: Sequence[str]) -> None:
        p = self.poses
        for e in effects:
            if e in (TEMP, SCALE_TEMP) and p.temp is None:
                raise NotApplicable("no temperature column")
            if e == HYSTERESIS and not p.ordered:
                raise NotApplicable("the pose order is not known (no time column)")

    def _residual(self, effects: Sequence[str]) -> Callable[[np.ndarray, float], np.ndarray]:
        """The weighted residuals (|a_p| - 1) / sigma_p as a function of (theta, tau):
        :func:`align.calibration.residual.stage_residual`."""
        return stage_residual(self, effects)

    def _scale(self, effects: Sequence[str]) -> np.ndarray:
        """Typical size of each parameter (least_squares' x_scale, the screening's step)."""
        s0, p = self.start, self.poses
        return np.concatenate([np.abs(s0.k) * 1e-3, np.full(3, 1e-4), np.full(3, 1e-4),
                               np.concatenate([_effect_scale(e, p) for e in effects])
                               if effects else []])

    def screen(self, current: StageFit, terms: Sequence[Term], names: Sequence[str]
               ) -> dict[str, float]:
        """The chi2 each candidate in ``names`` would leave, linearised at ``current`` (the
        fit of ``terms``): the score test's drop |P r|^2, P the projection on the
        candidate's Jacobian columns with the fitted parameters' columns projected out
        (the scale warm-up: the largest drop over its tau grid). A screen, not the test:
        the loop refits what might pass (:data:`align.loop.SCREEN_MARGIN`). Candidates that
        do not apply are left out (the refit says why)."""
        effects = tuple(t.name for t in terms)
        base = self.solutions.get(effects)
        jac = self.jacobians.get(effects)
        if base is None or jac is None:
            return {}
        r = self.projection[effects][1]
        tau0 = current.payload.warmup_tau_s if current.payload is not None else 0.0
        q, _ = np.linalg.qr(jac)
        r_perp = r - q @ (q.T @ r)
        span = max(float(np.ptp(self.poses.t)), 1.0)
        out = {}
        for name in names:
            if name in effects:
                continue
            try:
                self._check_applies([name])
            except NotApplicable:
                continue
            ext = [*effects, name]
            resid = self._residual(ext)
            h = self._scale(ext)[len(base):]
            taus = (np.asarray(WARMUP_TAUS) * span if name == SCALE_WARMUP and SCALE_WARMUP
                    not in effects else [tau0])
            best, linear = 0.0, True
            for tau in taus:
                th = np.concatenate([base, np.zeros(len(h))])
                f0 = resid(th, float(tau))
                cols = []
                for j, hj in enumerate(h):
                    tj = th.copy()
                    tj[len(base) + j] = hj
                    cols.append((resid(tj, float(tau)) - f0) / hj)
                c = np.column_stack(cols)
                # The Gauss-Newton step with the candidate: trusted where the model is
                # quadratic over it (its chi2 there as predicted, to a quarter of the drop);
                # else (a K2 that runs k away) no prediction: the refit decides.
                step = -np.linalg.lstsq(np.hstack([jac, c]), f0, rcond=None)[0]
                c = c - q @ (q.T @ c)
                beta = np.linalg.lstsq(c, r_perp, rcond=None)[0]
                drop = float(np.sum((c @ beta) ** 2))
                there = float(np.sum(resid(th + step, float(tau)) ** 2))
                if abs(there - (current.chi2 - drop)) > SCREEN_TRUST * drop + 1.0:
                    linear = False
                best = max(best, drop)
            if not linear:
                continue
            chi2 = current.chi2
            # In chi2's units (sigma unknown: the residuals are in g, chi2 the RSS).
            out[name] = max(chi2 - best, 0.0)
        return out

    def refine(self, effects: Sequence[str]) -> tuple[TriadModel, np.ndarray, np.ndarray]:
        p = self.poses
        s0 = self.start
        self._check_applies(effects)
        theta0 = np.concatenate([s0.k, s0.beta, s0.bias, np.zeros(_n_params(effects) - 9)])
        prev = self.solutions.get(tuple(effects[:-1]))
        if prev is not None:  # start a trial from the fit it extends (a few iterations)
            theta0[:len(prev)] = prev
        w = 1.0 / self.sigma if self.sigma is not None else np.ones(len(p.u))
        resid, jac = stage_functions(self, effects)
        if len(p.u) < len(theta0):
            raise NotApplicable("more parameters than poses")
        scale = self._scale(effects)
        span = max(float(np.ptp(p.t)), 1.0)

        def solve(tau: float):
            return least_squares(resid, theta0, jac=jac, x_scale=scale, method="lm",
                                 xtol=1e-10, ftol=1e-12, gtol=1e-12, max_nfev=300,
                                 args=(tau,))

        if SCALE_WARMUP in effects:
            # tau: the best of a log grid, then refined between its neighbours (bounded
            # scalar search on log tau; one searched parameter in BIC).
            grid = np.log(np.asarray(WARMUP_TAUS) * span)
            costs = [solve(float(np.exp(g))).cost for g in grid]
            j = int(np.argmin(costs))
            lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]
            best = minimize_scalar(lambda g: solve(float(np.exp(g))).cost, bounds=(lo, hi),
                                   method="bounded", options={"xatol": 0.02})
            tau = float(np.exp(best.x))
        else:
            tau = 0.0
        res = solve(tau)
        self.solutions[tuple(effects)] = res.x
        self.jacobians[tuple(effects)] = np.asarray(res.jac, float)
        # In g at each pose's sigma (whitened residuals when the walk correlates them).
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
        return _model_from(res.x, effects, s0.t_ref, s0.temp_ref, cov, tau), r, res.x

    def wander(self, level: float | None = None) -> WanderFit | None:
        """The declared model (no effect) with a bias random walk between the poses, its
        level fitted (:func:`align.calibration.walk.wander_fit`): the explanation every
        effect the loop adds is weighed against (on 14 poses a wander of a few µg is not
        separable from a drift); ``level`` [g²/s]: at that level instead. None: noise
        unknown, order unknown, or not fitted."""
        p = self.poses
        if self.sigma is None or not p.ordered or () not in self.fits:
            return None
        a = self.fits[()][0].payload.specific_force(p.u, p.t, p.temp)
        up = a / np.linalg.norm(a, axis=1, keepdims=True)
        W = self.whiten if self.whiten is not None else np.diag(1.0 / self.sigma)
        return wander_fit(self.projection[()][1], self.jacobians[()],
                          wander_shape(up, p.t, W), level)

    def fit(self, terms: Sequence[Term]) -> StageFit:
        effects = [t.name for t in terms]
        m, r, _ = self.refine(effects)
        p = self.poses
        a = m.specific_force(p.u, p.t, p.temp)
        d = a / np.linalg.norm(a, axis=1, keepdims=True)
        regs = {"ax": d[:, 0], "ay": d[:, 1], "az": d[:, 2], "t": p.t}
        if p.temp is not None and np.ptp(p.temp) > 0:
            regs["temp"] = p.temp
        for e in set(effects) & {K3, ASYMMETRY}:
            # Odd K3 and |x| are k's and K2's columns on most poses: where the poses cannot
            # measure the effect within its physical range, it is not a candidate for them
            # (skipped, as hysteresis without the pose order) rather than a run-away to
            # refuse (K2 on the paper's 14 poses: K3 = 0.02 at condition 5e3).
            u_max = max(m.u_of(n) for _, _, n in EFFECTS[e].slots)
            # (The physical bound: whether the poses measure it at all; a declared bound
            # is carried in u where they do not fit it, align.calibration.nonlinearity.)
            if not u_max <= prior_bound(e) / DETERMINED:
                raise NotApplicable(f"these poses cannot measure it: u {u_max:.2g} > 1/"
                                    f"{DETERMINED:g} of its physical bound {prior_bound(e):g}")
        eff = {}
        comps = {}
        for e in effects:
            slots = [EFFECTS[e].slots[j] for j in EFFECTS[e].report]
            vals = np.array([getattr(m, fld)[idx] for fld, idx, _ in slots])
            us = np.array([m.u_of(n) for _, _, n in slots])
            j = int(np.argmax(np.abs(vals) / np.where(us > 0, us, np.inf)))
            eff[e] = (float(vals[j]), float(us[j]))
            comps[e] = tuple((n.rsplit("_", 1)[-1] if len(slots) > 1 else n, float(v),
                              float(uu)) for (_, _, n), v, uu in zip(slots, vals, us,
                                                                     strict=True))
        q = {n: (float(v), m.u_of(n)) for n, v in zip(
            CORE, np.concatenate([m.k, m.beta, m.bias]), strict=True)}
        fit = StageFit(r, self.sigma, _n_params(effects), regs, "t", eff, q,
                       components=comps, payload=m)
        self.fits[tuple(effects)] = (fit, tuple(terms))
        return fit


def _spans(p: Poses) -> tuple[float, float]:
    """Time span [s] and temperature span [K] of the poses (at least 1 s, 1 mK)."""
    return (max(float(np.ptp(p.t)), 1.0),
            max(float(np.ptp(p.temp)) if p.temp is not None else 1.0, 1e-3))


def _effect_scale(e: str, p: Poses) -> np.ndarray:
    """Typical size of each parameter of ``e`` (least_squares' x_scale): 10 µg at 1 g."""
    size = EFFECTS[e].size(*_spans(p))
    if e == WARMUP:  # its drift slots are per second, its curvature per second squared
        t = _spans(p)[0]
        return np.concatenate([np.full(3, 1e-5 / t), np.full(3, 1e-5 / size)])
    return np.full(len(EFFECTS[e].slots), 1e-5 / size)


def _term(name: str):
    def build(fit: StageFit) -> Term | None:
        if name in (TEMP, SCALE_TEMP) and "temp" not in fit.regressors:
            return None
        if name in (DRIFT, WARMUP, SCALE_DRIFT, SCALE_WARMUP) and np.ptp(
                fit.regressors["t"]) == 0:
            return None
        width = len(EFFECTS[name].slots)
        if fit.n - fit.n_params < width + 1:
            return None
        return Term(name, EFFECT_UNITS[name], np.zeros((fit.n, width)),
                    searched=1 if name == SCALE_WARMUP else 0,
                    trials=len(CROSS) if name in CROSS else 1.0)
    return build


CANDIDATES: tuple[Candidate, ...] = (
    Candidate(NONLIN, "1/g", "second-order scale-factor nonlinearity K2 per axis", _term(NONLIN)),
    Candidate(DRIFT, "g/s", "bias drifting linearly during the session", _term(DRIFT)),
    Candidate(TEMP, "g/K", "bias following the temperature", _term(TEMP)),
    Candidate(WARMUP, "g/s^2", "bias warming up: drift that slows or turns (quadratic in "
              "time)", _term(WARMUP)),
    *(Candidate(c, "1/g", f"cross-axis second-order term: axis {c[6]} output from the product "
                f"a_{c[8]} a_{c[9]} (IEEE Std 1293 K_ip/K_io)", _term(c)) for c in CROSS),
    Candidate(SCALE_DRIFT, "1/s", "scale factor drifting linearly in time (relative)",
              _term(SCALE_DRIFT)),
    Candidate(SCALE_TEMP, "1/K", "scale factor following the temperature (relative)",
              _term(SCALE_TEMP)),
    Candidate(SCALE_WARMUP, "1", "scale factor warming up: exp(-t/tau) settling (relative "
              "amplitude; tau searched)", _term(SCALE_WARMUP)),
    Candidate(K3, "1/g^2", "third-order scale-factor nonlinearity K3 per axis (IEEE Std 1293; "
              "odd: separable from k only with poses at intermediate components)", _term(K3)),
    Candidate(ASYMMETRY, "1", "scale-factor asymmetry (k+ - k-)/(k+ + k-) per axis (IEEE Std "
              "1293; separable only with both signs and intermediate components)",
              _term(ASYMMETRY)),
    Candidate(HYSTERESIS, "g", "bias hysteresis: offset by the sign of the previous turn on "
              "each axis (pose order known)", _term(HYSTERESIS)),
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
EFFECT_PRIOR_G = 3e-3
"""... nor an effect in time or temperature (drifts, warm-ups, hysteresis) reach more than
this [g] at 1 g over the poses' time and temperature spans (real triads: scale drift below
1e-3 over a run, hysteresis below 1 mg; a phone-like recording with 2 mg noise took a 0.9 %
scale drift at 1e-2) ..."""
SCALE_TEMPCO_PRIOR_PER_K = 1e-3
"""... nor a scale factor's temperature coefficient exceed this [1/K] (so its reach is this
times the poses' temperature span [g at 1 g]): a tempco, not a reach, is what a sensor has
(QA-2000 < 180 ppm/°C, ADXL355 ±100, BMI160 ±300 ppm/K: 3e-3 over 10 K, real) ..."""
ATTITUDE_PRIOR_G = 1e-2
"""... nor K2, K3 or a cross-axis product more than this [g] at 1 g (a phone's K2 reaches
3e-3) ..."""
K3_PRIOR_G = 2e-3
"""... nor K3 more than this [g] at 1 g: a MEMS datasheet's ±0.1 % nonlinearity over its
±2 g span (4 mg) bounds K3 to 2e-3/g² (K3 x³ departs from its best line by 2 K3 at ±2 g;
navigation grade: below 3e-5); a larger K3 is k taken for a cubic (its column is nearly
k's) ..."""
ASYMMETRY_PRIOR = 1e-2
"""... nor a scale-factor asymmetry (k+ - k-)/(k+ + k-) more than this [1] (navigation
grade: below 1e-4; MEMS a few 1e-3)."""
DECLARED_Z = 3.0
"""A K2/K3 estimate is refused as beyond a declared bound only when it exceeds the bound by
more than this many of its own u (the truth may lie at the bound's edge)."""
DETERMINED = 3.0
"""K3 and the asymmetry are tried only where the poses measure them to this fraction of
their physical bound (u < bound / 3)."""
MAX_CONDITION = 1e7
"""Largest condition number of the (column-normalised) Jacobian: above it the data cannot
separate the effect from the model."""


def prior_bound(name: str, declared: dict[str, float] | None = None,
                temp_span_k: float = 1.0) -> float:
    """The physical bound on an effect's reach at 1 g [g] (the asymmetry's: [1]), or the
    user's ``declared`` one (K2, K3: :mod:`align.calibration.nonlinearity`); the scale
    factor's tempco's over the poses' temperature span ``temp_span_k`` [K]."""
    if declared and name in declared:
        return declared[name]
    if name == SCALE_TEMP:
        return SCALE_TEMPCO_PRIOR_PER_K * temp_span_k
    return (ATTITUDE_PRIOR_G if name in (NONLIN, *CROSS) else K3_PRIOR_G if name == K3
            else ASYMMETRY_PRIOR if name == ASYMMETRY else EFFECT_PRIOR_G)


def admissible(stage: CalibrationStage, overfit: bool = True
               ) -> Callable[[StageFit, StageFit, Term], str | None]:
    """The calibration's guard against a run-away loop: the reason to refuse an effect that
    the significance tests call for, or None (design: physical priors, over-fit, rank).
    ``overfit=False``: the physical checks alone (for the alternatives whose shifts widen u,
    where a fit that is too good is a reason to count it, not to refuse it)."""

    def check(base: StageFit, trial: StageFit, term: Term) -> str | None:
        mb, mt = base.payload, trial.payload
        cond = stage.condition.get(tuple(t.name for t in [*_terms_of(base), term]),
                                   float("nan"))
        if not np.isfinite(cond) or cond > MAX_CONDITION:
            return (f"the poses cannot separate it from the model (condition number "
                    f"{cond:.3g} > {MAX_CONDITION:.0e})")
        e = EFFECTS[term.name]
        vals = np.array([getattr(mt, e.slots[j][0])[e.slots[j][1]] for j in e.report])
        size = e.size(*_spans(stage.poses))
        if term.name == SCALE_WARMUP:  # its regressor is exp(-(t - t_ref)/tau) - 1
            size = float(np.max(np.abs(np.expm1(-(stage.poses.t - mt.t_ref)
                                                 / mt.warmup_tau_s))))
        reach = float(np.max(np.abs(vals))) * size
        bound = prior_bound(term.name, stage.bounds, _spans(stage.poses)[1])
        if term.name in stage.bounds:
            # A datasheet's bound may hold the truth at its edge: refused only when the
            # estimate lies beyond it by more than DECLARED_Z of its own u.
            us = np.array([mt.u_of(e.slots[j][2]) for j in e.report]) * size
            over = float(np.max(np.abs(vals) * size - DECLARED_Z * us))
            if over > bound:
                return (f"it reaches {reach:.3g} g at 1 g (less {DECLARED_Z:g} u: "
                        f"{over:.3g} g), beyond its declared bound {bound:g} g")
        elif reach > bound:
            return (f"it reaches {reach:.3g} g at 1 g over the run (> {bound} g): "
                    "outside the physical prior")
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
        if overfit and term.name == ASYMMETRY and NONLIN not in base.effects:
            why = _not_separated(stage, base, trial)
            if why:
                return why
        if overfit and trial.sigma is not None and trial.dof > 0:
            red = trial.chi2 / trial.dof
            u = np.array([base.quantities[n][1] for n in CORE])
            shift = np.abs(np.concatenate([mt.k - mb.k, mt.beta - mb.beta, mt.bias - mb.bias]))
            z = shift / np.where(u > 0, u, np.inf)
            if red < OVERFIT_CHI2 and z.max() > OVERFIT_SIGMA:
                i = int(np.argmax(z))
                return (f"over-fit: chi2/dof falls to {red:.3g} while {mb.names[i]} moves by "
                        f"{z[i]:.0f} of its standard uncertainty")
        return None

    return check


SEPARATE_CHI2 = 9.0
"""chi2 by which a scale-factor asymmetry must explain the poses better than K2 to be taken
for it (a 3-sigma difference): |x| and x² are equal at 0 and ±1 g and differ only at
intermediate components, so on most pose sets the two even effects are near-aliases."""


def _not_separated(stage: CalibrationStage, base: StageFit, trial: StageFit) -> str | None:
    """Why an asymmetry is not taken for K2 (None: it is separated; noise unknown: no test).
    K2 is the established effect: it is kept where the poses do not tell the two apart (the
    widening still weighs the asymmetry as an alternative)."""
    if trial.sigma is None:
        return None
    try:
        _, r, _ = stage.refine([*base.effects, NONLIN])
    except NotApplicable:
        return None
    d = float(np.sum((r / stage.sigma) ** 2)) - trial.chi2
    if d < SEPARATE_CHI2:
        return (f"the poses do not separate it from {NONLIN} (chi2 only {d:.3g} lower, "
                f"< {SEPARATE_CHI2:g}): |x| and x^2 differ only at intermediate components")
    return None


def _terms_of(fit: StageFit) -> list[Term]:
    """The effect terms a calibration fit carries (the names are all the guard needs)."""
    return [Term(n, "", np.zeros((0, 0))) for n in fit.effects]


