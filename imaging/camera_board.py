"""Whether the chessboard was printed with an anisotropic scale: its x scale over its y, s.

A board printed 0.5 % longer along its x than its y (a printer's or plotter's feed) and
calibrated as square looks to OpenCV almost like pixels 0.5 % taller than wide: the fit
puts it into fy / fx (user 18: fy/fx − 1 = −0.0051 ± 0.0002 against a true 0, and a 20°
mark through the model 329″ off at u 16″). The two differ in which frame they live in: the
board's s turns with the board, the pixel aspect stays with the sensor. With views at
different in-plane rotations of the board they are separable; with the board always the
same way up they are not, and only the print's tolerance bounds s.

``align camera`` fits s with the intrinsics (:func:`board_scale_fit`): one Gauss-Newton
step from the calibration at the board's nominal shape, with the object points' x scaled
by 1 + s as one more column of the reprojection Jacobian (the calibration's own, from
``cv2.projectPoints``; the views' poses eliminated with the rest). Its u is the larger of
the formal u (white corner noise) and the delete-one-view jackknife of that same step (the
views' scatter: the corners' errors are correlated within a view), and s is significant
when the estimate over its u exceeds Student's t at :data:`BOARD_ALPHA` with views − 1
degrees of freedom (a likelihood-ratio test of one parameter with the noise scaled by the
views' scatter). Then (:func:`board_choice`):

* significant: named and corrected (the calibration is redone on the board scaled by s, one
  more step refines s) and s's u carried;
* not significant, its u at most the print tolerance: the nominal board stands, s's range
  (the estimate and its u in quadrature, at most the tolerance) carried;
* not significant, its u above the tolerance (the views' in-plane rotations too alike): the
  print tolerance (:data:`BOARD_TOLERANCE`, or the user's ``--board-tolerance``) carried,
  with "rotate the board between views".

What is carried is a rank-one term in the model's covariance, as a left-out k3's
(:func:`imaging.camera_k3.left_out_term`): the change of every intrinsic along s's profile
(mostly fy / fx) times s's range, so the marks measured through the model carry it.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from scipy import special

from imaging.camera_cov import INTRINSICS

BOARD_TOLERANCE = 0.001
"""The default print tolerance of a chessboard's x/y scale ratio (0.1 %: a laser print on a
good printer; a plotter or a photocopy can be worse, declare it with ``--board-tolerance``)."""

BOARD_ALPHA = 0.01
"""Significance at which the views show the board's x scale differs from its y (as k3's)."""


def scaled_board(objpts: Sequence[np.ndarray], s: float) -> list[np.ndarray]:
    """The views' object points with the board's x scaled by 1 + ``s`` (float32, as given)."""
    out = []
    for o in objpts:
        p = np.array(o, dtype=np.float64)
        p[..., 0] *= 1.0 + s
        out.append(p.astype(np.float32))
    return out


def _reduced(objpts: Sequence[np.ndarray], imgpts: Sequence[np.ndarray], K: np.ndarray,
             D: np.ndarray, rvecs: Sequence[np.ndarray], tvecs: Sequence[np.ndarray],
             M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Per view the normal equations of the free intrinsics (``M``: :data:`INTRINSICS` per
    free one, as :func:`imaging.camera_cov.formal_cov`'s) and s, its pose eliminated (Schur
    complement): (N (n, p, p), b (n, p), the residuals' sum of squares per view (n,) [px²],
    the rows). s's column is d proj / d s = d proj / d X · X (central difference)."""
    D5 = np.zeros(5)
    D5[:min(5, np.size(D))] = np.ravel(D)[:5]
    Ns, bs, rr, rows = [], [], [], 0
    h = 1e-6
    for o, q, rv, tv in zip(objpts, imgpts, rvecs, tvecs, strict=True):
        o = np.asarray(o, np.float64).reshape(-1, 1, 3)
        proj, jac = cv2.projectPoints(o, rv, tv, K, D5)
        jac = np.asarray(jac)
        pm = [cv2.projectPoints(o * np.array([1.0 + e, 1.0, 1.0]), rv, tv, K, D5)[0].ravel()
              for e in (h, -h)]
        G = np.column_stack([jac[:, 6:15] @ M, (pm[0] - pm[1]) / (2 * h)])
        P = jac[:, :6]
        r = (np.asarray(q, np.float64).reshape(-1, 2) - proj.reshape(-1, 2)).ravel()
        # the pose's least squares taken out of the intrinsics' columns and the residuals
        Q = np.linalg.solve(P.T @ P, P.T @ np.column_stack([G, r]))
        Gp, rp = G - P @ Q[:, :-1], r - P @ Q[:, -1]
        Ns.append(Gp.T @ Gp)
        bs.append(Gp.T @ rp)
        rr.append(float(r @ r))
        rows += len(r)
    return np.array(Ns), np.array(bs), np.array(rr), rows


