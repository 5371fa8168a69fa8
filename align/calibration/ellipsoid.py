"""The seed paper's algebraic calibration: Li–Griffiths ellipsoid fit and exact extraction.

Model (seeds.md, eq. 1 and 5): u = K R (a + b), with K = diag(k) [V/g], R the exact
trigonometric matrix of the non-orthogonality angles beta [rad], b the bias [g]. In every
static pose |a| = 1 g, so the outputs lie on the ellipsoid (u - c)^T H (u - c) = 1 with
H = A^T A, A = (K R)^-1 up to the signs of k.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from align.errors import InputError

# Li & Griffiths' constraint 4J - I^2 = 1 as a quadratic form on (a b c d e f), with the
# cross terms written d*xy (not 2d*xy): seeds.md eq. (16).
_C1 = np.zeros((6, 6))
_C1[:3, :3] = [[-1, 1, 1], [1, -1, 1], [1, 1, -1]]
_C1[3:, 3:] = -np.eye(3)


def r_matrix(beta: np.ndarray) -> np.ndarray:
    """The paper's exact R (eq. 5) for beta = (bx, by, bz) [rad]."""
    bx, by, bz = beta
    return np.array([
        [1.0, np.sin(bz), np.cos(bz) * np.sin(by)],
        [0.0, np.cos(bz), np.cos(by) * np.sin(bx)],
        [0.0, 0.0, np.cos(bx) * np.cos(by)],
    ])


def row_norms(beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|r_i| of R(beta)'s rows and their Jacobian d|r_i|/d(beta_j) (3, 3).

    R's rows are not unit vectors (|r_x| > 1, |r_z| < 1 by ~beta^2/2): the triad's
    sensitivity along its sensitive axis i (output per g along it) is k_i |r_i|, not k_i.
    """
    bx, by, bz = beta
    sx, cx, sy, cy, sz, cz = (np.sin(bx), np.cos(bx), np.sin(by), np.cos(by), np.sin(bz),
                              np.cos(bz))
    n2 = np.array([1 + sz * sz + cz * cz * sy * sy, cz * cz + cy * cy * sx * sx,
                   cx * cx * cy * cy])
    # d(n^2)/d(beta): rows i, columns (bx, by, bz); sin(2b) = 2 sin b cos b.
    d2 = np.array([
        [0.0, 2 * cz * cz * sy * cy, 2 * sz * cz * cy * cy],
        [2 * cy * cy * sx * cx, -2 * sy * cy * sx * sx, -2 * sz * cz],
        [-2 * sx * cx * cy * cy, -2 * sy * cy * cx * cx, 0.0],
    ])
    n = np.sqrt(n2)
    return n, d2 / (2 * n[:, None])


@dataclass(frozen=True)
class Ellipsoid:
    """Fitted ellipsoid (u - centre)^T H (u - centre) = 1 in output units."""

    H: np.ndarray
    centre: np.ndarray


def li_griffiths(u: np.ndarray) -> Ellipsoid:
    """Ellipsoid-specific algebraic fit (Li & Griffiths 2004) exactly as the seed paper.

    The data are centred and scaled first (a similarity transform, undone afterwards) so the
    10x10 scatter matrix is well conditioned for outputs in volts or raw counts alike.
    """
    u = np.asarray(u, float)
    m = u.mean(0)
    s = float(np.sqrt(np.mean(np.sum((u - m) ** 2, 1))))
    if s == 0:
        raise InputError("all poses give the same output: no ellipsoid")
    x, y, z = ((u - m) / s).T
    D = np.column_stack([x * x, y * y, z * z, x * y, x * z, y * z, x, y, z, np.ones_like(x)])
    S = D.T @ D
    S11, S12, S22 = S[:6, :6], S[:6, 6:], S[6:, 6:]
    try:
        T = -np.linalg.solve(S22, S12.T)
    except np.linalg.LinAlgError:
        raise InputError("pose geometry is degenerate (the linear terms are not determined)"
                         ) from None
    M = np.linalg.solve(_C1, S11 + S12 @ T)
    w, v = np.linalg.eig(M)
    w, v = w.real, v.real
    # lambda = a^T S a / a^T C a with S >= 0: the admissible solution has a^T C1 a > 0 and
    # is the single positive eigenvalue (zero for noise-free data); take the best such.
    q = np.einsum("ij,ik,kj->j", v, _C1, v)
    ok = np.flatnonzero((q > 0) & (w > -1e-9 * np.abs(w).max()))
    if ok.size == 0:
        raise InputError("the fit does not yield an ellipsoid (no admissible eigenvector of "
                         "the reduced problem; degenerate poses?)")
    a1 = v[:, ok[np.argmin(w[ok])]]
    coef = np.concatenate([a1, T @ a1])
    a, b, c, d, e, f, g, h, i, j = coef
    Q = np.array([[a, d / 2, e / 2], [d / 2, b, f / 2], [e / 2, f / 2, c]])
    p = np.array([g, h, i])
    centre = -0.5 * np.linalg.solve(Q, p)
    scale = centre @ Q @ centre - j
    H = Q / scale
    if np.any(np.linalg.eigvalsh(H) <= 0):
        raise InputError("the fitted quadric is not an ellipsoid (poses do not span 3-D?)")
    # Undo the normalisation u' = (u - m) / s.
    return Ellipsoid(H / s**2, m + s * centre)


def extract(ell: Ellipsoid, signs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact (k, beta, b) from the ellipsoid, for scale-factor signs ``signs`` (+-1 each).

    A = chol(H) (upper, positive diagonal) equals diag(signs) (K R)^-1, so K R = A^-1
    diag(signs). The exact R of eq. (5) is then solved row by row (no small-angle forms).
    """
    L = np.linalg.cholesky(ell.H)
    A = L.T
    return triad_from_upper(np.linalg.inv(A) * np.asarray(signs, float)[None, :], ell.centre)


def triad_from_upper(M: np.ndarray, offset: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact (k, beta, b) of K R = M (upper triangular, R of eq. (5) solved row by row, no
    small-angle forms) and the bias b with K R b = ``offset`` (the ellipsoid's centre, or a
    known-pose fit's output offset)."""
    kx = M[0, 0]
    bz = np.arcsin(M[0, 1] / kx)
    by = np.arcsin(M[0, 2] / (kx * np.cos(bz)))
    ky = M[1, 1] / np.cos(bz)
    bx = np.arcsin(M[1, 2] / (ky * np.cos(by)))
    kz = M[2, 2] / (np.cos(bx) * np.cos(by))
    k = np.array([kx, ky, kz])
    beta = np.array([bx, by, bz])
    b = np.linalg.solve(k[:, None] * r_matrix(beta), offset)
    return k, beta, b
