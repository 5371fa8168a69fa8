"""The exact lens test's search (:func:`align.lens_exact.plausible_exact`) over all of a
camera's lines at once: at each lens vector tried, every line's bow (in its u) and its slopes.

The search reads only the lines' bows, at some 10-40 lens vectors per fit and up to ten fits
per frame (the leave-one-out tests, twice the ranges). One line at a time (one undistortion,
one line fit, one design each, :mod:`align.lens_design`) that was most of a busy frame's
lens (building.jpg: 9 lines, 69 vectors, 0.4 s of 0.5 s). Here the centres of all the lines
are one stack: one undistortion, every line's fit in closed form, the sums per line
(``np.add.reduceat``), the whitening one block-diagonal sparse matrix. The arithmetic is the
designs' (``_Design.bow_z``; the slopes a forward difference of the centres moved along
their first-order displacement) in another order: the same bows to rounding (~1e-12 of a
bow's u), and the search's results reach the user only through its p-value and the lens it
found, rounded in a note.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import sparse
from scipy.linalg import solve_triangular

from imaging.lens import undistortion_jacobian

MOVE_PX = 1e-4
"""The centres' largest move for a bow's slope [px] (a forward difference: the slopes agree
with central differences of whole designs to < 1e-6 of each column, tests/align/
test_lens_design.py)."""


class StackedLines:
    """A camera's lines as one stack of centres: where each line starts, its whitening (the
    centres' sigma and correlation, one sparse block per line).

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

    def whiten(self, X: np.ndarray) -> np.ndarray:
        """Columns ``X`` (one row per centre of the stack) whitened by the centres' noise."""
        return self.white @ X

    def off_line(self, tw: np.ndarray, V: np.ndarray) -> np.ndarray:
        """The whitened columns ``V`` with each line's straight-line part projected out: the
        least-squares fit on the line's whitened ``tw`` (along-line position) and constant
        columns, solved per line in closed form (2 x 2), subtracted."""
        s, one = self.seg, self.one_w[:, None]
        a00, a01, a11 = self.sums(tw * tw), -self.sums(tw * one), self.sums(one * one)
        c0, c1 = self.sums(tw * V), -self.sums(one * V)
        det = a00 * a11 - a01 * a01
        b0, b1 = (a11 * c0 - a01 * c1) / det, (a00 * c1 - a01 * c0) / det
        return V - tw * b0[s] + one * b1[s]

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
        """Each line's generalised least-squares line through its centres ``q`` [px]: the
        one :func:`imaging.fit_line_only` reaches by Gauss-Newton, here in closed form (the
        whitened residuals W q n - d W 1 are smallest for the offset d = (W 1)^T W q n /
        |W 1|^2 and the normal n the smaller principal axis of the whitened centres about
        that; the angle wrapped to (-pi/2, pi/2], the offset with it): (angle [rad],
        offset [px]) per line."""
        qw, one = self.whiten(q), self.one_w[:, None]
        s11 = self.sums(self.one_w**2)
        sx, sy = self.sums(qw * one).T
        cxx = self.sums(qw[:, 0] ** 2) - sx * sx / s11
        cxy = self.sums(qw[:, 0] * qw[:, 1]) - sx * sy / s11
        cyy = self.sums(qw[:, 1] ** 2) - sy * sy / s11
        a = -0.5 * np.arctan2(2 * cxy, cxx - cyy)  # the larger axis is the line's direction
        d = (sx * np.sin(a) + sy * np.cos(a)) / s11
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
        w = self.off_line(tw, bw)
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

    @cached_property
    def normal(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The lines' Gauss-Newton system at this vector, summed over them: (F, b, cost) =
        (sum G^T G, sum G^T z, sum z^T z), with each line's G and z its design's
        (:class:`align.lens_design._Design`: the whitened perpendicular displacements per
        unit of each parameter, the straight line's part projected out; the whitened
        residual of the straight line)."""
        st, s = self.stack, self.stack.seg
        ux, uy, nx, ny = np.cos(self.a)[s], -np.sin(self.a)[s], np.sin(self.a)[s], np.cos(self.a)[s]
        q = self.q
        E = self.jac[:, 0, :] * nx[:, None] + self.jac[:, 1, :] * ny[:, None]
        X = st.whiten(np.column_stack([q[:, 0] * ux + q[:, 1] * uy,
                                       q[:, 0] * nx + q[:, 1] * ny - self.d[s], E]))
        tw, rw, Ew = X[:, :1], X[:, 1], X[:, 2:]
        G = st.off_line(tw, Ew)
        return G.T @ G, G.T @ rw, float(rw @ rw)

    def bow_jacobian(self, cols: Sequence[int]) -> np.ndarray:
        """d ``bow_z`` / d lam[cols] of every line [per unit], (lines, cols): each line's
        centres moved by their first-order displacement (``jac``) so that the largest moves
        :data:`MOVE_PX`, the line stepped once from its fit (one Gauss-Newton step: exact to
        first order in the move), and the bows differenced."""
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
