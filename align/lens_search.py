"""The exact lens test's search (:func:`align.lens_exact.plausible_exact`) over all of a
camera's lines at once: at each lens vector tried, every line's bow (in its u) and its slopes.

The search reads only the lines' bows, at some 10-40 lens vectors per fit and up to ten fits
per frame (the leave-one-out tests, twice the ranges): one line at a time (one undistortion,
one line fit, one design each) that was most of a busy frame's lens (building.jpg: 9 lines,
69 vectors, 0.4 s of 0.5 s). Here the centres of all the lines are one stack: one
undistortion, each line's fit a few Gauss-Newton steps made for all lines together, their
sums per line (``np.add.reduceat``), the whitening one block-diagonal sparse matrix. The
arithmetic is :mod:`align.lens_design`'s (its ``_design``'s ``bow_z``, ``_bows_moved``'s
slopes) in another order: the same bows to rounding (~1e-12 of a bow's u), and the search's
results reach the user only through its p-value and the lens it found, rounded in a note.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.linalg import solve_triangular

from imaging.lens import undistortion_jacobian

MOVE_PX = 1e-4
"""The centres' largest move for a bow's slope [px] (:func:`align.lens_design._bows_moved`'s
forward difference)."""


class StackedLines:
    """A camera's lines as one stack of centres: where each line starts, its whitening (the
    centres' sigma and correlation, one sparse block per line) and its TLS weights.

    Parameters
    ----------
    lines : sequence of align.lens_design.LineGeometry
        Each line's centres [px] (relative to the image centre), sigma [px], correlation.
    scale : float
        The half-diagonal R [px] of the lens vector's radial terms.
    """

    def __init__(self, lines: Sequence, scale: float) -> None:
        n = np.array([len(ln.points) for ln in lines])
        self.scale = scale
        self.starts = np.concatenate([[0], np.cumsum(n)[:-1]])
        self.seg = np.repeat(np.arange(len(lines)), n)
        self.points = np.concatenate([ln.points for ln in lines])
        blocks = [np.diag(1 / ln.sigma) if ln.chol is None else
                  solve_triangular(ln.chol, np.diag(1 / ln.sigma), lower=True,
                                   check_finite=False) for ln in lines]
        self.white = sparse.block_diag(blocks, format="csr")
        self.one_w = self.white @ np.ones(len(self.points))
        self.tls_w = np.concatenate([1 / ln.sigma**2 for ln in lines])

    def whiten(self, X: np.ndarray) -> np.ndarray:
        """Columns ``X`` (one row per centre of the stack) whitened by the centres' noise."""
        return self.white @ X

    def sums(self, X: np.ndarray) -> np.ndarray:
        """Per line, the sum of ``X``'s rows (one row per centre): (lines, ...)."""
        return np.add.reduceat(X, self.starts, axis=0)

    def at(self, lam: np.ndarray) -> SearchPoint | None:
        """The lines at the lens vector ``lam`` (None where the lens folds any of them)."""
        q, jac = undistortion_jacobian(self.points, lam, self.scale)
        if not np.all(np.isfinite(q)) or not np.all(np.isfinite(jac)):
            return None
        a, d = self._fit(q)
        bz = self._bow_z(q[:, :1], q[:, 1:], a[:, None], d[:, None])[:, 0]
        return SearchPoint(self, q, jac, a, d, bz)

    def _step(self, qwx: np.ndarray, qwy: np.ndarray, a: np.ndarray, d: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """One Gauss-Newton step of each line (a, d: (lines, K)) through the whitened centres
        (M, K) [px]: the lines stepped, (a, d)."""
        s = self.seg
        ux, uy, nx, ny = np.cos(a)[s], -np.sin(a)[s], np.sin(a)[s], np.cos(a)[s]
        one = self.one_w[:, None]
        j0 = qwx * ux + qwy * uy
        r = qwx * nx + qwy * ny - d[s] * one
        a00, a01, a11 = self.sums(j0 * j0), -self.sums(j0 * one), self.sums(one * one)
        g0, g1 = self.sums(j0 * r), -self.sums(one * r)
        det = a00 * a11 - a01 * a01
        return a - (a11 * g0 - a01 * g1) / det, d - (a00 * g1 - a01 * g0) / det

    def _fit(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each line's generalised least-squares line through its centres ``q`` [px]
        (:func:`imaging.fit_line_only`'s: from the weighted TLS line, Gauss-Newton to its
        end; the angle wrapped to (-pi/2, pi/2], the offset with it): (angle [rad], offset
        [px]) per line."""
        w = self.tls_w[:, None]
        m = self.sums(w * q) / self.sums(w)
        e = q - m[self.seg]
        cxx, cxy, cyy = (self.sums(w[:, 0] * e[:, 0] * e[:, 0]),
                         self.sums(w[:, 0] * e[:, 0] * e[:, 1]),
                         self.sums(w[:, 0] * e[:, 1] * e[:, 1]))
        a = -0.5 * np.arctan2(2 * cxy, cxx - cyy)  # the principal axis, as line_frame's angle
        d = m[:, 0] * np.sin(a) + m[:, 1] * np.cos(a)
        qw = self.whiten(q)
        a, d = a[:, None], d[:, None]
        for _ in range(8):
            a1, d1 = self._step(qw[:, :1], qw[:, 1:], a, d)
            done = np.all(np.abs(a1 - a) < 1e-14) and np.all(np.abs(d1 - d) < 1e-11)
            a, d = a1, d1
            if done:
                break
        a, d = a[:, 0], d[:, 0]
        wrapped = (a + np.pi / 2) % np.pi - np.pi / 2
        wrapped = np.where(wrapped <= -np.pi / 2 + 4 * np.finfo(float).eps, np.pi / 2, wrapped)
        return wrapped, np.where(np.abs(wrapped - a) > 1, -d, d)

    def _bow_z(self, qx: np.ndarray, qy: np.ndarray, a: np.ndarray, d: np.ndarray
               ) -> np.ndarray:
        """:attr:`align.lens_design._Design.bow_z` of each line for the centres (qx, qy)
        (M, K) [px] and the line (a, d) (lines, K): (lines, K)."""
        s = self.seg
        ux, uy, nx, ny = np.cos(a)[s], -np.sin(a)[s], np.sin(a)[s], np.cos(a)[s]
        t = qx * ux + qy * uy
        lo, hi = np.minimum.reduceat(t, self.starts), np.maximum.reduceat(t, self.starts)
        bow = ((t - ((lo + hi) / 2)[s]) / np.maximum(hi - lo, 1.0)[s]) ** 2
        k = t.shape[1]
        X = self.whiten(np.hstack([t, bow, qx * nx + qy * ny - d[s]]))
        tw, bw, rw = X[:, :k], X[:, k:2 * k], X[:, 2 * k:]
        one = self.one_w[:, None]
        a00, a01, a11 = self.sums(tw * tw), -self.sums(tw * one), self.sums(one * one)
        c0, c1 = self.sums(tw * bw), -self.sums(one * bw)
        det = a00 * a11 - a01 * a01
        b0, b1 = (a11 * c0 - a01 * c1) / det, (a00 * c1 - a01 * c0) / det
        w = bw - tw * b0[s] + one * b1[s]
        return self.sums(w * rw) / np.maximum(np.sqrt(self.sums(w * w)), 1e-300)


@dataclass(frozen=True)
class SearchPoint:
    """The lines at one lens vector: their undistorted centres ``q`` [px] and slopes ``jac``
    (dq/dlam, (M, 2, P)), each line's fit (angle ``a`` [rad], offset ``d`` [px]) and bow
    ``bow_z`` [its u]."""

    stack: StackedLines
    q: np.ndarray
    jac: np.ndarray
    a: np.ndarray
    d: np.ndarray
    bow_z: np.ndarray

    def bow_jacobian(self, cols: Sequence[int]) -> np.ndarray:
        """d ``bow_z`` / d lam[cols] of every line [per unit], (lines, cols): each line's
        centres moved by their first-order displacement (``jac``) so that the largest moves
        :data:`MOVE_PX`, the line stepped once from its fit, and the bows differenced
        (:meth:`align.lens_design._DesignCache.bow_jacobian`, all lines at once)."""
        st, s = self.stack, self.stack.seg
        dq = self.jac[:, :, list(cols)]  # (M, 2, C)
        h = MOVE_PX / np.maximum(np.maximum.reduceat(np.abs(dq).max(axis=1), st.starts), 1e-300)
        zero = np.zeros((len(s), 1))
        qx = self.q[:, :1] + np.hstack([zero, h[s] * dq[:, 0, :]])
        qy = self.q[:, 1:] + np.hstack([zero, h[s] * dq[:, 1, :]])
        k = qx.shape[1]
        qw = st.whiten(np.hstack([qx, qy]))
        a, d = st._step(qw[:, :k], qw[:, k:], np.repeat(self.a[:, None], k, 1),
                        np.repeat(self.d[:, None], k, 1))
        bz = st._bow_z(qx, qy, a, d)
        return (bz[:, 1:] - bz[:, :1]) / h
