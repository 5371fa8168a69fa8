"""Relative orientation of two calibrated triads that saw the same static poses.

Each triad's ellipsoid calibration gives specific force in its own floating "convenient"
frame; gravity seen by both in the same pose is one vector in two frames. The rotation that
carries triad B's frame onto A's is Wahba's problem (scipy's ``Rotation.align_vectors``) over
the unit gravity directions; its covariance is scipy's sensitivity matrix times the variance of
one direction component — known from the pose means' standard errors, or estimated from the
residual (2 N - 3 degrees of freedom) when not. Putting both in one frame is exactly what the
seed paper says its method cannot do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.spatial.transform import Rotation

from align.calibration import Poses, StaticSettings, TriadModel, find_static


@dataclass(frozen=True)
class RelativeOrientation:
    """B -> A rotation; ``rotvec`` [rad] and its 3x3 covariance [rad^2] (a small rotation of
    frame A); per-pose residual angles [rad] before (frames taken as one) and after; the
    direction noise used [rad] and whether it was measured (``sigma_known``); chi2/dof and
    its p-value against that noise (None when the noise was estimated from the residual);
    ``inflation``: sqrt(chi2/dof) applied to ``cov`` when the residual is significantly above
    the stated noise (p < 1e-3) — the disagreement is then part of the uncertainty."""

    rotation: Rotation
    rotvec: np.ndarray
    cov: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray
    sigma_rad: float
    sigma_known: bool
    chi2_dof: float | None
    p_value: float | None
    inflation: float = 1.0

    @property
    def angle_rad(self) -> float:
        return float(np.linalg.norm(self.rotvec))

    @property
    def u_rad(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))


def relative_orientation(a: np.ndarray, b: np.ndarray,
                         sigma: np.ndarray | None = None) -> RelativeOrientation:
    """Rotation taking triad B's frame to triad A's from per-pose specific forces.

    Parameters
    ----------
    a, b : (N, 3) specific force [g] of the same N static poses in frames A and B.
    sigma : (N,) standard uncertainty of each pose's gravity direction per tangential
        component [rad] (both triads combined), or None to estimate one common value from the
        residual.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3 or len(a) < 3:
        raise ValueError("need the same >= 3 poses from both triads as (N, 3) arrays")
    ua = a / np.linalg.norm(a, axis=1, keepdims=True)
    ub = b / np.linalg.norm(b, axis=1, keepdims=True)
    w = None if sigma is None else 1 / np.square(sigma)
    rot, _, sens = Rotation.align_vectors(ua, ub, weights=w, return_sensitivity=True)
    after = np.linalg.norm(ua - rot.apply(ub), axis=1)
    before = np.linalg.norm(ua - ub, axis=1)
    dof = 2 * len(a) - 3
    if sigma is None:
        s2 = float(np.sum(after**2) / dof)
        cov = sens * s2
        return RelativeOrientation(rot, rot.as_rotvec(), cov, before, after, float(np.sqrt(s2)),
                                   False, None, None)
    # align_vectors normalises the weights' harmonic mean; scale back to variances.
    hm = len(sigma) / np.sum(1 / np.square(sigma))
    chi2 = float(np.sum(after**2 / np.square(sigma)))
    p = float(special.chdtrc(dof, chi2))
    inflation = float(np.sqrt(chi2 / dof)) if p < 1e-3 and chi2 > dof else 1.0
    cov = sens * hm * inflation**2
    return RelativeOrientation(rot, rot.as_rotvec(), cov, before, after,
                               float(np.sqrt(hm)), True, chi2 / dof, p, inflation)


def shared_poses(t: np.ndarray, u_a: np.ndarray, u_b: np.ndarray, settings: StaticSettings
                 ) -> tuple[Poses, Poses]:
    """Per-pose means of two triads recorded on one clock, over the same static intervals
    (found once over all six channels, so both see exactly the same placements)."""
    iv = find_static(t, np.hstack([u_a, u_b]), settings)
    out = []
    for cols in (slice(0, 3), slice(3, 6)):
        out.append(Poses(np.array([x.mean[cols] for x in iv]),
                         np.array([(x.start_s + x.end_s) / 2 for x in iv]), None,
                         np.array([x.sem[cols] for x in iv]), np.array([x.samples for x in iv]),
                         tuple(f"static@{x.start_s:.1f}s" for x in iv)))
    return out[0], out[1]


def calibrated_directions(model: TriadModel, poses: Poses) -> tuple[np.ndarray, np.ndarray]:
    """Specific force per pose [g] through a calibration, and the standard uncertainty of its
    direction per tangential component [rad] from the pose means' standard errors."""
    a = model.specific_force(poses.u, poses.t, poses.temp)
    if poses.sigma_u is None:
        raise ValueError("pose standard errors unknown (per-pose means only)")
    return a, np.linalg.norm(poses.sigma_u / np.abs(model.k), axis=1) / np.sqrt(3)
