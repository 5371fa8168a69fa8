"""Whether a chessboard calibration's views determine k3: the lens model the data support.

OpenCV frees k1, k2, p1, p2 and k3 by default. With a few views over a frame the boards do
not reach the corners, k3's r⁶ is nearly k1's r² and k2's r⁴ over the field they cover, and
the three are strongly correlated (k2, k3 −0.97 on the real chessboard's 7 views): a free k3
buys no fit and its wandering inflates k1's and k2's u. ``align camera`` fits both models
and keeps k3 only when the views determine it (:func:`choose_k3`): the reprojection's
improvement is significant against its noise (F-test, formal: white corner noise) *and*
k3's estimate is beyond its u (the larger of the formal and the delete-one-view jackknife u,
which sees the corners' errors correlated within a view).

A k3 left out is not taken as known to be 0: what it could do is carried in the model's
covariance as one named rank-one term, ``k3_left_out`` (:func:`left_out_term`), the change
of every intrinsic along k3's profile (the free fit's regression of each on k3: k1, k2, the
principal point, f absorb part of a k3 over the boards' field) over the k3 estimate's range
(the estimate and its u in quadrature, as the lens loop's ``lens_<p>_small``); every angle
measured through the model carries its part (:mod:`align.camera_model_u`).
"""

from __future__ import annotations

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

K3 = 8
"""k3's row in the intrinsics' covariance (:data:`imaging.camera_cov.INTRINSICS`)."""

K3_ALPHA = 0.01
"""Significance at which the views determine k3 (both tests). Leaving out a k3 the views do
determine costs the angles nothing overconfident (its range is carried in u), keeping one
they do not determine costs every angle's u its wandering: 1 % errs towards keeping it."""


def choose_k3(rms_free: float, rms_fixed: float, points: int, params_free: int,
              k3: float, u_k3: float, alpha: float = K3_ALPHA) -> dict:
    """Whether the views determine k3, and why (the record ``align camera`` saves as
    ``lens_choice``).

    Parameters
    ----------
    rms_free, rms_fixed : float
        RMS reprojection error [px] with k3 free and with k3 at 0 (OpenCV's: the root of the
        sum of squared corner errors over the corners).
    points : int
        Corners over all views.
    params_free : int
        Parameters of the free fit (intrinsics and six per view).
    k3, u_k3 : float
        The free fit's k3 and its standard uncertainty (larger of formal and jackknife).
    alpha : float
        Significance of both tests.

    Returns
    -------
    dict
        ``k3`` ("fitted" or "left out"), ``F``, ``p_F`` (the F-test of the fit's
        improvement: 1 and 2·points − params_free degrees of freedom), ``k3_estimate``,
        ``u_k3``, ``z_k3`` (the estimate over its u), ``alpha``, both RMS and ``why``.
    """
    dof = max(2 * points - params_free, 1)
    ss_free, ss_fixed = rms_free**2 * points, rms_fixed**2 * points
    F = max(ss_fixed - ss_free, 0.0) / max(ss_free / dof, 1e-300)
    p = float(special.fdtrc(1, dof, F))
    z = abs(k3) / u_k3 if u_k3 > 0 else float("inf")
    z_crit = float(-special.ndtri(alpha / 2))
    keep = p < alpha and z > z_crit
    if keep:
        why = (f"the views determine k3: the fit improves by F = {F:.3g} (p = {p:.2g}) and "
               f"k3 {k3:+.4g} is {z:.1f} u from 0")
    else:
        fails = ([f"the fit improves only by F = {F:.3g} (p = {p:.2g} >= {alpha:g})"]
                 if p >= alpha else []) + (
            [f"k3 {k3:+.4g} ± {u_k3:.3g} is {z:.1f} u from 0 (< {z_crit:.2f})"]
            if z <= z_crit else [])
        why = ("the views do not determine k3 (" + "; ".join(fails) + "): k3 is left out "
               "and its range carried in the covariance (k3_left_out)")
    return {"k3": "fitted" if keep else "left out", "F": float(F), "p_F": p,
            "k3_estimate": float(k3), "u_k3": float(u_k3), "z_k3": float(z),
            "alpha": alpha, "rms_px_free": float(rms_free), "rms_px_fixed": float(rms_fixed),
            "why": why}


def left_out_term(cov_free: np.ndarray, k3: float, u_k3: float) -> tuple[np.ndarray, float]:
    """The direction and size of a left-out k3's term: ``w`` (the change of each intrinsic
    per unit of k3 along its profile, from the free fit's covariance: cov[:, k3] / var k3,
    1 at k3) and ``s`` (k3's range: the estimate and its u in quadrature). The term added to
    the fixed model's covariance is s² w wᵀ."""
    var = float(cov_free[K3, K3])
    if var > 0:
        w = cov_free[:, K3] / var
    else:  # (no covariance of k3: the others' profile unknown, k3 alone)
        w = np.zeros(len(cov_free))
        w[K3] = 1.0
    return w, float(np.hypot(k3, u_k3))
