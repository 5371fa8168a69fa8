"""Weighted orthogonal line fit to points, with optional extra model terms.

Residual of point k (perpendicular distance, px):

    r_k = n(a) . q_k - d - sum_j beta_j F_kj

with n(a) = (sin a, cos a) in (x right, y down) coordinates relative to the image centre.
Extra columns F describe effects the residual loop adds (curvature, a periodic wiggle, ...).
Solved by Gauss–Newton from the weighted total-least-squares line; the covariance of
(a, d, beta) is (J^T W J)^-1 with the points' own standard uncertainties, i.e. propagated,
not a residual RMS. Outliers (dust, scratches) are rejected at ``reject_sigma`` and the fit
repeated. When the points' errors are correlated (surface texture along a mark), the fit is
generalised least squares with their correlation matrix R = L L^T: every column and the
residual are whitened by L^-1 (so the covariance is (J^T C^-1 J)^-1 and the whitened
residuals are independent unit-variance noise under the model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular

from imaging.detect import line_frame, wrap_angle


@dataclass(frozen=True)
class LineFit:
    """Result of :func:`fit_line`.

    ``angle_rad``, ``offset_px``: line; ``cov``: covariance of (angle, offset, beta...);
    ``beta``: coefficients of the extra columns; ``residuals_px``/``t_px``/``sigma_px``: per
    used point (perpendicular residual, position along the line, standard uncertainty);
    ``used``: mask over the input points; ``chi2``/``dof``; ``z``: the residuals whitened
    by the points' correlation and divided by their sigma (independent N(0, 1) under the
    model; residual / sigma when the points are independent).

    Attributes
    ----------
    angle_rad : float
        Direction of the line [rad].
    offset_px : float
        Signed distance from the origin [px].
    cov : ndarray
        Covariance of (angle [rad], offset [px], beta...).
    beta : ndarray
        Coefficients of the extra columns (their units over px).
    residuals_px : ndarray
        Perpendicular residual of each used point [px].
    t_px : ndarray
        Position of each used point along the line [px].
    sigma_px : ndarray
        Standard uncertainty of each used point [px].
    used : ndarray
        Boolean mask over the input points.
    chi2 : float
        Chi-square of the fit.
    dof : int
        Its degrees of freedom.
    z : ndarray or None
        Whitened, normalised residuals (dimensionless).
    """

    angle_rad: float
    offset_px: float
    cov: np.ndarray
    beta: np.ndarray
    residuals_px: np.ndarray
    t_px: np.ndarray
    sigma_px: np.ndarray
    used: np.ndarray
    chi2: float
    dof: int
    z: np.ndarray | None = None

    @property
    def angle_u_rad(self) -> float:
        return float(np.sqrt(self.cov[0, 0]))

    @property
    def offset_u_px(self) -> float:
        return float(np.sqrt(self.cov[1, 1]))

    @property
    def length_px(self) -> float:
        return float(np.ptp(self.t_px)) if self.t_px.size else 0.0


def _tls(q: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    m = (w[:, None] * q).sum(0) / w.sum()
    c = ((q - m) * w[:, None]).T @ (q - m)
    _, v = np.linalg.eigh(c)
    u = v[:, 1]
    a = wrap_angle(np.arctan2(-u[1], u[0]))
    return a, float(m @ line_frame(a)[1])


def _solve(q, sigma, F, a, d, iters=4, chol=None, want_cov=True):
    """Gauss–Newton for (a, d, beta). Every column is linear in the points, so it is
    whitened once: W(X) = L^-1 (X / sigma) (L = identity for independent points).
    ``want_cov`` False: (a, d, beta) only (the same bits; no covariance or residuals)."""
    m = F.shape[1]
    X = np.column_stack([q, np.ones(len(q)), F]) / sigma[:, None]
    if chol is not None:
        X = solve_triangular(chol, X, lower=True, check_finite=False)
    qw, one, Fw = X[:, :2], X[:, 2], X[:, 3:]
    beta = np.zeros(m)
    for _ in range(iters):
        u, n = line_frame(a)
        r = qw @ n - d * one - Fw @ beta
        J = np.column_stack([qw @ u, -one, -Fw])
        step = np.linalg.lstsq(J.T @ J, -(J.T @ r), rcond=None)[0]
        a, d, beta = a + step[0], d + step[1], beta + step[2:]
        if m == 0 and abs(step[0]) < 1e-14 and abs(step[1]) < 1e-11:
            # A bare line from its weighted-TLS start (already the optimum for independent
            # points) moves by rounding only; the lens solver fits ~10 lines per mark.
            break
    if not want_cov:
        return a, d, beta
    u, n = line_frame(a)
    J = np.column_stack([qw @ u, -one, -Fw])
    cov = np.linalg.pinv(J.T @ J)
    if np.any(np.diag(cov) < 0):
        # J^T J squares J's condition: on a noise-free frame (sigma ~1e-4 px, a bow's t^2
        # column ~1e4) its pseudo-inverse lost a variance's sign (sqrt of a negative in the
        # loop). From J's own QR factor R the covariance R^-1 R^-T has row norms squared on
        # its diagonal: never negative.
        r_inv = solve_triangular(np.linalg.qr(J, mode="r"), np.eye(J.shape[1]),
                                 check_finite=False)
        cov = r_inv @ r_inv.T
    return a, d, beta, q @ n - d - F @ beta, cov, qw @ n - d * one - Fw @ beta


def fit_line(points: np.ndarray, sigma: np.ndarray, extra: np.ndarray | None = None,
             reject_sigma: float | None = 4.5, max_rounds: int = 6,
             chol: np.ndarray | None = None) -> LineFit:
    """Fit a line (plus extra columns) to points with perpendicular uncertainties.

    Parameters
    ----------
    points : (N, 2) array
        Points [px], relative to the image centre, x right, y down.
    sigma : (N,) array
        Standard uncertainty of each point across the line [px].
    extra : (N, m) array, optional
        Extra design columns (effects); their coefficients are returned in ``beta``.
    reject_sigma : float or None
        Reject points whose normalised residual exceeds this, then refit (None: keep all).
    chol : (N, N) array, optional
        Lower Cholesky factor of the points' correlation matrix (generalised least squares);
        every point is then kept (``reject_sigma`` must be None).
    max_rounds : int
        Most rounds of rejection and refit.

    Returns
    -------
    LineFit
        The line, its covariance and the residuals.
    """
    q = np.asarray(points, float)
    sigma = np.asarray(sigma, float)
    F = np.zeros((len(q), 0)) if extra is None else np.asarray(extra, float).reshape(len(q), -1)
    used = np.isfinite(sigma) & np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(F), axis=1)
    if used.sum() < 3 + F.shape[1]:
        raise ValueError("too few points for a line fit")
    if chol is not None and (reject_sigma is not None or not used.all()):
        raise ValueError("correlated points: all must be finite and none rejected")
    for _ in range(max_rounds):
        a, d = _tls(q[used], 1 / sigma[used] ** 2)
        a, d, beta, r, cov, z = _solve(q[used], sigma[used], F[used], a, d, chol=chol)
        if reject_sigma is None:
            break
        u, n = line_frame(a)
        z_all = np.abs(q @ n - d - F @ beta) / sigma
        # Reject at the threshold but never more than a third of the points.
        limit = max(reject_sigma, np.quantile(z_all[used], 2 / 3))
        new = used & np.isfinite(z_all) & (z_all <= limit)
        if np.array_equal(new, used):
            break
        used = new
    else:
        # Rounds ran out while the set was still changing: solve once more on the final set.
        a, d = _tls(q[used], 1 / sigma[used] ** 2)
        a, d, beta, r, cov, z = _solve(q[used], sigma[used], F[used], a, d)
    u, _ = line_frame(a)
    if abs(wrap_angle(a) - a) > 1:
        # The direction turned by pi on wrapping: the normal, hence d and the residuals, flip.
        d, r, beta, u, z = -d, -r, -beta, -u, -z
        flip = np.diag([1.0, -1.0] + [-1.0] * len(beta))
        cov = flip @ cov @ flip
    return LineFit(angle_rad=wrap_angle(a), offset_px=float(d), cov=cov, beta=beta,
                   residuals_px=r, t_px=q[used] @ u, sigma_px=sigma[used], used=used,
                   chi2=float(np.sum(z**2)), dof=int(used.sum() - 2 - F.shape[1]), z=z)


def fit_line_only(points: np.ndarray, sigma: np.ndarray, chol: np.ndarray | None = None
                  ) -> tuple[float, float]:
    """The line of :func:`fit_line` with every point kept (``reject_sigma`` None, no extra
    columns): (angle [rad], offset [px]), the same bits, without the covariance and the
    residuals. The lens solver fits ~10 lines per mark for their direction alone, and the
    covariance's pseudo-inverse was a fifth of that.

    Parameters
    ----------
    points : (N, 2) array
        Points [px], relative to the image centre.
    sigma : (N,) array
        Standard uncertainty of each point across the line [px].
    chol : (N, N) array, optional
        Lower Cholesky factor of the points' correlation matrix.

    Returns
    -------
    tuple of float
        The line's angle [rad] and offset [px].
    """
    q = np.asarray(points, float)
    sigma = np.asarray(sigma, float)
    used = np.isfinite(sigma) & np.all(np.isfinite(q), axis=1)
    if used.sum() < 3:
        raise ValueError("too few points for a line fit")
    if chol is not None and not used.all():
        raise ValueError("correlated points: all must be finite and none rejected")
    a, d = _tls(q[used], 1 / sigma[used] ** 2)
    a, d, _ = _solve(q[used], sigma[used], np.zeros((int(used.sum()), 0)), a, d, chol=chol,
                     want_cov=False)
    if abs(wrap_angle(a) - a) > 1:
        d = -d  # the direction turned by pi on wrapping (as fit_line)
    return wrap_angle(a), float(d)
