"""Each static pose's trend in time: the slope of its samples per axis and its uncertainty.

While the triad is static its specific force is constant, so a pose's readings change in time
only by the triad's own wander: a bias that drifts or walks, and a scale factor that follows
the room's temperature (:mod:`align.calibration.wander` separates the two across the poses).
Hand-written: an ordinary least-squares line per pose on block means, a few lines of numpy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

MIN_SLOPE_SAMPLES = 48
"""Fewest samples of a pose whose trend is used (as the walk's spectrum,
:data:`align.calibration.walk.MIN_WALK_SAMPLES`)."""
SLOPE_POINTS = 48
"""The pose is averaged in blocks down to at most this many points before the line is fitted:
the residual scatter of block means then carries the noise's correlation over up to a block
(a sensor's anti-alias filter, a flicker of seconds), so the slope's u is not that of white
noise when the noise is not white; 46 dof still give u to 10 %."""
WALK_SLOPE = 1.2
"""Var(slope) of a least-squares line through a Wiener process of unit rate over a pose of
duration T is 6/(5 T) (∫∫ (s − T/2)(r − T/2) min(s, r) ds dr / (T³/12)²): a bias walk's share
of a pose's slope variance beyond what its block means' scatter shows [1]."""


def pose_slopes(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
                walk_rate: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Each pose's slope per axis [output unit/s], its standard uncertainty and the pose's
    duration [s]; NaN slopes (u inf) for poses too short to tell; None when no pose is.

    Parameters
    ----------
    samples : sequence of (n_p, 3) arrays
        Each pose's samples [output unit].
    times : sequence of (n_p,) arrays
        Their times [s].
    walk_rate : numpy.ndarray, optional
        The bias random walk's rate per axis the samples show [output unit² / s]
        (:func:`align.calibration.walk.walk_levels`): its slope variance
        :data:`WALK_SLOPE` q / T is added.
    """
    n = len(samples)
    slope = np.full((n, 3), np.nan)
    u = np.full((n, 3), np.inf)
    span = np.zeros(n)
    for p, (x, t) in enumerate(zip(samples, times, strict=True)):
        t = np.asarray(t, float)
        if len(x) < MIN_SLOPE_SAMPLES or np.ptp(t) <= 0:
            continue
        b = -(-len(x) // SLOPE_POINTS)
        m = len(x) // b
        y = np.asarray(x, float)[:m * b].reshape(m, b, -1).mean(1)
        tb = t[:m * b].reshape(m, b).mean(1)
        X = np.column_stack([np.ones(m), tb - tb.mean()])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ coef
        sxx = float(np.sum((tb - tb.mean()) ** 2))
        var = np.sum(r * r, 0) / (m - 2) / sxx
        span[p] = float(np.ptp(t))
        if walk_rate is not None:
            var = var + WALK_SLOPE * np.asarray(walk_rate, float) / span[p]
        slope[p], u[p] = coef[1], np.sqrt(var)
    if not np.any(span > 0):
        return None
    return slope, u, span
