"""A camera model's own uncertainty in one mark's angle: the joint covariance of its
parameters (``align camera``'s ``cov``, :mod:`imaging.camera_cov`) propagated linearly
through the angle's sensitivity to each parameter.

The sensitivity is read off the mark itself: its centres (already undistorted by the model)
are taken back to the raw image through the model, undistorted again by the model with one
parameter moved by ± its u, and the line refitted (central difference). This holds for
every parameter OpenCV fits (fx, fy, k3 too) at the model's own distortion, where the lens
vector's derivatives (the rule before camera format 4) are taken at none.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
from scipy.linalg import solve_triangular

from imaging import CameraModel, fit_line_only
from imaging.camera_cov import INTRINSICS

TERM = "camera_model"
"""The name of the calibration's joint term in a mark's u (components ``camera_model.0``,
``camera_model.1``, ... on the covariance's principal directions, shared by every mark of
the camera)."""

K3_TERM = "camera_k3_left_out"
"""A mark's term for the k3 its camera's calibration left out (the views did not determine
it): the change of the angle along k3's profile over k3's range (:mod:`imaging.camera_k3`)."""


def raw_pixels(camera: CameraModel, points: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Points undistorted by ``camera`` (relative to the image centre, square pixels of the
    column pitch: :meth:`CameraModel.undistort_centred`) back in the raw image [px]."""
    h, w = shape
    K = camera.camera_matrix
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    xy = (points + c - K[:2, 2]) / K[0, 0]  # the square pinhole's normalised coordinates
    obj = np.column_stack([xy, np.ones(len(xy))]).reshape(-1, 1, 3)
    raw, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K,
                               np.ravel(camera.dist_coeffs).astype(np.float64))
    return raw.reshape(-1, 2)


def model_cov(camera: CameraModel) -> np.ndarray:
    """The model's joint covariance (:data:`INTRINSICS`; [px², px, 1]); for a file without
    one (written elsewhere, or before camera format 4) its u's as if independent, except fx
    and fy, whose covariance makes fy / fx's u the stated ``aspect`` where the file states it
    (fx and fy of one calibration are strongly correlated: their u's as if independent turn
    a 45° mark by ~100″ the calibration does not allow).

    Every parameter enters at the model's own distortion: a principal point's u turns an
    angle only through the distortion (the lens vector's derivatives, taken at none, see no
    cx, cy and no fx: a model without cov then left 8 of 40 angles ok beyond 3 u through
    lenses drawn from its u's)."""
    if camera.cov is not None:
        return camera.cov
    u = camera.u or {}
    v = np.array([u.get(k, 0.0) for k in INTRINSICS], float)
    v = np.where(np.isfinite(v), v, 0.0)
    C = np.diag(v**2)
    if "aspect" in u and np.isfinite(u["aspect"]):
        fx, fy = float(camera.camera_matrix[0, 0]), float(camera.camera_matrix[1, 1])
        q = fy / fx
        # var(fy / fx) = (var fy + q² var fx - 2 q cov) / fx², solved for cov, within ±1.
        c = (v[1]**2 + q**2 * v[0]**2 - (fx * u["aspect"])**2) / (2 * q)
        C[0, 1] = C[1, 0] = float(np.clip(c, -v[0] * v[1], v[0] * v[1]))
    return C


def _moved(camera: CameraModel, j: int, step: float) -> CameraModel:
    """The model with intrinsic ``INTRINSICS[j]`` moved by ``step``."""
    K = camera.camera_matrix.copy()
    D = np.zeros(max(5, np.size(camera.dist_coeffs)))
    D[:np.size(camera.dist_coeffs)] = np.ravel(camera.dist_coeffs)
    if j < 4:
        K[(0, 1, 0, 1)[j], (0, 1, 2, 2)[j]] += step
    else:
        D[j - 4] += step
    return replace(camera, camera_matrix=K, dist_coeffs=D)


