"""The triad's bias instability: a random walk of the bias estimated from the samples within
each pose, and the covariance it puts between the pose means.

Every triad's bias wanders (a random walk at its shortest time scales, a flicker floor
beyond). Over a tumble of minutes that wander is not independent from pose to pose: two poses
a short time apart share most of it, and on the paper's 14 poses a wander of a few µg is not
separable from a linear scale or bias drift. The calibration's noise model therefore carries
it as a time-correlated covariance between the poses (a Wiener process, Cov(b_p, b_q) =
q min(t_p, t_q)), so a drift candidate must beat the wander, not white noise.

The level q is measured where no calibration effect can mimic it: within each pose, from the
Allan variance of its samples at two block lengths (a drift of the scale factor over a pose's
seconds is far below it). Hand-written: no well-kept library estimates one random-walk level
from many short, separate records (allantools wants one long series).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

WALK_ALPHA = 1e-3
"""Significance at which the within-pose Allan variances must show a random walk before it
enters the noise model (white noise alone: the clean triad's fit is unchanged)."""
MIN_WALK_SAMPLES = 64
"""Fewest samples of a pose whose Allan variance is used (eight blocks of eight)."""


def _avar(x: np.ndarray, m: int) -> tuple[np.ndarray, int]:
    """Allan variance at blocks of ``m`` samples (adjacent non-overlapping pairs) per column,
    and the number of pairs."""
    nb = len(x) // m
    means = x[:nb * m].reshape(nb, m, -1).mean(1)
    d = np.diff(means, axis=0)
    return 0.5 * np.mean(d * d, 0), nb - 1


def walk_rate(samples: Sequence[np.ndarray], times: Sequence[np.ndarray]) -> np.ndarray | None:
    """The bias random walk's rate q per axis [output unit² / s], or None when the samples do
    not show one at :data:`WALK_ALPHA` (or are too short to tell).

    Per pose, the Allan variances at m1 = n/8 and m2 = n/2 samples: white noise gives
    A/m, a random walk of q_s per sample adds q_s m / 3, so 4 σ²(m2) − σ²(m1) = 5 q_s m1
    (white noise cancels). Pooled over the poses (sums of squared differences over pairs);
    the test: that excess against its white-noise standard deviation (A/m1) √(2/P2 + 2/P1),
    P the pairs, pooled over the axes (each scaled by its own white level).

    Parameters
    ----------
    samples : sequence of (n_p, 3) arrays
        Each pose's samples [output unit].
    times : sequence of (n_p,) arrays
        Their times [s].
    """
    s1 = s2 = 0.0
    p1 = p2 = 0
    m1s, rates = [], []
    for x, t in zip(samples, times, strict=True):
        n = len(x)
        if n < MIN_WALK_SAMPLES or np.ptp(t) <= 0:
            continue
        m1, m2 = n // 8, n // 2
        a1, k1 = _avar(x, m1)
        a2, k2 = _avar(x, m2)
        s1, p1 = s1 + a1 * k1, p1 + k1
        s2, p2 = s2 + a2 * k2, p2 + k2
        m1s.append(m1)
        rates.append((n - 1) / np.ptp(t))
    if len(m1s) < 3:
        return None
    av1, av2 = s1 / p1, s2 / p2
    m1 = float(np.mean(m1s))
    excess = 4 * av2 - av1
    sd = av1 * np.sqrt(2 / p2 + 2 / p1)
    z = float(np.sum(excess / sd) / np.sqrt(len(sd)))
    if not z > stats.norm.isf(WALK_ALPHA):
        return None
    return np.maximum(excess, 0.0) / (5 * m1) * float(np.median(rates))


def walk_covariance(rate: np.ndarray, g: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The covariance (N, N) [g²] of the poses' |a| residuals from a bias random walk.

    Cov = Σ_i g_p,i g_q,i q_i (min(t_p, t_q) − t_0): the walk from the first pose (its value
    there is the fitted bias), seen through each pose's d|a|/du ``g`` (N, 3) [g per output
    unit]; ``rate`` q per axis [output unit² / s]; ``t`` the poses' times [s]."""
    s = np.asarray(t, float) - float(np.min(t))
    return (g * rate) @ g.T * np.minimum(s[:, None], s[None, :])
