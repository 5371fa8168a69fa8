"""The triad's bias instability: a random walk of the bias estimated from the samples within
each pose, and the covariance it puts between the pose means.

Every triad's bias wanders (a random walk at its shortest time scales, a flicker floor
beyond). Over a tumble of minutes that wander is not independent from pose to pose: two poses
a short time apart share most of it, and on the paper's 14 poses a wander of a few µg is not
separable from a linear scale or bias drift. The calibration's noise model therefore carries
it as a time-correlated covariance between the poses (a Wiener process, Cov(b_p, b_q) =
q min(t_p, t_q)), so a drift candidate must beat the wander, not white noise.

The level q is measured where no calibration effect can mimic it: within each pose, from the
spectrum of its samples at the lowest frequencies after the pose's mean and trend are
removed (a drift of the scale factor or the bias over a pose is a trend). When the samples
show a walk, it enters the noise model (:class:`align.calibration.model.CalibrationStage`).
When they do not, they still bound it; the poses' means may then show a wander a drift
candidate explains as well (:func:`wander_fit`, the alternatives that widen u in
:mod:`align.calibration.pipeline`). Hand-written: no well-kept library estimates one
random-walk level from many short, separate records (allantools wants one long series).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import fft, special
from scipy.optimize import minimize_scalar

WALK_ALPHA = 1e-3
"""Significance at which the poses' low-frequency scatter must exceed white noise before a
random walk enters the noise model (white noise alone: the clean triad's fit is unchanged)."""
MIN_WALK_SAMPLES = 48
"""Fewest samples of a pose whose spectrum is used."""
MAX_POINTS = 240
"""A longer pose is averaged in blocks down to at most this many points first (the exact
expectations below take O(n²) memory; the low modes are what counts)."""
LOW_MODES = (2, 7)
"""The DCT modes [first, last) that carry the walk (0 and 1, the mean and the trend, are
removed: a drift of the scale factor or the bias over a pose is not a wander)."""
TREND_PARAMS = 4
"""The fit each axis's pose trends are taken less: (1, t, u, u t), a bias or scale drift,
steady or changing over the run."""
WHITE_BAND = (1 / 8, 1 / 3)
"""The modes, as fractions of the points, that give the white level: below the sampling's
anti-alias filter (which lowers the highest modes of a real sensor) and above the walk."""


@functools.lru_cache(maxsize=MAX_POINTS)
def _expectations(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Per DCT mode of a detrended series of n points: the expected square for unit white
    noise and for a unit random walk (variance 1 per point); the unit ramp (centred) and the
    walk's expected square on it (white: 1). Exact: the detrending projector P and the walk's
    covariance min(i, j) through the orthonormal DCT-II. Kept for every n (at most
    MAX_POINTS of them, 3 n numbers each): poses of different lengths missed a cache of 8,
    and each miss is an O(n³) product."""
    i = np.arange(n, dtype=float)
    X = np.column_stack([np.ones(n), i - i.mean()])
    P = np.eye(n) - X @ np.linalg.pinv(X)
    D = fft.dct(np.eye(n), norm="ortho", axis=0)
    DP = D @ P
    walk = np.minimum.outer(i + 1, i + 1)
    ramp = (i - i.mean()) / np.linalg.norm(i - i.mean())
    return (np.einsum("ij,ij->i", DP, DP), np.einsum("ij,jk,ik->i", DP, walk, DP), ramp,
            float(ramp @ walk @ ramp))


def walk_levels(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
                skip: Sequence[int] = ()) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The bias random walk's rate q per axis [output unit² / s] when the samples show one
    at :data:`WALK_ALPHA` (else None), and the largest rate they do not exclude at
    :data:`WALK_ALPHA` (one-sided; None: too short to tell) — :func:`walk_estimate`, the
    poses ``skip`` (:func:`walk_outliers`) left out."""
    est = walk_estimate(samples, times, skip)
    if est is None:
        return None, None
    rate, sd, p = est
    return (rate if p < WALK_ALPHA else None), rate - special.ndtri(WALK_ALPHA) * sd


def walk_outliers(samples: Sequence[np.ndarray], times: Sequence[np.ndarray]
                  ) -> tuple[int, ...]:
    """The poses whose low frequencies are beyond the walk and white noise the other poses
    show (indices into ``samples``): a walk goes on in every pose, a step or a knock in one.

    Each pose's low modes (:data:`LOW_MODES`, per axis) against their expectation under the
    other poses' (s², q) (:func:`walk_estimate` without it): the sum a weighted chi2, its
    tail bounded by its mean times one chi2 of 1 dof; the worst pose is out when its p is below
    :data:`WALK_ALPHA` / (3 N) (Bonferroni over the poses and axes), then the next, at most
    a quarter of the poses (more is not one event but a noise the model lacks)."""
    out: list[int] = []
    lo = slice(*LOW_MODES)
    while len(out) < len(samples) // 4:
        worst, p_min = -1, 1.0
        for i, (x, t) in enumerate(zip(samples, times, strict=True)):
            if i in out or len(x) < MIN_WALK_SAMPLES or np.ptp(t) <= 0:
                continue
            est = walk_estimate(samples, times, (*out, i), levels=True)
            if est is None:
                return tuple(out)
            s2b, q = est
            _, c2, b, dt = _pose_modes(x, t)
            w, g, _, _ = _expectations(len(c2))
            e = w[lo, None] * s2b + g[lo, None] * dt * b * q  # each mode's expectation
            # Σ E_k χ²₁ is bounded in its far tail by its mean times one χ²₁ (all of it in
            # one mode): a walk's modes fall as 1/k², and Satterthwaite's dof (2-5) flagged
            # a pose in 3 of 40 synth tumbles walking at 1e-5 g/√s (1 χ²₁: 0 of 40).
            stat = c2[lo].sum(0) * b / np.maximum(e.sum(0), 1e-300)
            p = float(np.min(special.chdtrc(1, stat)))
            if p < p_min:
                worst, p_min = i, p
        if worst < 0 or p_min >= WALK_ALPHA / (3 * len(samples)):
            break
        out.append(worst)
    return tuple(out)


def _pose_modes(x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, float]:
    """One pose's b-sample averages (n, 3) [output unit] (at most :data:`MAX_POINTS`), their
    detrended DCT squares (n, 3) [output unit²], b and one averaged point's time [s]."""
    b = -(-len(x) // MAX_POINTS)
    n = len(x) // b
    y = x[:n * b].reshape(n, b, -1).mean(1)
    i = np.arange(n, dtype=float)
    X = np.column_stack([np.ones(n), i - i.mean()])
    r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    return y, fft.dct(r, norm="ortho", axis=0) ** 2, b, np.ptp(t) / (len(x) - 1) * b


def walk_estimate(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
                  skip: Sequence[int] = (), levels: bool = False
                  ) -> tuple[np.ndarray, ...] | None:
    """The bias random walk's rate q per axis [output unit² / s] (clipped at 0), its standard
    deviation, and the p-value of white noise alone; None when too short to tell.

    Each pose's samples (block-averaged to at most :data:`MAX_POINTS`), detrended, through
    the orthonormal DCT: white noise of variance s² puts s² w_k in mode k, a random walk of
    q per point q g_k (w, g exact for the detrended series). Summed over the poses, the low
    modes (:data:`LOW_MODES`) and a white band (:data:`WHITE_BAND`) give two equations in
    (s², q) per axis; the test: the low modes' mean square over the white band's, an
    F(3 dof_low, 3 dof_white) under white noise (the axes pooled).

    Parameters
    ----------
    samples : sequence of (n_p, 3) arrays
        Each pose's samples [output unit].
    times : sequence of (n_p,) arrays
        Their times [s].
    skip : sequence of int
        Poses left out (:func:`walk_outliers`).
    levels : bool
        Return only (s² b, q) per axis, clipped at 0 (the white level of one sample times
        its seconds [output unit² s], the walk's rate [output unit² / s]).
    """
    lo = slice(*LOW_MODES)
    S = np.zeros((2, 3))
    W = np.zeros(2)
    G = np.zeros(2)
    dof = np.zeros(2)
    trend, trend_g, where, when = [], [], [], []
    low_w, low_g = [], []  # each low mode's expected square per unit white and walk
    for k, (x, t) in enumerate(zip(samples, times, strict=True)):
        if k in skip or len(x) < MIN_WALK_SAMPLES or np.ptp(t) <= 0:
            continue
        y, c2, b, dt = _pose_modes(x, t)
        n = len(y)
        w, g, ramp, g_ramp = _expectations(n)
        hi = slice(int(n * WHITE_BAND[0]), int(n * WHITE_BAND[1]))
        for j, band in enumerate((lo, hi)):
            # White variance of a point: s²/b, the walk's per point q dt: both per second.
            S[j] += c2[band].sum(0) * b
            W[j] += w[band].sum()
            G[j] += g[band].sum() * dt * b
            dof[j] += len(w[band])
        low_w.append(w[lo])
        low_g.append(g[lo] * dt * b)
        trend.append(ramp @ y * np.sqrt(b))
        trend_g.append(g_ramp * dt * b)
        where.append(y.mean(0))
        when.append(float(np.mean(t)))
    if len(trend) > 2 * TREND_PARAMS:
        # Each pose's trend (its samples on the unit ramp): a walk's is random, a drift's
        # (of the bias or the scale factor, steady or not) follows the run and the pose's
        # output: the trends less their fit on (1, t, u, u t) per axis carry the walk alone.
        tr, gr = np.array(trend), np.array(trend_g)
        tt = np.array(when) - np.mean(when)
        u = np.array(where)
        for ax in range(3):
            D = np.column_stack([np.ones(len(tt)), tt, u[:, ax], u[:, ax] * tt])
            res = tr[:, ax] - D @ np.linalg.lstsq(D, tr[:, ax], rcond=None)[0]
            S[0, ax] += res @ res
        free = len(tr) - TREND_PARAMS
        W[0] += free
        G[0] += free * float(np.mean(gr))
        dof[0] += free
        low_w.append(np.ones(free))
        low_g.append(np.full(free, float(np.mean(gr))))
    if dof[0] < 3 * (LOW_MODES[1] - LOW_MODES[0]) or dof[1] < 10:
        return None
    ratio = float(np.mean((S[0] / W[0]) / (S[1] / W[1])))
    # (s² b, q) from S = W s² b + G q in the two bands, per axis; each band's sum a
    # chi2 of its dof times its mean (a normal approximation for the bound).
    M = np.array([[W[0], G[0]], [W[1], G[1]]])
    sol = np.linalg.solve(M, S)
    if levels:
        return np.maximum(sol[0], 0.0), np.maximum(sol[1], 0.0)
    inv = np.linalg.inv(M)
    # The low band's terms are unequal (a walk's modes fall as 1/k²): its variance is
    # 2 Σ E_k², E_k each term's expectation at the solution.
    e_low = (np.concatenate(low_w)[:, None] * np.maximum(sol[0], 0.0)
             + np.concatenate(low_g)[:, None] * np.maximum(sol[1], 0.0))
    sd = np.sqrt(inv[1, 0] ** 2 * 2 * np.sum(e_low**2, 0)
                 + (inv[1, 1] * S[1]) ** 2 * 2 / dof[1])
    return np.maximum(sol[1], 0.0), sd, float(special.fdtrc(3 * dof[0], 3 * dof[1], ratio))


def walk_covariance(rate: np.ndarray, g: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The covariance (N, N) [g²] of the poses' |a| residuals from a bias random walk.

    Cov = Σ_i g_p,i g_q,i q_i (min(t_p, t_q) − t_0): the walk from the first pose (its value
    there is the fitted bias), seen through each pose's d|a|/du ``g`` (N, 3) [g per output
    unit]; ``rate`` q per axis [output unit² / s]; ``t`` the poses' times [s]."""
    s = np.asarray(t, float) - float(np.min(t))
    return (g * rate) @ g.T * np.minimum(s[:, None], s[None, :])


WANDER = "bias_wander"
"""The alternative the loop's effects are weighed against: the declared model with a bias
random walk between the poses (its level fitted), no effect."""


@dataclass(frozen=True)
class WanderFit:
    """The declared model's fit with a bias wander in its noise (:func:`wander_fit`).

    Attributes
    ----------
    m2ll : float
        −2 log likelihood (constants shared with the white-noise fits dropped) —
        dimensionless.
    chi2 : float
        The generalised chi2 of the residuals under that noise — dimensionless.
    level : float
        The walk's rate q [g² / s] (in the units of ``shape``'s scale).
    step : numpy.ndarray
        The parameters' change from the fit it linearises [the parameters' units].
    cov : numpy.ndarray
        Their covariance [products of their units].
    """

    m2ll: float
    chi2: float
    level: float
    step: np.ndarray
    cov: np.ndarray


def wander_shape(up: np.ndarray, t: np.ndarray, whiten: np.ndarray) -> np.ndarray:
    """The covariance shape K (N, N) of an isotropic bias random walk of unit rate [g²/s]
    in the whitened pose residuals: ``whiten`` W (N, N) K₀ Wᵀ, K₀_pq = (n_p · n_q)
    (min(t_p, t_q) − t₀), ``up`` the poses' unit up vectors n (N, 3), ``t`` [s]."""
    s = np.asarray(t, float) - float(np.min(t))
    return whiten @ ((up @ up.T) * np.minimum.outer(s, s)) @ whiten.T


def wander_fit(r: np.ndarray, J: np.ndarray, shape: np.ndarray, level: float | None = None
               ) -> WanderFit:
    """Maximum likelihood of the walk's level q for the whitened residuals ``r`` (N,) of a
    fit with Jacobian ``J`` (N, P), linearised there: r + J δ ~ N(0, I + q K), K ``shape``.
    Profile likelihood over log q (bounded scalar search), δ and its covariance by
    generalised least squares at the best q (or at ``level`` when given). Hand-written: a
    one-parameter variance model in a few lines of numpy (statsmodels' GLS takes the
    covariance as given)."""
    norms = np.linalg.norm(J, axis=0)
    d = 1.0 / np.where(norms > 0, norms, 1.0)
    Jn = J * d

    def solve(q: float) -> tuple[float, float, np.ndarray, np.ndarray]:
        L = np.linalg.cholesky(np.eye(len(r)) + q * shape)
        rt = np.linalg.solve(L, r)
        Jt = np.linalg.solve(L, Jn)
        step = -np.linalg.lstsq(Jt, rt, rcond=None)[0]
        res = rt + Jt @ step
        chi2 = float(res @ res)
        return chi2 + 2 * float(np.sum(np.log(np.diag(L)))), chi2, step, Jt

    if level is not None:
        m2ll, chi2, step, Jt = solve(level)
        return WanderFit(m2ll, chi2, level, step * d,
                         d[:, None] * np.linalg.pinv(Jt.T @ Jt) * d[None, :])
    top = max(float(np.max(np.diag(shape))), 1e-300)
    lo, hi = np.log(1e-4 / top), np.log(1e5 / top)
    best = minimize_scalar(lambda g: solve(float(np.exp(g)))[0], bounds=(lo, hi),
                           method="bounded", options={"xatol": 0.05})
    q = float(np.exp(best.x))
    fit = solve(q)
    if solve(0.0)[0] <= fit[0]:  # no wander explains it better than none
        q, fit = 0.0, solve(0.0)
    m2ll, chi2, step, Jt = fit
    cov = d[:, None] * np.linalg.pinv(Jt.T @ Jt) * d[None, :]
    return WanderFit(m2ll, chi2, q, step * d, cov)


@functools.lru_cache(maxsize=4)
def _chi2_draws(n: int) -> np.ndarray:
    """:func:`allowed_fraction`'s 20000 seeded draws of n chi2_1 variables (20000, n), drawn
    once per n (read-only): drawing them was a third of its time."""
    z = np.random.default_rng(0).chisquare(1, (20000, n))
    z.setflags(write=False)
    return z


def allowed_fraction(chi2: float, P: np.ndarray, w: np.ndarray, walk: np.ndarray) -> float:
    """The largest fraction f <= 1 of a walk's covariance ``walk`` (N, N) [g²] that a white
    fit's ``chi2`` allows: not in the lower :data:`WALK_ALPHA` tail of its distribution under
    diag(sigma²) + f walk (Σ λ_i χ²₁, λ the eigenvalues of the residual-space covariance,
    ``P`` the fit's residual-space projector, ``w`` = 1/sigma per pose [1/g]; 20000 seeded
    draws: scipy has no such distribution); 0 when even 1e-4 of it is excluded
    (:meth:`align.calibration.model.CalibrationStage.means_allow`)."""
    Ww = P @ (w[:, None] * walk * w[None, :]) @ P
    z = _chi2_draws(len(w))
    # z @ lam in blocks of rows: OpenBLAS threads a product of this size, which cost 10-20
    # times the CPU of the blocks on a busy two-core machine (the same numbers: each row's
    # sum is the same kernel's).
    rows = max(40000 // len(w), 1)

    def allowed(f: float) -> bool:
        lam = np.clip(np.linalg.eigvalsh(P + f * Ww), 0, None)
        s = np.concatenate([z[i:i + rows] @ lam for i in range(0, len(z), rows)])
        return float(np.mean(s <= chi2)) >= WALK_ALPHA

    if allowed(1.0):
        return 1.0
    lo, hi = np.log(1e-4), 0.0
    if not allowed(float(np.exp(lo))):
        return 0.0
    for _ in range(12):  # bisection on log f: the chi2's lower tail grows with f
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if allowed(float(np.exp(mid))) else (lo, mid)
    return float(np.exp(lo))
