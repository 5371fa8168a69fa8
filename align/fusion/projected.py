"""Extra columns tested against a fitted model: what they explain of its whitened residual
beyond the model's own parameters (the leave-one-source-out E of
:mod:`align.fusion.diagnosis`, the pose pairs' common shift of :mod:`align.fusion.pairs`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ExtraFit:
    """The extra columns fitted to the residual after projecting the model's span off them.

    Attributes
    ----------
    coef : numpy.ndarray
        The columns' coefficients with r ≈ A coef (in the columns' units).
    cov : numpy.ndarray
        Their covariance (whitened residual: unit variance).
    drop : float
        The fall in χ² they allow — dimensionless.
    dof : int
        The rank of what the model leaves of the columns — dimensionless.
    own : numpy.ndarray
        Per column, whether it lies in that rank's row space (its coefficient is determined
        by the data; the others are said by the test, not by a value).
    """

    coef: np.ndarray
    cov: np.ndarray
    drop: float
    dof: int
    own: np.ndarray


def model_span(J: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the model's Jacobian ``J``'s column space."""
    U, s, _ = np.linalg.svd(J, full_matrices=False)
    return U[:, s > 1e-10 * s[0]]


def extra_fit(r: np.ndarray, Q: np.ndarray, A: np.ndarray, scale: float) -> ExtraFit | None:
    """The columns ``A`` fitted to the whitened residual ``r`` once the model's span ``Q``
    (:func:`model_span`) is projected off them; singular values below 1e-8 ``scale`` (the
    columns' size) are none. None when nothing of ``A`` is left."""
    B = A - Q @ (Q.T @ A)
    Ub, sb, Vt = np.linalg.svd(B, full_matrices=False)
    keep = sb > 1e-8 * max(scale, 1e-300)
    k = int(keep.sum())
    if k == 0:
        return None
    Ub, sb, Vt = Ub[:, keep], sb[keep], Vt[keep]
    proj = Ub.T @ r
    return ExtraFit(Vt.T @ (proj / sb), Vt.T @ np.diag(1 / sb**2) @ Vt, float(proj @ proj), k,
                    np.sum(Vt**2, axis=0) > 0.99)
