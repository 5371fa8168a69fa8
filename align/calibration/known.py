"""The known-pose (six-position) calibration: IEEE Std 1293's six-position test, Ferraris'
method, what imucal implements — but with a covariance and a declared fixture error.

Each pose's up direction d_p is known in the fixture's frame (the faces +x, -x, +y, -y, +z,
-z: the triad axis that points up). The output is linear in the parameters:

    u_p = M d_p + o,      M = K R C    [output/g],  o = K R b  [output]

12 unknowns (M, o) from 3 equations per pose, so six faces leave 6 degrees of freedom.
M = (K R) C is split by an RQ decomposition into the triad's upper-triangular K R (the same
factor the ellipsoid fit finds: it is frame-free) and the rotation C of the triad in the
fixture; K, beta, b then follow exactly as in :func:`align.calibration.ellipsoid.extract`.
Weights: each pose's mean has its output noise plus the fixture's placement error sigma_f
[rad] about each of the two axes perpendicular to d_p, propagated through M (a declared,
Type B uncertainty): Sigma_p = diag(sem^2) + sigma_f^2 M (I - d d^T) M^T + sigma_f^4 M d d^T
M^T, and the tilt's second-order mean shortens d to (1 - sigma_f^2) d. Generalised least
squares, two passes (the weights need M).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import rq

from align.calibration.ellipsoid import triad_from_upper
from align.calibration.triad import Poses, TriadModel
from align.errors import InputError, InternalError
from align.loop import StageFit, Term
from axisbase.units import DEG

FACES = ("+x", "-x", "+y", "-y", "+z", "-z")
_ALIASES = {"x+": "+x", "x-": "-x", "y+": "+y", "y-": "-y", "z+": "+z", "z-": "-z",
            "x_p": "+x", "x_a": "-x", "y_p": "+y", "y_a": "-y", "z_p": "+z", "z_a": "-z",
            "xp": "+x", "xn": "-x", "yp": "+y", "yn": "-y", "zp": "+z", "zn": "-z"}
FIXTURE_ERROR_RAD = 0.5 * DEG
"""Default placement error of a face on its support (a hand against a box edge) [rad]."""
RECOGNISE_RAD = 15 * DEG
"""An unlabelled pose is taken as a face when its direction is within this of an axis [rad]."""


def face_of(label: str) -> str | None:
    """'+x', 'x+', 'x_p' (imucal), ... -> '+x'; None when the label is not a face."""
    s = str(label).strip().lower()
    return s if s in FACES else _ALIASES.get(s)


def direction(face: str) -> np.ndarray:
    d = np.zeros(3)
    d["xyz".index(face[1])] = 1.0 if face[0] == "+" else -1.0
    return d


def recognise(u: np.ndarray, tol_rad: float = RECOGNISE_RAD) -> list[str | None]:
    """Faces of unlabelled pose means: centred on the mid-range and scaled by the half-range
    of each axis, a pose within ``tol_rad`` [rad] of +-axis i is that face; else None."""
    u = np.asarray(u, float)
    lo, hi = u.min(0), u.max(0)
    half = (hi - lo) / 2
    if np.any(half <= 0):
        return [None] * len(u)
    return _nearest_faces((u - (hi + lo) / 2) / half, tol_rad)


def _nearest_faces(v: np.ndarray, tol_rad: float) -> list[str | None]:
    """Per row of v (N, 3): the face '+x' ... '-z' whose axis is within ``tol_rad`` of the
    row's direction, else None."""
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    out: list[str | None] = []
    for row in v:
        i = int(np.argmax(np.abs(row)))
        ok = np.abs(row[i]) >= np.cos(tol_rad)
        out.append(("+" if row[i] > 0 else "-") + "xyz"[i] if ok else None)
    return out


RECOGNISE_FIT_RAD = 2 * DEG
"""After an ellipsoid fit, a pose is taken as a face (for the cross-check) only when its
calibrated direction is within this [rad] of an axis: hand-placed poses near an axis are not."""


def recognise_directions(a: np.ndarray, tol_rad: float = RECOGNISE_FIT_RAD
                         ) -> list[str | None]:
    """Faces of calibrated specific forces a (N, 3): within ``tol_rad`` [rad] of +-axis i."""
    return _nearest_faces(np.asarray(a, float), tol_rad)


def labelled(poses: Poses) -> bool:
    """True when the pose labels name faces (+x, x_p, ...)."""
    return any(face_of(lab) is not None for lab in poses.labels)


def faces_of(poses: Poses) -> list[str | None]:
    """Each pose's face: from its label when the labels name faces, else recognised."""
    named = [face_of(lab) for lab in poses.labels]
    if any(f is not None for f in named):
        return named
    return recognise(poses.u)


