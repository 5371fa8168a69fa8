"""The scale factors' wander over the run, estimated from the poses' own trends.

While the triad is static its specific force is constant, so each pose's reading on axis a,
u_a = k_a s_a(t) (x_a + b_a(t)), changes in time only by the wander: within the pose

    du_a/dt = u_a ṡ_a/s_a + k_a ḃ_a      [output unit/s]

— a scale-factor rate seen in proportion to the axis's reading (its share of gravity), a bias
rate seen alike at every attitude. A ±100 ppm HVAC cycle of 15 min moves the axis that carries
gravity by up to 40 ppm of g within a 60 s pose, several times the slope's noise over a
thousand samples; a bias drift moves the axes that see ~0 g as much as the others. Across the
poses (their slopes, :mod:`align.calibration.slopes`, less what the loop's effects in time
already predict) each axis's rates are fitted by

    slope_pa − model_pa = k_a (β₀ + β₁ τ_p) + u_pa Σ_{j<M} c_j τ_p^j,   τ ∈ [−1, 1] over the run

(a bias rate that is steady or changes linearly; a scale rate ṡ/s a polynomial of degree
M − 1 in time, M ≤ :data:`MAX_TERMS`), weighted by the slopes' u. The scale terms are tested
with an F test pooled over the axes (the residual scatter as the noise scale, so a noise the
slopes' u misjudges by a common factor does not make a wander). When they are significant at
the loop's α, the path ε_a(t) − ε_a(t_ref) at each pose comes from the same rates through a
Gaussian process (:func:`wander_path`), each pose's readings are taken back to the scale at
``t_ref`` (:func:`corrected_poses`) and refitted (the loop and its structure tests run again
on them), and the path's covariance enters u as the ``scale_stability`` term G Σ_ε Gᵀ, G the
refit's gain (dθ = G ε of :mod:`align.calibration.stability`). Not significant, or not
visible (means only, no times, poses shorter than
:data:`~align.calibration.slopes.MIN_SLOPE_SAMPLES`), the stated assumption stays: a term
at the slopes' own resolution would widen every clean run's u (the path's u is tens of ppm
where k's is a few).
Hand-written: a weighted polynomial regression and its F test, a few lines of numpy/scipy.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import special

from align.calibration.triad import AXES, Poses, TriadModel

MAX_TERMS = 4
"""Most terms of the scale rate's polynomial in time (a cubic rate, a quartic path: enough
for one and a half cycles of a room's temperature over the run)."""
MIN_RESIDUAL_DOF = 3
"""Fewest residual degrees of freedom per axis left to the slopes' scatter."""
@dataclass(frozen=True)
class ScaleWander:
    """The scale wander the poses' trends show.

    Attributes
    ----------
    p : float
        The F test's p-value of the scale-rate terms (pooled over the axes) — dimensionless.
    found : bool
        p below the loop's significance level: the wander is corrected and its u carried —
        dimensionless.
    terms : int
        The test's polynomial terms M — dimensionless.
    path : numpy.ndarray or None
        When found: each pose's relative scale change from ``t_ref`` (N, 3) [1]
        (:func:`wander_path`).
    cov : numpy.ndarray or None
        Its covariance (3N, 3N), order 3p + a [1].
    """

    p: float
    found: bool
    terms: int
    path: np.ndarray | None = None
    cov: np.ndarray | None = None

    def to_dict(self) -> dict:
        """The JSON ``scale_stability.wander`` record: the test, and when found the path's
        half-range per axis and its largest u [ppm]."""
        d = {"p": float(self.p), "found": bool(self.found), "terms": int(self.terms),
             "range_ppm": None, "u_ppm": None}
        if self.path is not None and self.cov is not None:
            d["range_ppm"] = [float(v) * 1e6 / 2 for v in np.ptp(self.path, axis=0)]
            d["u_ppm"] = float(np.sqrt(np.max(np.diag(self.cov)))) * 1e6
        return d


