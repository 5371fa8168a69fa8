"""The lens model the mark stage fits or carries: Brown-Conrady at the image half-diagonal.

A point of the ideal (pinhole, square-pixel) image at (X, Y) [px] from the principal point is
imaged at

    x = X / R, y = Y / R, r^2 = x^2 + y^2                     (R: the image half-diagonal)
    x_d = x (1 + k1 r^2 + k2 r^4) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4) + p1 (r^2 + 2 y^2) + 2 p2 x y
    sensor = (R x_d + cx, (1 + aspect) R y_d + cy)             (relative to the image centre)

so every coefficient is dimensionless and means "displacement at the half-diagonal / R".
OpenCV's coefficients for focal length f [px] convert as k1 = k1_cv (R/f)^2, k2 = k2_cv
(R/f)^4, p = p_cv R/f; ``aspect`` = fy/fx - 1; (cx, cy) [px] is the principal point's offset
from the image centre. :data:`PARAMS` names the vector's entries in this order.

Written by hand (not cv2.undistortPoints): the stage needs the model in the half-diagonal
normalisation without a focal length, and its derivatives with respect to each coefficient.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PARAMS = ("k1", "k2", "p1", "p2", "aspect", "cx", "cy")
"""The lens vector's entries, in order (see the module docstring for their units)."""


