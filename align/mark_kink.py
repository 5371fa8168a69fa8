"""A kink along one mark: two straight grooves meeting at an angle, seen as one line.

Two scribed strokes that share an end point at a few degrees (a "V", a bent-line corner) are
found as one groove; its straight fit, its chord and a bow (:data:`align.mark_stage.BEND`)
all read a direction that is neither stroke's. The test here: a broken line (a hinge
max(0, t - t_b) added to the line and the bow) against the line and the bow, its break t_b
searched over the middle of the mark. The supremum of the F statistic over t_b is not
F-distributed (the break is searched; Andrews 1993): its null distribution is simulated with
the mark's own design (its points along the line, its whitening) — a hand-written step, no
library gives the sup-F null of a given design. A bow (a circular arc) is in the null model,
so a bent mark does not fire it.

When the kink is significant the mark is two lines and not ok (no one direction is the
user's): :func:`align.marks.loop_mark` says where the break lies. (Each part is not measured
on its own here: near the break the other stroke lies in the groove's profile window over
(w + 6 s) / tan(kink) along the mark and pulls the centres, so a part's fit on the found
mark's centres is not that stroke's direction.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, special

from imaging import MarkMeasurement, line_frame

TRIM = 0.15
"""The break is searched between these fractions of the span from each end (Andrews' pi0:
near an end a hinge is a single point's worth of data and the sup-F diverges)."""

N_BREAKS = 101
"""Breaks tried over the searched span (the grid of the supremum)."""

N_SIM = 2000
"""Simulated null draws of the supremum (seeded: the test is deterministic)."""

MIN_POINTS = 30
"""Fewer centres than this: no kink test (a part would have too few to read a line)."""


@dataclass(frozen=True)
class Kink:
    """The best broken line along a mark and its test.

    Attributes
    ----------
    t_px : float
        Where the break lies along the mark, from the mark's middle [px].
    sup_f : float
        The supremum over the searched breaks of the F statistic — dimensionless.
    p : float
        Its p-value under no kink (simulated null of the supremum) — dimensionless.
    """

    t_px: float
    sup_f: float
    p: float


def _whiten(cols: np.ndarray, sigma: np.ndarray, chol: np.ndarray | None) -> np.ndarray:
    w = cols / sigma[:, None]
    return w if chol is None else linalg.solve_triangular(chol, w, lower=True)


def _sup_f(H: np.ndarray, Z: np.ndarray, dof: int) -> np.ndarray:
    """sup over the (orthonormalised) hinge columns H of the 1-column F, per column of the
    residuals Z."""
    c = H.T @ Z
    rss = np.sum(Z * Z, axis=0)
    return np.max(c**2 / np.maximum(rss - c**2, 1e-300) * dof, axis=0)


def kink_test(m: MarkMeasurement, sigma: np.ndarray, seed: int = 0) -> Kink | None:
    """The broken-line test along a mark (None: too few centres to test).

    Parameters
    ----------
    m : imaging.MarkMeasurement
        The mark: its centres [px] and the Cholesky factor of their correlation.
    sigma : numpy.ndarray
        Each centre's sigma across the line [px] (the loop's, texture included).
    seed : int
        Seed of the simulated null.

    Returns
    -------
    Kink or None
        The best break [px], its sup-F and p-value.
    """
    q = m.points
    n_pts = len(q)
    if n_pts < MIN_POINTS:
        return None
    u, nrm = line_frame(m.line.angle_rad)
    t, e = q @ u, q @ nrm
    tm = (t.min() + t.max()) / 2
    X0 = _whiten(np.column_stack([np.ones(n_pts), t - tm, (t - tm) ** 2 / np.ptp(t)]),
                 sigma, m.chol)
    Q0, _ = np.linalg.qr(X0)
    tb = np.quantile(t, np.linspace(TRIM, 1 - TRIM, N_BREAKS))
    H = _whiten(np.maximum(0.0, t[:, None] - tb[None, :]), sigma, m.chol)
    H -= Q0 @ (Q0.T @ H)
    H /= np.linalg.norm(H, axis=0)
    z = _whiten(e[:, None], sigma, m.chol)
    z -= Q0 @ (Q0.T @ z)
    dof = n_pts - X0.shape[1] - 1
    c = (H.T @ z)[:, 0]
    f = c**2 / np.maximum(float(z[:, 0] @ z[:, 0]) - c**2, 1e-300) * dof
    # Where the break lies: the best broken line against the straight line alone (the bow
    # in the null model takes up much of a V whose break is near the middle, and blurs its
    # place; the test keeps the bow so that a circular arc does not fire it).
    Q1, _ = np.linalg.qr(X0[:, :2])
    H1 = _whiten(np.maximum(0.0, t[:, None] - tb[None, :]), sigma, m.chol)
    H1 -= Q1 @ (Q1.T @ H1)
    z1 = _whiten(e[:, None], sigma, m.chol)
    k = int(np.argmax((H1.T @ (z1 - Q1 @ (Q1.T @ z1)))[:, 0] ** 2
                      / np.maximum(np.sum(H1 * H1, axis=0), 1e-300)))
    # The null: white residuals of the same design (the whitened centres are independent
    # under the model); F is scale-free, so a mis-stated sigma does not move it.
    Z = np.random.default_rng(seed).standard_normal((n_pts, N_SIM))
    Z -= Q0 @ (Q0.T @ Z)
    sims = _sup_f(H, Z, dof)
    # Below the simulation's resolution, the tail is extrapolated with an effective number
    # of independent breaks fitted where the simulation is good (its 90 % point): the single
    # break's F tail raised to that power.
    f_sup = float(np.max(f))
    p1 = float(special.fdtrc(1, dof, f_sup))
    c90 = float(np.quantile(sims, 0.9))
    m_eff = max(1.0, np.log(0.1) / np.log1p(-float(special.fdtrc(1, dof, c90))))
    p_ext = float(-np.expm1(m_eff * np.log1p(-p1))) if p1 < 1 else 1.0
    p_sim = (1 + int(np.sum(sims >= f_sup))) / (N_SIM + 1)
    p = p_sim if p_sim > 20 / N_SIM else min(p_sim, p_ext)
    return Kink(t_px=float(tb[k] - tm), sup_f=f_sup, p=p)
