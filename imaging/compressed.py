"""A least-squares problem as Levenberg–Marquardt and trust-region solvers see it, in
n_params + 1 rows instead of n residuals.

scipy's ``least_squares`` reads the residuals r (n) and their Jacobian J (n x p) only
through |r|, J^T J and J^T r (and, in its trust-region steps, the SVD or QR of J). With
J = Q R, the problem f = (Q^T r, |r - Q Q^T r|), Jacobian (R; 0) has the same |f|, the same
J^T J = R^T R and J^T f = R^T Q^T r = J^T r: the same steps and stops, to rounding, without
the solver's own factorisations of an n x p matrix every step (most of a fit's CPU when the
model is cheap and n is thousands).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg


def compressed(r: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The compressed residuals (p + 1,) and Jacobian (p + 1, p) of residuals ``r`` (n,) and
    Jacobian ``J`` (n, p) (see the module).

    R from the Cholesky factor of J^T J (J^T J = R^T R, R upper) and Q^T r = R^-T J^T r;
    J's QR where J^T J is not positive definite (a rank-deficient J: MINPACK's own case).
    """
    try:
        R = linalg.cholesky(J.T @ J)  # upper
        qtr = linalg.solve_triangular(R, J.T @ r, trans="T")
    except linalg.LinAlgError:
        Q, R = np.linalg.qr(J)
        qtr = Q.T @ r
    rest = np.sqrt(max(float(r @ r) - float(qtr @ qtr), 0.0))
    return np.append(qtr, rest), np.vstack([R, np.zeros((1, J.shape[1]))])