def _distort_norm(x: np.ndarray, y: np.ndarray, lam: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    k1, k2, p1, p2 = lam[:4]
    r2 = x * x + y * y
    g = 1.0 + k1 * r2 + k2 * r2 * r2
    return (x * g + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * g + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def distort_points(q: np.ndarray, lam: Sequence[float], scale: float) -> np.ndarray:
    """Ideal points (relative to the principal point) -> sensor points (relative to the image
    centre) [px]; ``lam`` ordered as :data:`PARAMS`, ``scale`` = R [px].

    Parameters
    ----------
    q : ndarray
        (N, 2) ideal points [px].
    lam : sequence of float
        The lens vector (k1, k2, p1, p2 at the half-diagonal, dimensionless; aspect
        fy/fx - 1; principal point cx, cy [px]).
    scale : float
        R, the half-diagonal the coefficients are expressed at [px].

    Returns
    -------
    ndarray
        (N, 2) sensor points [px].
    """
    lam = np.asarray(lam, float)
    xd, yd = _distort_norm(q[:, 0] / scale, q[:, 1] / scale, lam)
    return np.column_stack([scale * xd + lam[5], (1 + lam[4]) * scale * yd + lam[6]])


def _undistort_norm(q: np.ndarray, lam: np.ndarray, scale: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`undistort_points` in the normalised coordinates (x, y) = ideal point / R."""
    xn = (q[:, 0] - lam[5]) / scale
    yn = (q[:, 1] - lam[6]) / ((1 + lam[4]) * scale)
    if not np.any(lam[:4]):
        return xn, yn
    k1, k2, p1, p2 = (float(v) for v in lam[:4])
    x, y = xn.copy(), yn.copy()
    for _ in range(30):
        # _distort_norm and its Jacobian sharing r^2 and g (same expressions, so the same
        # bits as calling it: this loop is the lens stage's inner cost).
        r2 = x * x + y * y
        g = 1.0 + k1 * r2 + k2 * r2 * r2
        ex = x * g + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xn
        ey = y * g + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - yn
        dg = k1 + 2 * k2 * r2  # d g / d (r^2)
        j11 = g + 2 * x * x * dg + 2 * p1 * y + 6 * p2 * x
        j12 = 2 * x * y * dg + 2 * p1 * x + 2 * p2 * y  # = j21
        j22 = g + 2 * y * y * dg + 6 * p1 * y + 2 * p2 * x
        det = j11 * j22 - j12 * j12
        x = x - (j22 * ex - j12 * ey) / det
        y = y - (-j12 * ex + j11 * ey) / det
        if max(np.abs(ex).max(initial=0), np.abs(ey).max(initial=0)) < 1e-14:
            break
    fx, fy = _distort_norm(x, y, lam)
    # A root on the far branch (the lens folded: the point came back through the centre, or
    # the map's Jacobian changed sign) is no undistortion.
    r2 = x * x + y * y
    g = 1.0 + k1 * r2 + k2 * r2 * r2
    bad = (np.hypot(fx - xn, fy - yn) > 1e-9) | ~np.isfinite(det) | (g <= 0) | (
        1.0 + 3 * k1 * r2 + 5 * k2 * r2 * r2 <= 0)
    x[bad] = np.nan
    y[bad] = np.nan
    return x, y


def undistort_points(q: np.ndarray, lam: Sequence[float], scale: float) -> np.ndarray:
    """Sensor points (relative to the image centre) -> ideal points (relative to the principal
    point) [px]: Newton's method on both coordinates with the analytic Jacobian (the
    tangential terms leave no closed-form inverse). Non-finite where the lens folds.

    Parameters
    ----------
    q : ndarray
        (N, 2) sensor points [px].
    lam : sequence of float
        The lens vector, as :func:`distort_points`.
    scale : float
        R [px].

    Returns
    -------
    ndarray
        (N, 2) ideal points [px] (NaN where the lens folds).
    """
    x, y = _undistort_norm(np.asarray(q, float), np.asarray(lam, float), scale)
    return np.column_stack([x, y]) * scale


def undistortion_jacobian(q: np.ndarray, lam: Sequence[float], scale: float,
                          only: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The undistorted points at ``lam`` and d(undistorted point)/d(lam_j) for every entry
    (shape (N, 2, len(PARAMS))) [px per unit]; ``only``: compute just these entries (the
    others are zero).

    Analytic, by the implicit-function theorem on D(x, y; lam) = (xn, yn)(lam): one
    undistortion, then d(x, y)/d lam = J^-1 (d(xn, yn)/d lam - dD/d lam) with J the map's
    2x2 Jacobian at the root, for all points and entries at once (it replaced central
    differences through 14 iterative undistortions; the two agree to their truncation error,
    ~1e-6 relative). Non-finite where the lens folds.
    """
    lam = np.asarray(lam, float)
    q = np.asarray(q, float)
    x, y = _undistort_norm(q, lam, scale)
    base = np.column_stack([x, y]) * scale
    k1, k2, p1, p2, a = lam[:5]
    r2 = x * x + y * y
    g = 1.0 + k1 * r2 + k2 * r2 * r2
    dg = k1 + 2 * k2 * r2  # d g / d (r^2)
    xy2 = 2 * x * y * dg + 2 * p1 * x + 2 * p2 * y
    j11 = g + 2 * x * x * dg + 2 * p1 * y + 6 * p2 * x
    j22 = g + 2 * y * y * dg + 6 * p1 * y + 2 * p2 * x
    det = j11 * j22 - xy2 * xy2
    # b[:, :, j] = d(xn, yn)/d lam_j - dD/d lam_j (normalised units per unit of lam_j).
    b = np.zeros((len(q), 2, len(PARAMS)))
    b[:, 0, 0], b[:, 1, 0] = -x * r2, -y * r2
    b[:, 0, 1], b[:, 1, 1] = -x * r2 * r2, -y * r2 * r2
    b[:, 0, 2], b[:, 1, 2] = -2 * x * y, -(r2 + 2 * y * y)
    b[:, 0, 3], b[:, 1, 3] = -(r2 + 2 * x * x), -2 * x * y
    b[:, 1, 4] = -(q[:, 1] - lam[6]) / ((1 + a) ** 2 * scale)
    b[:, 0, 5] = -1.0 / scale
    b[:, 1, 6] = -1.0 / ((1 + a) * scale)
    if only is not None:
        b[:, :, [j for j in range(len(PARAMS)) if j not in only]] = 0.0
    jac = np.empty_like(b)
    f = (scale / det)[:, None]
    jac[:, 0, :] = f * (j22[:, None] * b[:, 0, :] - xy2[:, None] * b[:, 1, :])
    jac[:, 1, :] = f * (j11[:, None] * b[:, 1, :] - xy2[:, None] * b[:, 0, :])
    return base, jac


def opencv_to_lens(camera_matrix: np.ndarray, dist: Sequence[float],
                   image_size: tuple[int, int]) -> np.ndarray:
    """An OpenCV camera (K, k1 k2 p1 p2 [k3]) as this module's lens vector (k3 dropped: the
    caller adds its effect if it matters). ``image_size`` (width, height) [px].

    Parameters
    ----------
    camera_matrix : ndarray
        OpenCV's 3 x 3 K [px].
    dist : sequence of float
        OpenCV's k1, k2, p1, p2[, k3] (normalised coordinates).
    image_size : tuple of int
        (width, height) [px].

    Returns
    -------
    ndarray
        The lens vector ordered as :data:`PARAMS` (coefficients at the half-diagonal).
    """
    w, h = image_size
    scale = float(np.hypot(w - 1, h - 1) / 2)
    fx, fy = float(camera_matrix[0, 0]), float(camera_matrix[1, 1])
    d = np.zeros(5)
    d[:min(5, len(dist))] = np.asarray(dist, float)[:5]
    a = scale / fx
    return np.array([d[0] * a**2, d[1] * a**4, d[2] * a, d[3] * a, fy / fx - 1,
                     camera_matrix[0, 2] - (w - 1) / 2, camera_matrix[1, 2] - (h - 1) / 2])