def model_slopes(model: TriadModel, poses: Poses) -> np.ndarray:
    """What the model's effects in time make of each pose's slope (N, 3) [output unit/s]:
    the scale drift and warm-up (u ṡ/s) and the bias drift (k ḃ, to first order in β)."""
    dt = poses.t - model.t_ref
    rate = np.multiply.outer(np.ones_like(dt), model.scale_drift)
    if model.warmup_tau_s > 0:
        rate = rate - np.multiply.outer(np.exp(-dt / model.warmup_tau_s),
                                        model.scale_warmup / model.warmup_tau_s)
    s = model.scale_of(poses.t)
    bias = model.drift + 2 * np.multiply.outer(dt, model.drift2)
    return poses.u * rate / s + model.k * s * bias


def scale_wander(poses: Poses, model: TriadModel, alpha: float) -> ScaleWander | None:
    """The scale wander of the run from the poses' slopes (the module's fit and test), or
    None when the poses cannot show it (no slopes, no time order, too few usable poses)."""
    if poses.slope is None or poses.slope_u is None or not poses.ordered:
        return None
    r = poses.slope - model_slopes(model, poses)
    ok = np.isfinite(r) & np.isfinite(poses.slope_u) & (poses.slope_u > 0)
    n_min = int(ok.sum(0).min())
    m = min(MAX_TERMS, n_min - 2 - MIN_RESIDUAL_DOF)
    if m < 1 or np.ptp(poses.t) <= 0:
        return None
    half = np.ptp(poses.t) / 2
    tau = (poses.t - poses.t.min()) / half - 1.0
    powers = np.vander(tau, m, increasing=True)  # (N, M): τ^j
    chi0 = chi1 = 0.0
    dof = 0
    for a in range(3):
        w = 1.0 / poses.slope_u[ok[:, a], a]
        y = r[ok[:, a], a] * w
        base = model.k[a] * np.column_stack([np.ones(ok[:, a].sum()), tau[ok[:, a]]])
        scale = poses.u[ok[:, a], a, None] * powers[ok[:, a]]
        X0 = base * w[:, None]
        X1 = np.hstack([X0, scale * w[:, None]])
        e0 = y - X0 @ np.linalg.lstsq(X0, y, rcond=None)[0]
        e1 = y - X1 @ np.linalg.lstsq(X1, y, rcond=None)[0]
        chi0 += float(e0 @ e0)
        chi1 += float(e1 @ e1)
        dof += len(y) - X1.shape[1]
    f = ((chi0 - chi1) / (3 * m)) / max(chi1 / dof, 1e-300)
    p = float(special.fdtrc(3 * m, dof, max(f, 0.0)))
    if p >= alpha:
        return ScaleWander(p, False, m)
    return ScaleWander(p, True, m, *wander_path(poses, model))


LENGTHS = np.geomspace(0.05, 1.0, 9)
"""The wander path's correlation times tried, as fractions of the run (ML among them)."""


