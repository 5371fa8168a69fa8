"""A wiggle along a mark, fitted out before the lens reads its bow (issue 18 ask 3).

A periodic wiggle (a shaking camera's rolling shutter, vibration) moves a mark's centres across
it by a sinusoid along it; over a few periods its projection on a lens's bow columns is not
small, and the check of the marks against a calibrated lens read it as the lens departing
from its model: user 8's shaking camera (0.3 px, 110 px period along the rows, ~3 periods
along a 350 px mark) through an exact model called for cy +13 px on top of it, and every
mark of it was lens-limited. A lens bows a mark smoothly (a low polynomial along it); a
wiggle needs at least 2 periods along the mark (:data:`align.mark_stage.WIGGLE`'s rule: a
slower one is a bow, a bend or a lens, told apart elsewhere). So the wiggle is searched
first, on what a cubic along the mark leaves (the lens's shapes and the straight line), and
where it is significant its fitted sinusoid is taken off the centres the lens sees. The
mark's own loop fits it again with its line (``periodic_wiggle``) and carries its u.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import solve_triangular

from align.lens_design import LineGeometry
from align.loop import periodogram_test
from imaging import fit_line_only, line_frame

SMOOTH_ORDER = 3
"""The polynomial along the mark the wiggle is searched beside: the straight line and the
shapes a lens bows it by (a quadratic, and a cubic where the foot of the perpendicular from
the principal point is off the mark's middle)."""


@dataclass(frozen=True)
class Wiggle:
    """A wiggle fitted out of one mark.

    Attributes
    ----------
    period_px : float
        Its period along the mark [px].
    amplitude_px : float
        Its amplitude across the mark [px].
    fap : float
        The periodogram's false-alarm probability (look-elsewhere corrected).
    """

    period_px: float
    amplitude_px: float
    fap: float


def _whiten(X: np.ndarray, line: LineGeometry) -> np.ndarray:
    Xw = X / line.sigma[:, None]
    if line.chol is not None:
        Xw = solve_triangular(line.chol, Xw, lower=True, check_finite=False)
    return Xw


def without_wiggle(line: LineGeometry, alpha: float = 1e-3, nu: float | None = None
                   ) -> tuple[LineGeometry, Wiggle | None]:
    """The mark with a significant wiggle of at least 2 periods along it taken off its
    centres (the line itself when there is none).

    Parameters
    ----------
    line : LineGeometry
        The mark's centres [px], their sigma across it [px] and correlation factor.
    alpha : float
        Level of the periodogram test (its false-alarm probability over the searched
        periods).
    nu : float or None
        Degrees of freedom of an estimated whitening covariance
        (:func:`align.mark_stage.noise_dof`; None: known).

    Returns
    -------
    LineGeometry, Wiggle or None
        The centres less the fitted sinusoid across the mark, and the wiggle found.
    """
    q = line.points
    if len(q) < 4 * (SMOOTH_ORDER + 3):
        return line, None
    # The direction without the centres' correlation (one whitening less per mark): the
    # cubic's linear term takes up what it is off by.
    u, n = line_frame(fit_line_only(q, line.sigma)[0])
    t = q @ u
    span = float(np.ptp(t))
    if span <= 0:
        return line, None
    x = (t - (t.min() + t.max()) / 2) / span
    Xw = _whiten(np.column_stack([*(x**k for k in range(SMOOTH_ORDER + 1)), q @ n]), line)
    Pw, ew = Xw[:, :-1], Xw[:, -1]
    zw = ew - Pw @ np.linalg.lstsq(Pw, ew, rcond=None)[0]
    test, omega = periodogram_test(zw, t, nu)
    if not np.isfinite(omega) or not test.p_value < alpha:
        return line, None
    omega = _refined(omega, t, span, Pw, ew, line)
    if 2 * np.pi / omega > span / 2:
        # Fewer than 2 periods: a slow sinusoid less a cubic peaks as a faster one (1.5
        # periods at 2.1), the joint fit tells them apart; a bow, a bend or a lens.
        return line, None
    S = np.column_stack([np.sin(omega * t), np.cos(omega * t)])
    beta = np.linalg.lstsq(np.column_stack([Pw, _whiten(S, line)]), ew, rcond=None)[0][-2:]
    wig = Wiggle(float(2 * np.pi / omega), float(np.hypot(*beta)), float(test.p_value))
    return replace(line, points=q - np.outer(S @ beta, n)), wig


STEP = 0.05
"""The joint fit's grid of frequencies [cycles over the mark's span]."""


def _refined(omega: float, t: np.ndarray, span: float, Pw: np.ndarray, ew: np.ndarray,
             line: LineGeometry) -> float:
    """The wiggle's frequency [rad/px] fitted jointly with the cubic (least residual):
    the periodogram's peak is of what the cubic left, on its grid, and a sinusoid slower
    than 2 periods less a cubic peaks faster. Searched from 1 period over the span up to
    3 (where the cubic and a slow sinusoid trade shapes) and within 1/4 cycle of the
    periodogram's peak (a step or two of its grid), then to a tenth of this grid's step."""

    def rss(w: float) -> float:
        X = np.column_stack([Pw, _whiten(np.column_stack([np.sin(w * t), np.cos(w * t)]),
                                          line)])
        r = ew - X @ np.linalg.lstsq(X, ew, rcond=None)[0]
        return float(r @ r)

    c0 = omega * span / (2 * np.pi)
    cycles = np.unique(np.concatenate([np.arange(1.0, min(c0, 3.0) + STEP, STEP),
                                       c0 + np.arange(-0.25, 0.25 + STEP / 2, STEP)]))
    cycles = cycles[cycles > 0.5]
    best = float(cycles[np.argmin([rss(2 * np.pi * c / span) for c in cycles])])
    fine = best + np.linspace(-STEP, STEP, 11)
    best = float(fine[np.argmin([rss(2 * np.pi * c / span) for c in fine])])
    return 2 * np.pi * best / span
