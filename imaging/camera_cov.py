"""The joint covariance of a chessboard calibration's intrinsics (fx fy cx cy k1 k2 p1 p2 k3).

OpenCV's extended calibration states only each parameter's standard deviation, but the
parameters of one calibration are strongly correlated (k1 with k2 and k3, fx with fy): an
angle measured through the model moves with a combination of them, and adding their terms
as if independent overstates it (the real chessboard lens: a mark 190 px from the centre,
k1 100″ and k2 98″ added to 147″ where the views move it by 85″). Two estimates, as for the
per-parameter u (:mod:`imaging.camera`):

* formal: s² (JᵀJ)⁻¹ from the reprojection Jacobian at the solution (``cv2.projectPoints``
  gives it per view; the views' poses are eliminated by inverting the whole normal matrix):
  white corner noise, exact model;
* jackknife: the delete-one-view covariance, which also sees the corners' errors correlated
  within a view and the lens's departure from OpenCV's model; rank at most views − 1.

The covariance used is the smallest one at least as large as both in every direction of the
parameters (:func:`dominating`): the matrix form of the per-parameter "larger of the two",
so every angle's u is at least its formal and its jackknife u, and a direction the few views
leave unseen by the jackknife keeps its formal u.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""The parameters of a camera model's covariance, in its rows' order."""


def formal_cov(objpts: Sequence[np.ndarray], imgpts: Sequence[np.ndarray],
               K: np.ndarray, D: np.ndarray, rvecs: Sequence[np.ndarray],
               tvecs: Sequence[np.ndarray], fix_k3: bool = False, fix_aspect: bool = False
               ) -> np.ndarray:
    """s² (JᵀJ)⁻¹ of the intrinsics (:data:`INTRINSICS`; a fixed one's row and column 0).

    Parameters
    ----------
    objpts, imgpts : sequence of ndarray
        Per view the board's corners [board units] and their image [px].
    K, D : ndarray
        The calibration's camera matrix [px] and distortion (k1 k2 p1 p2 k3).
    rvecs, tvecs : sequence of ndarray
        Per view the pose found by the calibration.
    fix_k3, fix_aspect : bool
        The calibration kept k3 at 0; kept fy / fx at its start.

    Returns
    -------
    ndarray
        (9, 9) covariance [px², px, 1] in :data:`INTRINSICS`' order.
    """
    D5 = np.zeros(5)
    D5[:min(5, np.size(D))] = np.ravel(D)[:5]
    # Free intrinsics as columns of the 9 (fy tied to fx by the fixed aspect; k3 held at 0).
    M = np.eye(9)
    if fix_aspect:
        M[0, 0], M[1, 0] = 1.0, K[1, 1] / K[0, 0]
        M = np.delete(M, 1, axis=1)
    if fix_k3:
        M = M[:, :-1]
    nf, n = M.shape[1], len(objpts)
    rows, res = [], []
    for i, (o, q) in enumerate(zip(objpts, imgpts, strict=True)):
        proj, jac = cv2.projectPoints(np.asarray(o, np.float64).reshape(-1, 1, 3),
                                      rvecs[i], tvecs[i], K, D5)
        jac = np.asarray(jac)
        Ji = np.zeros((jac.shape[0], nf + 6 * n))
        # projectPoints' columns: rvec (3), tvec (3), fx fy, cx cy, the distortion (5).
        Ji[:, :nf] = jac[:, 6:15] @ M
        Ji[:, nf + 6 * i: nf + 6 * i + 6] = jac[:, :6]
        rows.append(Ji)
        res.append((np.asarray(q, np.float64).reshape(-1, 2) - proj.reshape(-1, 2)).ravel())
    J, r = np.vstack(rows), np.concatenate(res)
    s2 = float(r @ r) / max(len(r) - J.shape[1], 1)
    cov_free = s2 * np.linalg.pinv(J.T @ J)[:nf, :nf]
    c = M @ cov_free @ M.T
    return 0.5 * (c + c.T)


def jackknife_cov(estimates: np.ndarray) -> np.ndarray:
    """Delete-one covariance (n−1)/n Σ (θ₋ᵢ − θ̄)(θ₋ᵢ − θ̄)ᵀ of ``estimates`` (n, p)."""
    n = len(estimates)
    d = estimates - estimates.mean(axis=0)
    c = (n - 1) / n * d.T @ d
    return 0.5 * (c + c.T)


def dominating(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The covariance at least as large as both ``a`` and ``b`` in every direction of ``a``'s
    range, equal to the larger one along each generalised eigen-direction of the pair (what
    ``b`` holds outside that range, a parameter the calibration fixed, is left out).

    By hand: a matrix "max" of two covariances is no library function. Worked on the
    correlation scale of ``a`` (the intrinsics' units span 1e-4 to 1e2)."""
    d = np.sqrt(np.clip(np.diag(a), 0.0, None))
    free = np.flatnonzero(d > 0)
    out = np.zeros_like(a)
    if not free.size:
        return out
    F = np.ix_(free, free)
    S = 1.0 / np.outer(d[free], d[free])
    s, U = np.linalg.eigh(a[F] * S)
    keep = s > 1e-10 * s.max()
    W = U[:, keep] / np.sqrt(s[keep])          # whitens a on its range
    w, V = np.linalg.eigh(W.T @ (b[F] * S) @ W)
    T = U[:, keep] * np.sqrt(s[keep]) @ V      # back from the whitened directions
    out[F] = (T * np.maximum(w, 1.0)) @ T.T / S
    return 0.5 * (out + out.T)