def angle_sensitivity(camera: CameraModel, points: np.ndarray, sigma: np.ndarray,
                      chol: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """d(angle)/d(parameter) [rad per unit of each of :data:`INTRINSICS`] of the mark whose
    centres ``points`` the model undistorted (0 for a parameter the covariance fixes).

    Each parameter moves the centres by a field (central difference at ± its u); the line's
    (generalised least-squares) angle responds to the field's component across the line
    linearly: its slope against the position along the line, fitted with the mark's weights
    and correlation (one fit of all nine fields, not a line refitted per parameter: with
    correlated centres that was 0.1 s per mark)."""
    h, w = shape
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    raw = raw_pixels(camera, points, shape) - c
    steps = np.sqrt(np.clip(np.diag(model_cov(camera)), 0.0, None))
    # The line's direction (weights alone: it only orients the fields); the angle is
    # counter-clockwise with y down, u = (cos a, -sin a), so a turn by da moves a point t
    # along the line by t da along n = du/da.
    a0 = fit_line_only(points, sigma)[0]
    u, n = np.array([np.cos(a0), -np.sin(a0)]), np.array([-np.sin(a0), -np.cos(a0)])
    fields = np.zeros((len(points), len(INTRINSICS)))
    for j, hj in enumerate(steps):
        if hj > 0:
            q = [_moved(camera, j, s * hj).undistort_centred(raw, sigma, shape)[0]
                 for s in (1.0, -1.0)]
            fields[:, j] = (q[0] - q[1]) @ n / (2 * hj)
    X = np.column_stack([points @ u, np.ones(len(points))]) / sigma[:, None]
    Y = fields / sigma[:, None]
    if chol is not None:
        X, Y = (solve_triangular(chol, M, lower=True) for M in (X, Y))
    return np.linalg.lstsq(X, Y, rcond=None)[0][0]


def model_coupling(camera: CameraModel, points: np.ndarray, sigma: np.ndarray,
                   chol: np.ndarray | None, shape: tuple[int, int]) -> dict[str, float]:
    """The mark's angle components [rad] of the camera model's joint covariance
    (:func:`model_cov`): one per principal direction of it (``camera_model.i``); their
    root sum of squares is the angle's u from the model, gᵀ C g, and their products between
    two marks the covariance the calibration puts between their angles."""
    g = angle_sensitivity(camera, points, sigma, chol, shape)
    C, out = model_cov(camera), {}
    carried = left_out_k3(camera)
    if carried is not None:
        # k3 left out by the calibration (the views do not determine it): its range along
        # its profile is in cov as s² w wᵀ; named on its own (shared by every mark of the
        # camera like the rest), the rest on cov's principal directions.
        w_k3, s_k3 = carried
        C = C - s_k3**2 * np.outer(w_k3, w_k3)
        out[K3_TERM] = float(g @ w_k3) * s_k3
    w, V = np.linalg.eigh(C)
    comp = (g @ V) * np.sqrt(np.clip(w, 0.0, None))
    out.update({f"{TERM}.{i}": float(v) for i, v in enumerate(comp) if v != 0.0})
    return out


def left_out_k3(camera: CameraModel) -> tuple[np.ndarray, float] | None:
    """A left-out k3's term in ``camera.cov`` (:mod:`imaging.camera_k3`): its direction w
    per :data:`INTRINSICS` and range s; None when k3 was fitted, fixed as known, or the file
    predates format 5."""
    c = camera.lens_choice or {}
    if c.get("carried_k3") is None or camera.cov is None:
        return None
    return np.asarray(c["carried_direction"], float), float(c["carried_k3"])


def independent_u(camera: CameraModel, points: np.ndarray, sigma: np.ndarray,
                  chol: np.ndarray | None, shape: tuple[int, int]) -> float:
    """The same angle's u with the parameters' covariance taken as its diagonal (their u's
    added as if independent) [rad]: what the joint covariance replaces (for comparison)."""
    g = angle_sensitivity(camera, points, sigma, chol, shape)
    return float(np.sqrt(np.sum(g**2 * np.diag(model_cov(camera)))))


FIELD_RADII_PX = (100.0, 175.0, 250.0)
"""Distances [px] from the image centre of the marks :func:`field_u` sums up."""
FIELD_LENGTH_PX = 150.0
"""Their length [px]."""


def field_u(camera: CameraModel) -> dict | None:
    """What the model's own u leaves the angle of a typical mark: 150 px marks 100-250 px
    from the image centre (8 azimuths, radial and tangential), gᵀ C g each; their median
    and largest [″] (None without a covariance). ``align camera`` states it, so a user
    sees before measuring whether the calibration makes such marks lens-limited."""
    if camera.cov is None:
        return None
    w, h = camera.image_size
    t = np.linspace(-FIELD_LENGTH_PX / 2, FIELD_LENGTH_PX / 2, 76)
    us = []
    for r in FIELD_RADII_PX:
        for phi in np.radians(np.arange(0.0, 360.0, 45.0)):
            for a in (phi, phi + np.pi / 2):
                q = r * np.array([np.cos(phi), np.sin(phi)]) + np.outer(
                    t, [np.cos(a), np.sin(a)])
                if np.any(np.abs(q) > np.array([w, h]) / 2 - 5):
                    continue
                g = angle_sensitivity(camera, q, np.ones(len(q)), None, (h, w))
                us.append(float(np.sqrt(max(g @ camera.cov @ g, 0.0))))
    if not us:
        return None
    arcsec = np.degrees(np.array(us)) * 3600
    return {"median_u_arcsec": float(np.median(arcsec)), "max_u_arcsec": float(arcsec.max()),
            "radii_px": [FIELD_RADII_PX[0], FIELD_RADII_PX[-1]], "length_px": FIELD_LENGTH_PX,
            "marks": len(us)}