def has_six_faces(faces: Sequence[str | None]) -> bool:
    return set(FACES) <= {f for f in faces if f is not None}


@dataclass(frozen=True)
class KnownPoseFit:
    """Known-pose calibration.

    Attributes
    ----------
    M : numpy.ndarray
        (3, 3) matrix from specific force to output [output unit/g].
    offset : numpy.ndarray
        (3,) output at zero specific force [output unit].
    cov_mo : numpy.ndarray
        (12, 12) covariance over (M row by row, offset) [products of their units].
    model : TriadModel
        The triad (k, beta, bias) with its covariance over ``model.names``; unit — (its
        own fields carry units).
    mounting : numpy.ndarray
        C, the triad's rotation in the fixture frame — dimensionless.
    chi2 : float
        The fit's χ² — dimensionless.
    dof : int
        Its degrees of freedom — dimensionless.
    faces : tuple of str
        The faces used (``+x``, ``-x``, ...); unit —.
    fixture_error_rad : float
        The declared placement error of the faces [rad].
    noise_known : bool
        False when only means were given (uncertainty from the residual); unit —.
    residuals : numpy.ndarray
        Each pose's residual [output unit].
    sigma : numpy.ndarray
        Each pose's standard uncertainty [output unit].
    projection : numpy.ndarray or None
        (9, 3n) map from the weighted residuals ``residuals_w`` to (k, beta, bias), for the
        widening of u when structure remains (:mod:`align.calibration.widen`) [each
        parameter's unit per weighted residual].
    residuals_w : numpy.ndarray or None
        The weighted residuals (3n) — dimensionless (noise unknown: the residuals [output
        unit]).
    scale_gain : numpy.ndarray or None
        (9, 3n) change of (k, beta, bias) per relative change of each pose-axis reading
        (:mod:`align.calibration.stability`) [each parameter's unit].
    """

    M: np.ndarray
    offset: np.ndarray
    cov_mo: np.ndarray
    model: TriadModel
    mounting: np.ndarray
    chi2: float
    dof: int
    faces: tuple[str, ...]
    fixture_error_rad: float
    noise_known: bool
    residuals: np.ndarray
    sigma: np.ndarray
    projection: np.ndarray | None = None
    residuals_w: np.ndarray | None = None
    scale_gain: np.ndarray | None = None

    def to_dict(self) -> dict:
        return {"method": "known-pose (six-position)", "faces": list(self.faces),
                "fixture_error_rad": self.fixture_error_rad,
                "matrix_per_g": self.M.tolist(), "offset": self.offset.tolist(),
                "scale_factors": self.model.sensitivity().tolist(),
                "scale_factors_u": self.model.sensitivity_u().tolist(),
                "beta_rad": self.model.beta.tolist(),
                "beta_u_rad": self.model.u_per_axis("beta").tolist(),
                "bias_g": self.model.bias.tolist(),
                "bias_u_g": self.model.u_per_axis("bias").tolist(),
                "mounting_rotation": self.mounting.tolist(), "chi2": self.chi2,
                "dof": self.dof, "noise_known": self.noise_known}


