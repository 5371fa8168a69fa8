"""Face angles from pulse times, below the count quantisation, on a steady table.

With pulse times, each revolution also gives the angles as fractions of its period,
A_k = 2 pi dt_k / T_r: exact when the table turns at constant speed within the revolution,
limited then by the autocollimator's timing jitter (~0.1" a pulse) instead of the counter's
quantisation (0.69" an angle a revolution at 1.70" a count — and q / sqrt(6) for good when the
quantisation phase is locked). A speed ripple locked to the table angle biases the timing
angles and is invisible in the times themselves: only the ring laser sees it. So the timing
estimate is checked against the counts revolution by revolution: the mean difference per
angle must vanish within its uncertainty (chi2 over n - 1 dof, the closure removing one). It
is offered only under that check; what it cannot exclude is a ripple below the counts' own
averaged resolution, which is said with the result.

Uses the kept revolutions (the first ``keep`` of the log, see ``read_revolutions``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from goniometry.angles import kept_table
from goniometry.revolutions import LogSummary


@dataclass(frozen=True)
class TimingAngles:
    """Angles from time fractions [rad] with u and covariance (batch means); the per-angle
    mean difference counts - timing [rad] with its u, chi2 over ``dof`` and p-value."""

    angles_rad: np.ndarray
    u_rad: np.ndarray
    cov: np.ndarray
    revolutions: int
    diff_rad: np.ndarray
    diff_u_rad: np.ndarray
    chi2: float
    dof: int
    p_value: float


def _batch_cov(x: np.ndarray, block: int = 8) -> np.ndarray:
    """Covariance of the mean of the rows of ``x`` from the scatter of block means (rows are
    revolutions, which share reference pulses and speed wander: not independent)."""
    nb = len(x) // block
    if nb < 8:
        d = x - x.mean(0)
        return d.T @ d / (len(x) - 1) / len(x)
    m = x[: nb * block].reshape(nb, block, -1).mean(1)
    d = m - m.mean(0)
    return d.T @ d / (nb - 1) / nb


def timing_angles(summary: LogSummary) -> TimingAngles:
    """Timing angles of a log with pulse times, and their check against the counts."""
    counts, dt, _ = kept_table(summary)
    if dt is None:
        raise ValueError("the log has no t column: timing angles need pulse times")
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    counts, dt = counts[ok], dt[ok]
    if len(dt) < 16:
        raise ValueError(f"only {len(dt)} revolutions with times: need at least 16")
    a_t = 2 * np.pi * dt / dt.sum(1, keepdims=True)
    a_c = 2 * np.pi * counts / counts.sum(1, keepdims=True)
    cov = _batch_cov(a_t)
    d = a_c - a_t
    cd = _batch_cov(d)
    mean_d = d.mean(0)
    n = dt.shape[1]
    chi2 = float(mean_d @ np.linalg.pinv(cd, rcond=1e-10) @ mean_d)
    from scipy.special import chdtrc  # (the chi2 survival function, without scipy.stats)

    return TimingAngles(a_t.mean(0), np.sqrt(np.diag(cov)), cov, len(dt), mean_d,
                        np.sqrt(np.diag(cd)), chi2, n - 1, float(chdtrc(n - 1, chi2)))
