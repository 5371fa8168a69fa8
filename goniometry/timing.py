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
from goniometry.errors import LogError
from goniometry.revolutions import LogSummary


@dataclass(frozen=True)
class TimingAngles:
    """Angles from time fractions [rad] with u and covariance (batch means); the per-angle
    mean difference counts - timing [rad] with its u, chi2 over ``dof`` and p-value;
    ``stamp_limited``: u is the time stamps' resolution floor (``stamp_resolution_s`` [s]),
    not their scatter; ``diff_cov``: the mean difference's covariance [rad^2] (its u is the
    root of the diagonal)."""

    angles_rad: np.ndarray
    u_rad: np.ndarray
    cov: np.ndarray
    revolutions: int
    diff_rad: np.ndarray
    diff_u_rad: np.ndarray
    chi2: float
    dof: int
    p_value: float
    stamp_limited: bool = False
    stamp_resolution_s: float = float("nan")
    diff_cov: np.ndarray | None = None


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


def stamp_resolution(t: np.ndarray) -> float:
    """The resolution [s] of time stamps (and of differences of them): the coarsest decimal
    grid (1 s ... 1e-12 s) they all lie on (a 10 MHz clock: 1e-7 s), but never finer than
    float64 holds them at their magnitude (0.24 µs for Unix epoch seconds). A grid finer than
    100 float64 steps is not told apart: the float64 step is then returned."""
    t = np.asarray(t, float)
    ulp = float(np.spacing(np.max(np.abs(t))))
    for k in range(13):
        step = 10.0 ** -k
        if step < 100 * ulp:  # (finer grids cannot be told from the binary rounding of t)
            break
        x = t / step
        # (on the grid: off it by no more than the decimal-to-binary rounding of t)
        if np.all(np.abs(x - np.round(x)) <= 8 * ulp / step + 8 * np.spacing(np.abs(x))):
            return step
    return ulp


def timing_angles(summary: LogSummary) -> TimingAngles:
    """Timing angles of a log with pulse times, and their check against the counts."""
    counts, dt, t_end = kept_table(summary)
    if dt is None:
        raise LogError("the log has no t column: timing angles need pulse times")
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    counts, dt = counts[ok], dt[ok]
    if len(dt) < 16:
        raise LogError(f"only {len(dt)} revolutions with times: need at least 16")
    a_t = 2 * np.pi * dt / dt.sum(1, keepdims=True)
    a_c = 2 * np.pi * counts / counts.sum(1, keepdims=True)
    cov = _batch_cov(a_t)
    # The stamps' own quantisation (+-res/2 at each end of an interval): averaged like the
    # counts' only while the jitter dithers it; when the fractions barely scatter it is
    # locked (a steady table, stamps coarser than the jitter — e.g. epoch seconds in float64)
    # and does not average at all: the floor then stands for good.
    # (the intervals too: at a whole number of revolutions a second, the reference pulses
    # alone all fall near whole seconds)
    res = stamp_resolution(np.concatenate([t_end[ok], dt.ravel()]))
    floor = 2 * np.pi * res / np.sqrt(6) / float(dt.sum(1).mean())
    locked = a_t.std(0) < 0.5 * floor
    u_floor = np.where(locked, floor, floor / np.sqrt(len(dt)))
    scale = np.maximum(u_floor / np.sqrt(np.maximum(np.diag(cov), 1e-300)), 1.0)
    cov = cov * np.outer(scale, scale)
    d = a_c - a_t
    cd = _batch_cov(d)
    # (the difference carries the stamps' error too: the check must not take it for a ripple)
    cd = cd + np.diag(np.maximum(u_floor**2 - np.diag(cd), 0.0))
    mean_d = d.mean(0)
    n = dt.shape[1]
    chi2 = float(mean_d @ np.linalg.pinv(cd, rcond=1e-10) @ mean_d)
    from scipy.special import chdtrc  # (the chi2 survival function, without scipy.stats)

    return TimingAngles(a_t.mean(0), np.sqrt(np.diag(cov)), cov, len(dt), mean_d,
                        np.sqrt(np.diag(cd)), chi2, n - 1, float(chdtrc(n - 1, chi2)),
                        bool(np.any(scale > 1.0)), res, cd)