def _step(N: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton step and the unscaled covariance N⁻¹ (on the diagonal's scale: the
    columns span px to 1e-4)."""
    d = np.sqrt(np.clip(np.diag(N), 1e-300, None))
    C = np.linalg.pinv(N / np.outer(d, d)) / np.outer(d, d)
    return C @ b, C


def board_scale_fit(objpts: Sequence[np.ndarray], imgpts: Sequence[np.ndarray],
                    K: np.ndarray, D: np.ndarray, rvecs: Sequence[np.ndarray],
                    tvecs: Sequence[np.ndarray], fix_k3: bool = False,
                    fix_aspect: bool = False) -> dict:
    """The board's x/y scale s − 1 fitted with the intrinsics, from a calibration on the
    board as given (its K, D, poses).

    Returns
    -------
    dict
        ``s`` (the step's estimate, relative to the board given), ``u_formal``,
        ``u_jackknife`` (None below 3 views), ``u`` (the larger), ``dof`` (views − 1),
        ``profile`` (the change of each of :data:`INTRINSICS` per unit of s along its
        profile: the fit's regression of each on s; [px], 1).
    """
    M = np.eye(len(INTRINSICS))
    if fix_aspect:  # fy held at its ratio to fx
        M[0, 0], M[1, 0] = 1.0, K[1, 1] / K[0, 0]
        M = np.delete(M, 1, axis=1)
    if fix_k3:
        M = M[:, :-1]
    Ns, bs, rr, rows = _reduced(objpts, imgpts, K, D, rvecs, tvecs, M)
    n, nf = len(objpts), M.shape[1]
    delta, C = _step(Ns.sum(0), bs.sum(0))
    s2 = float(rr.sum()) / max(rows - (nf + 1 + 6 * n), 1)
    u_formal = float(np.sqrt(s2 * C[-1, -1]))
    profile = M @ (C[:nf, -1] / C[-1, -1]) if C[-1, -1] > 0 else np.zeros(len(INTRINSICS))
    u_jack = None
    if n >= 3:  # the same step without each view in turn
        est = np.array([_step(Ns.sum(0) - Ns[i], bs.sum(0) - bs[i])[0][-1] for i in range(n)])
        u_jack = float(np.sqrt((n - 1) / n * np.sum((est - est.mean())**2)))
    return {"s": float(delta[-1]), "u_formal": u_formal, "u_jackknife": u_jack,
            "u": float(max(u_formal, u_jack or 0.0)), "dof": max(n - 1, 1),
            "profile": profile.tolist()}


def board_choice(fit: dict, s_total: float, applied: bool, tolerance: float = BOARD_TOLERANCE,
                 alpha: float = BOARD_ALPHA) -> dict:
    """What ``align camera`` does with the board's fitted scale (the record it saves as
    ``board_scale``).

    Parameters
    ----------
    fit : dict
        :func:`board_scale_fit` on the board as given.
    s_total : float
        The estimate of s relative to the nominal (square) board.
    applied : bool
        The calibration is on the board scaled by s_total (:func:`significant`).
    tolerance : float
        The board's print tolerance of its x/y scale ratio (1: 0.001 is 0.1 %).
    alpha : float
        Significance.

    Returns
    -------
    dict
        ``board`` ("corrected", "nominal" or "not separable"), ``s``, ``u_s``, ``z``,
        ``t_crit``, ``alpha``, ``tolerance``, ``carried_s`` (the range carried along
        ``carried_direction``, per :data:`INTRINSICS`) and ``why``.
    """
    u = fit["u"]
    z = abs(s_total) / u if u > 0 else float("inf")
    t_crit = float(special.stdtrit(fit["dof"], 1 - alpha / 2))
    pct = 100 * s_total
    if applied:
        board = "corrected"
        carried = float(u)
        why = (f"the board's x scale differs from its y by {pct:+.2f} ± {100 * u:.2f} % "
               f"({z:.1f} u; a print error): corrected")
    elif u > tolerance:
        board = "not separable"
        carried = float(tolerance)
        why = (f"the views do not separate the board's x/y scale from the pixels' aspect "
               f"(s = {pct:+.2f} ± {100 * u:.2f} %, u above the print tolerance "
               f"{100 * tolerance:.2g} %: the board's in-plane rotations too alike): the print "
               f"tolerance is carried in fy/fx's u (board_print); rotate the board between "
               f"views (by 30-90° about its normal) or declare the board's tolerance")
    else:
        board = "nominal"
        carried = float(min(np.hypot(s_total, u), tolerance))
        why = (f"the board's x/y scale {pct:+.3f} ± {100 * u:.3f} % is {z:.1f} u from square "
               f"(< {t_crit:.2f}): taken as printed square, its range (at most the print "
               f"tolerance) carried (board_print)")
    return {"board": board, "s": float(s_total), "u_s": float(u),
            "u_s_formal": float(fit["u_formal"]),
            "u_s_jackknife": None if fit["u_jackknife"] is None else float(fit["u_jackknife"]),
            "z": float(z), "t_crit": t_crit, "alpha": alpha, "tolerance": float(tolerance),
            "carried_s": carried, "carried_direction": list(fit["profile"]), "why": why}


def board_fit(objpts: Sequence[np.ndarray], imgpts: Sequence[np.ndarray], K: np.ndarray,
              D: np.ndarray, fix_k3: bool, fix_aspect: bool) -> dict:
    """:func:`board_scale_fit` at a calibration's intrinsics, each view's pose found again
    (``cv2.solvePnP``: the calibration's own pose at those intrinsics)."""
    poses = [cv2.solvePnP(o, q, K, D)[1:] for o, q in zip(objpts, imgpts, strict=True)]
    return board_scale_fit(objpts, imgpts, K, D, [p[0] for p in poses], [p[1] for p in poses],
                           fix_k3, fix_aspect)


def significant(fit: dict, alpha: float = BOARD_ALPHA) -> bool:
    """Whether the fitted s is beyond Student's t at ``alpha`` (views − 1 dof) times its u."""
    t_crit = float(special.stdtrit(fit["dof"], 1 - alpha / 2))
    return fit["u"] > 0 and abs(fit["s"]) > t_crit * fit["u"]


def carried(cov: np.ndarray, u: dict, K: np.ndarray, choice: dict) -> tuple[np.ndarray, dict]:
    """The model's covariance and u's with the board's term (``board_print``): the intrinsics'
    change along s's profile times the range carried, c² w wᵀ added to ``cov`` and each u
    (the aspect fy / fx's too) with its part in quadrature."""
    w, c = board_term(choice)
    out = {k: float(np.hypot(v, c * w[INTRINSICS.index(k)])) if k in INTRINSICS else v
           for k, v in u.items()}
    if "aspect" in out:
        fx, a = K[0, 0], K[1, 1] / K[0, 0]
        out["aspect"] = float(np.hypot(out["aspect"], c * (w[1] - a * w[0]) / fx))
    return cov + c**2 * np.outer(w, w), out


def board_term(choice: dict) -> tuple[np.ndarray, float]:
    """The direction w (per :data:`INTRINSICS`, per unit of s) and range c of the board's
    term in a model's covariance (c² w wᵀ) from its ``board_scale`` record."""
    return np.array(choice["carried_direction"], float), float(choice["carried_s"])
