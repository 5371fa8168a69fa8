"""Plumb-line estimate of radial distortion from points that should lie on straight lines.

Model: each set of points q (relative to the principal point, assumed at the image centre
unless given) is the image of a straight line through x_d = x_u (1 + k1 (r_u/R)^2 +
k2 (r_u/R)^4), R a length scale (default the image half-diagonal) so k1, k2 are
dimensionless; OpenCV's coefficients are k1 (f/R)^2 and k2 (f/R)^4 for focal length f [px].
Fitted jointly over all lines by scipy's least_squares: (k1[, k2]) and one (angle, offset)
per line, residuals the perpendicular distances of the undistorted points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from axisbase.fixedpoint import iterate_elementwise
from imaging.linefit import fit_line


@dataclass(frozen=True)
class PlumbLineFit:
    """k (k1[, k2]) at scale R with standard uncertainties, and straightness before/after.

    ``rms_before_px``/``rms_after_px``: RMS perpendicular residual of per-line straight-line
    fits to the raw and to the undistorted points [px].

    Attributes
    ----------
    k, k_u : ndarray
        k1[, k2] at scale R and their u — dimensionless.
    scale_px : float
        R [px].
    rms_before_px, rms_after_px : float
        Straightness before and after [px].
    n_lines, n_points : int
        Lines and points used.
    """

    k: np.ndarray
    k_u: np.ndarray
    scale_px: float
    rms_before_px: float
    rms_after_px: float
    n_lines: int
    n_points: int

    def opencv(self, focal_px: float) -> np.ndarray:
        """The same coefficients in OpenCV's normalised convention for focal length f [px]."""
        p = np.arange(1, len(self.k) + 1)
        return self.k * (focal_px / self.scale_px) ** (2 * p)


def undistort(q: np.ndarray, k: Sequence[float], scale: float) -> np.ndarray:
    """Invert x_d = x_u (1 + k1 (r_u/R)^2 + k2 (r_u/R)^4 ...) by Newton iteration on the
    radius (points relative to the principal point, R = ``scale``).

    Parameters
    ----------
    q : ndarray
        (N, 2) distorted points [px].
    k : sequence of float
        k1[, k2, ...] at R — dimensionless.
    scale : float
        R [px].

    Returns
    -------
    ndarray
        (N, 2) undistorted points [px].
    """
    rd = np.linalg.norm(q, axis=1) / scale

    def newton(at: np.ndarray, ru: np.ndarray) -> tuple[np.ndarray]:
        g = ru.copy()
        dg = np.ones_like(ru)
        for i, ki in enumerate(k, start=1):
            g += ki * ru ** (2 * i + 1)
            dg += (2 * i + 1) * ki * ru ** (2 * i)
        return (ru - (g - rd[at]) / dg,)

    # (25 steps at most; the points already converged to the last bit left alone)
    (ru,) = iterate_elementwise(newton, (rd,), 25)
    f = np.where(rd > 0, ru / np.where(rd > 0, rd, 1.0), 1.0)
    return q * f[:, None]


def cross_magnification(q: np.ndarray, k: Sequence[float], scale: float,
                        normal: np.ndarray) -> np.ndarray:
    """How much :func:`undistort` magnifies a small displacement of each point along
    ``normal`` (a line's unit normal), measured along that normal: n . J n with J the
    undistortion's Jacobian at the point (radial gain dr_u/dr_d, tangential r_u/r_d).

    A centre's standard uncertainty across its line is multiplied by this when the centres
    are undistorted: leaving it as it was would read points pulled together by a strong
    fitted k1 as points that fit better, and make the fit prefer k1 for that alone.

    Parameters
    ----------
    q : ndarray
        (N, 2) distorted points [px].
    k : sequence of float
        k1[, k2] at R.
    scale : float
        R [px].
    normal : ndarray
        (2,) or (N, 2) unit normal(s) of the line.

    Returns
    -------
    ndarray
        (N,) magnification along the normal — dimensionless.
    """
    q = np.asarray(q, float)
    qu = undistort(q, k, scale)
    rd = np.linalg.norm(q, axis=1)
    ru = np.linalg.norm(qu, axis=1) / scale
    tang = np.where(rd > 0, ru * scale / np.where(rd > 0, rd, 1.0), 1.0)
    dg = np.ones_like(ru)
    for i, ki in enumerate(k, start=1):
        dg += (2 * i + 1) * ki * ru ** (2 * i)
    radial = 1.0 / dg
    c2 = np.where(rd > 0, (q @ np.asarray(normal, float)) ** 2 / np.where(rd > 0, rd, 1.0) ** 2,
                  0.0)
    return radial * c2 + tang * (1.0 - c2)


def _rms_straight(lines: Sequence[np.ndarray]) -> float:
    r = [fit_line(q, np.ones(len(q)), reject_sigma=None).residuals_px for q in lines]
    return float(np.sqrt(np.mean(np.concatenate(r) ** 2)))


def plumb_line(lines: Sequence[np.ndarray], scale_px: float, n_coeffs: int = 1,
               centre: np.ndarray | None = None) -> PlumbLineFit:
    """Joint plumb-line fit.

    Parameters
    ----------
    lines : sequence of (N_i, 2) arrays
        Points of each straight feature [px], in image coordinates relative to ``centre``.
    scale_px : float
        R, the radius at which k is expressed [px].
    n_coeffs : int
        1 (k1) or 2 (k1, k2).
    centre : (2,) array, optional
        Principal point relative to the coordinates' origin [px] (default: origin).

    Returns
    -------
    PlumbLineFit
        k with u and the straightness before and after [px].
    """
    c = np.zeros(2) if centre is None else np.asarray(centre, float)
    lines = [np.asarray(q, float) - c for q in lines if len(q) >= 3]
    if len(lines) < 2:
        raise ValueError("plumb-line needs at least two lines of three or more points")
    # Variable projection: for given k every line is a closed-form TLS fit, so only k is
    # searched; the reduced Jacobian gives k's covariance with the lines profiled out.
    def resid(k):
        out = []
        for q in lines:
            u = undistort(q, k, scale_px)
            m = u.mean(0)
            _, v = np.linalg.eigh((u - m).T @ (u - m))
            out.append((u - m) @ v[:, 0])
        return np.concatenate(out)

    res = least_squares(resid, np.zeros(n_coeffs), method="lm", x_scale=[0.1] * n_coeffs)
    r = res.fun
    dof = max(len(r) - n_coeffs - 2 * len(lines), 1)
    # Plain Jacobian at the solution (no robust loss here), scaled by the residual variance.
    cov = np.linalg.pinv(res.jac.T @ res.jac) * (r @ r / dof)
    k = res.x
    return PlumbLineFit(k, np.sqrt(np.diag(cov)), scale_px, _rms_straight(lines),
                        _rms_straight([undistort(q, k, scale_px) for q in lines]), len(lines),
                        int(sum(len(q) for q in lines)))


def chessboard_lines(corners: np.ndarray, pattern: tuple[int, int]) -> list[np.ndarray]:
    """Rows and columns of chessboard inner corners (cols x rows) as point sets.

    Parameters
    ----------
    corners : ndarray
        (cols x rows, 2) corners [px] (:func:`imaging.camera.find_chessboard`).
    pattern : tuple of int
        (cols, rows).

    Returns
    -------
    list of ndarray
        One (n, 2) array [px] per row, then per column.
    """
    grid = corners.reshape(pattern[1], pattern[0], 2)
    return [grid[i] for i in range(pattern[1])] + [grid[:, j] for j in range(pattern[0])]