def _triad(theta: np.ndarray, signs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, beta, b) as one vector (9,), and C, from (M row-major, o)."""
    M = theta[:9].reshape(3, 3)
    o = theta[9:]
    T, C = rq(M)
    # Signs: diag(T) takes the scale-factor signs; C absorbs the flips (C stays orthogonal).
    s = np.sign(np.diag(T)) * signs
    T, C = T * s[None, :], C * s[:, None]
    k, beta, b = triad_from_upper(T, o)
    return np.concatenate([k, beta, b]), C


LABEL_AXES_RAD = 45 * DEG
"""The face labels name the triad's own axes (and so give the signs) only when each triad
axis is within this [rad] of its fixture axis; beyond it a sign would be read from noise."""


def face_signs(poses: Poses, faces: Sequence[str | None]) -> tuple[np.ndarray, float]:
    """Scale-factor signs (+-1 each) that labelled faces determine.

    A face label says which triad axis pointed up, so the fixture frame is the triad's own
    frame up to its small mounting rotation C: of the RQ split M = (K R) C, the one with C's
    diagonal positive (C near the identity) gives the signs of K. An ellipsoid cannot tell
    them; the labels can. Returns the signs and the largest angle between a triad axis and
    its fixture axis [rad] (:data:`LABEL_AXES_RAD`).
    """
    use = [i for i, f in enumerate(faces) if f is not None]
    d = np.array([direction(faces[i]) for i in use])
    A = np.column_stack([d, np.ones(len(use))])
    M = np.linalg.lstsq(A, poses.u[use], rcond=None)[0][:3].T  # u = M d + o, unweighted
    T, C = rq(M)
    off = float(np.arccos(np.clip(np.abs(np.diag(C)).min(), 0.0, 1.0)))
    return np.sign(np.diag(T)) * np.where(np.diag(C) < 0, -1.0, 1.0), off


def resolve_signs(poses: Poses, faces: Sequence[str | None],
                  given: Sequence[float] | None, given_as: str = "--scale-sign"
                  ) -> tuple[float, float, float]:
    """The scale-factor signs: from labelled faces when the poses carry them (an explicit
    ``given`` that contradicts them is refused, naming both), else ``given`` or +,+,+.
    Labels whose axes are more than :data:`LABEL_AXES_RAD` off the triad's give no signs:
    ``given`` is then used, and without it the calibration is refused. ``given_as``: how
    the user gives the signs (``--scale-sign``, or session.toml's ``[calibration]
    scale_sign``), which the messages name."""
    if not (labelled(poses) and has_six_faces(faces)):
        return tuple(float(s) for s in (given if given is not None else (1, 1, 1)))
    s, off = face_signs(poses, faces)
    if off > LABEL_AXES_RAD:
        if given is not None:
            return tuple(float(v) for v in given)  # type: ignore[return-value]
        raise InputError(f"the labelled faces do not name the triad's axes (an axis "
                         f"{off / DEG:.0f}° from its face, > {LABEL_AXES_RAD / DEG:g}°: swapped "
                         "labels, or the triad turned in the fixture), so they cannot give the "
                         f"scale-factor signs: correct the labels or give {given_as}")
    derived = tuple(float(v) for v in s)
    if given is not None and tuple(float(v) for v in given) != derived:
        raise InputError(f"scale sign {_sign_text(given)} ({given_as}) contradicts the "
                         f"labelled faces, which give {_sign_text(derived)} "
                         f"({_worst_face(poses, faces, s)}): drop {given_as} or correct the "
                         "pose labels")
    return derived  # type: ignore[return-value]


def _sign_text(signs: Sequence[float]) -> str:
    return ",".join("-" if v < 0 else "+" for v in signs)


def _worst_face(poses: Poses, faces: Sequence[str | None], signs: np.ndarray) -> str:
    """A face whose reading shows a sign: '+x up reads -2.41 (u_x)'."""
    i = int(np.argmin(signs)) if np.any(signs < 0) else 0
    ax = "xyz"[i]
    up = [j for j, f in enumerate(faces) if f == f"+{ax}"]
    down = [j for j, f in enumerate(faces) if f == f"-{ax}"]
    half = (poses.u[up, i].mean() - poses.u[down, i].mean()) / 2
    return f"u{ax} of face +{ax} is {half:+.4g} from the mid-point of faces +{ax} and -{ax}"


def check_mounting(C: np.ndarray) -> None:
    """A mounting is a rotation: det C = -1 (a mirror) means the labels and the signs
    describe no physical triad — refused with the reason."""
    det = float(np.linalg.det(C))
    if det < 0:
        raise InputError(f"known-pose calibration: the mounting rotation has determinant "
                         f"{det:+.3f} (a mirror, not a rotation): the scale-factor signs and "
                         "the face labels contradict each other (swapped labels, or a "
                         "scale sign given with one axis wrong)")


def fit_known(poses: Poses, faces: Sequence[str | None], signs: Sequence[float] = (1, 1, 1),
              fixture_error_rad: float = FIXTURE_ERROR_RAD) -> KnownPoseFit:
    """Known-pose fit over the poses that are faces (the others are ignored here).

    Refused (:func:`check_mounting`) when the mounting it implies is not a proper rotation.
    """
    use = [i for i, f in enumerate(faces) if f is not None]
    used = [faces[i] for i in use]
    if not has_six_faces(used):
        missing = sorted(set(FACES) - set(used))
        raise InputError(f"known-pose calibration needs all six faces; missing "
                         f"{', '.join(missing)}")
    d = np.array([direction(f) for f in used])
    # A face tilted by (e1, e2) [rad] sees cos|e| ~ 1 - (e1^2 + e2^2)/2 of g along d: on
    # average 1 - sigma_f^2 (second order, but 1e-5 of g at a 3 mrad fixture error).
    d = d * (1 - fixture_error_rad**2)
    u = poses.u[use]
    n = len(use)
    sem = poses.sigma_u[use] if poses.sigma_u is not None else np.zeros((n, 3))
    A = np.zeros((3 * n, 12))
    for p in range(n):
        for i in range(3):
            A[3 * p + i, 3 * i:3 * i + 3] = d[p]
            A[3 * p + i, 9 + i] = 1.0
    y = u.ravel()
    theta = np.linalg.lstsq(A, y, rcond=None)[0]
    for _ in range(2):
        M = theta[:9].reshape(3, 3)
        W = np.zeros((3 * n, 3 * n))
        for p in range(n):
            dn = d[p] / np.linalg.norm(d[p])
            P = np.eye(3) - np.outer(dn, dn)
            Md = M @ dn
            # tilt: first order across d; its second order along d (variance sigma_f^4)
            S = (np.diag(sem[p] ** 2) + fixture_error_rad**2 * M @ P @ M.T
                 + fixture_error_rad**4 * np.outer(Md, Md))
            # Noise-free means (synthetic data) leave S singular: a floor far below any
            # real noise (1e-12 of |M|^2) keeps the weights finite.
            S = S + np.eye(3) * 1e-12 * np.trace(M @ M.T) / 3
            W[3 * p:3 * p + 3, 3 * p:3 * p + 3] = np.linalg.inv(S)
        N = A.T @ W @ A
        theta = np.linalg.solve(N, A.T @ W @ y)
    cov = np.linalg.inv(N)
    r = y - A @ theta
    chi2 = float(r @ W @ r)
    dof = 3 * n - 12
    known = poses.sigma_u is not None or fixture_error_rad > 0
    if not known and dof > 0:
        cov = cov * float(r @ r) / dof
    sig = np.sqrt(1 / np.diag(W))
    s = np.asarray(signs, float)
    q, C = _triad(theta, s)
    check_mounting(C)
    # Propagate (M, o) -> (k, beta, b) by central differences (the map is smooth).
    J = np.zeros((9, 12))
    for j in range(12):
        h = 1e-7 * max(1.0, abs(theta[j]))
        tp, tm = theta.copy(), theta.copy()
        tp[j] += h
        tm[j] -= h
        J[:, j] = (_triad(tp, s)[0] - _triad(tm, s)[0]) / (2 * h)
    names = tuple(f"{p}_{ax}" for p in ("k", "beta", "bias") for ax in "xyz")
    model = TriadModel(q[:3], q[3:6], q[6:9], t_ref=float(np.mean(poses.t[use])),
                       cov=J @ cov @ J.T, names=names)
    # theta = N^-1 A^T W y: with W = L L^T, dtheta = N^-1 A^T L d(L^T r) per weighted
    # residual; noise unknown (W a multiple of I): per residual [output], N^-1 A^T W.
    gain = np.linalg.solve(N, A.T @ W)
    if known:
        L = np.linalg.cholesky(W)
        proj, r_w = J @ gain @ np.linalg.inv(L).T, L.T @ r
    else:
        proj, r_w = J @ gain, r
    return KnownPoseFit(theta[:9].reshape(3, 3), theta[9:], cov, model, C, chi2, dof,
                        tuple(used), fixture_error_rad, known, r, sig, proj, r_w,
                        J @ gain * y[None, :])


class KnownPoseStage:
    """The known-pose fit as a loop stage (no candidate effects: six faces leave no room)."""

    def __init__(self, fit: KnownPoseFit, poses: Poses):
        self.result = fit
        self.poses = poses

    def fit(self, terms: Sequence[Term]) -> StageFit:
        if terms:
            # The pipeline runs this stage with no candidates: a term here is a defect.
            raise InternalError("the known-pose fit takes no effects")
        f = self.result
        m = f.model
        t = np.repeat(np.arange(len(f.faces), dtype=float), 3)
        q = {n: (float(v), m.u_of(n)) for n, v in zip(
            m.names, np.concatenate([m.k, m.beta, m.bias]), strict=True)}
        # 18 components in 6 dof on six faces, each pose's three correlated through M:
        # not a sequence of independent residuals (the runs and spectral tests flagged 9 %
        # of clean six-face fits).
        return StageFit(f.residuals, f.sigma, 12, {"t": t}, "t", {}, q, payload=m,
                        sequence=False)


def cross_check(ellipsoid: TriadModel, known: TriadModel, limit: float = 5.0
                ) -> tuple[dict, list[str]]:
    """Ellipsoid vs known-pose (k, beta, b): differences in units of their combined
    uncertainty; warnings for those beyond ``limit``."""
    out, warn = {}, []
    for name, a, b in zip(ellipsoid.names[:9], np.concatenate(
            [ellipsoid.k, ellipsoid.beta, ellipsoid.bias]), np.concatenate(
            [known.k, known.beta, known.bias]), strict=True):
        u = float(np.hypot(ellipsoid.u_of(name), known.u_of(name)))
        z = float((a - b) / u) if u > 0 else float("nan")
        out[name] = {"ellipsoid": float(a), "known_pose": float(b), "z": z}
        if not abs(z) <= limit:
            warn.append(f"calibration: ellipsoid and known-pose fits disagree on {name}: "
                        f"{a:.6g} vs {b:.6g} ({z:+.1f} sigma)")
    return out, warn