def _kernels(t: np.ndarray, s: np.ndarray, ell: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A squared-exponential path ε of unit variance and correlation time ``ell`` [s]:
    Cov(ε(t), ε(s)), Cov(ε(t), ε̇(s)) [1/s] and Cov(ε̇(t), ε̇(s)) [1/s²] (its derivatives)."""
    d = np.subtract.outer(t, s)
    e = np.exp(-0.5 * (d / ell) ** 2)
    return e, d / ell**2 * e, (1.0 - (d / ell) ** 2) / ell**2 * e


VARIANCES = np.geomspace(1e-12, 1e-6, 25)
"""The path's variances tried [1] (its standard deviation 1 to 1000 ppm)."""


def wander_path(poses: Poses, model: TriadModel) -> tuple[np.ndarray, np.ndarray]:
    """The scale's relative change at each pose from its value at the model's ``t_ref``,
    ε_pa (N, 3) [1], and its covariance (3N, 3N) in the order 3p + a, from the slopes.

    Per axis a Gaussian process: ε_a smooth (squared exponential), observed through its rate
    in each pose's slope, u_pa ε̇_a(t_p), beside a bias rate k_a (β₀ + β₁ τ_p) of flat prior
    (projected out: universal kriging). Its variance (per axis, :data:`VARIANCES`) and
    correlation time (shared, :data:`LENGTHS` of the run) are not fixed at their best fit but
    averaged over, weighted by their likelihood (flat priors in their logarithms): a few
    poses' rates leave both uncertain (synth's cycles, 20 seeds: the parameters' |err|/u RMS
    0.63 so, 0.52 at the best fit alone). Hand-
    written: a GP with derivative observations and a fixed-effect mean is a few lines of
    numpy; scikit-learn's GaussianProcessRegressor takes neither."""
    r = poses.slope - model_slopes(model, poses)
    ok = np.isfinite(r) & np.isfinite(poses.slope_u) & (poses.slope_u > 0)
    t = poses.t
    n = len(t)
    span = max(float(np.ptp(t)), 1e-9)
    tau = (t - t.min()) / span
    tt = np.r_[t, model.t_ref]
    means, covs, logl = [], [], []
    for ell in LENGTHS * span:
        kz, kzd, kdd = _kernels(tt, tt, ell)
        mean = np.zeros((n, 3))
        cov = np.zeros((3 * n, 3 * n))
        total = 0.0
        for a in range(3):
            o = ok[:, a]
            y, D = r[o, a], poses.u[o, a]
            B = model.k[a] * np.column_stack([np.ones(o.sum()), tau[o]])
            Q = np.linalg.svd(B, full_matrices=True)[0][:, 2:]
            S = Q.T @ (D[:, None] * kdd[:n, :n][np.ix_(o, o)] * D[None, :]) @ Q
            N = Q.T @ np.diag(poses.slope_u[o, a] ** 2) @ Q
            yq = Q.T @ y
            # z_p = ε(t_p) − ε(t_ref): its covariance with the observed rates, with itself.
            czy = (kzd[:n, :n][:, o] - kzd[n, :n][o][None, :]) * D[None, :] @ Q
            czz = kz[:n, :n] - kz[:n, n][:, None] - kz[n, :n][None, :] + kz[n, n]
            ms, cs, ls = [], [], []
            for v in VARIANCES:
                L = np.linalg.cholesky(v * S + N)
                zy = np.linalg.solve(L, yq)
                G = np.linalg.solve(L, (v * czy).T)  # L⁻¹ C_yz
                ls.append(-0.5 * float(zy @ zy) - float(np.sum(np.log(np.diag(L)))))
                ms.append(G.T @ zy)
                cs.append(v * czz - G.T @ G)
            m_a, c_a, l_a = _mixture(np.array(ms), np.array(cs), np.array(ls))
            mean[:, a] = m_a
            idx = 3 * np.arange(n) + a
            cov[np.ix_(idx, idx)] = c_a
            total += l_a
        means.append(mean.ravel())
        covs.append(cov)
        logl.append(total)
    m, c, _ = _mixture(np.array(means), np.array(covs), np.array(logl))
    return m.reshape(n, 3), c


def _mixture(means: np.ndarray, covs: np.ndarray, logl: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, float]:
    """Moments of a mixture weighted by exp(logl) (the law of total variance), and the log
    of its mean likelihood."""
    top = float(np.max(logl))
    w = np.exp(logl - top)
    w = w / w.sum()
    m = w @ means
    d = means - m
    c = np.einsum("i,ijk->jk", w, covs) + (d * w[:, None]).T @ d
    return m, c, top + float(np.log(np.mean(np.exp(logl - top))))


def corrected_poses(poses: Poses, w: ScaleWander) -> Poses:
    """The poses' readings taken back to the scale at ``t_ref``: u_pa / (1 + ε̂_pa) (the
    scale multiplies the whole reading, bias included: u = k s (x + b))."""
    return replace(poses, u=poses.u / (1.0 + w.path))


def wander_reason(w: ScaleWander) -> str:
    """Why the ``scale_stability`` term is there when the data set it."""
    d = w.to_dict()
    per = ", ".join(f"{ax} ±{v:.3g}" for ax, v in zip(AXES, d["range_ppm"], strict=True))
    return (f"the poses' trends show the scale factors wandering over the run (p = {w.p:.2g}): "
            f"each pose corrected by the path the within-pose slopes give ({per} ppm, u up to "
            f"{d['u_ppm']:.3g} ppm) and refitted, the path's u carried")
