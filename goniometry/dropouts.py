"""Communication drop-outs: rows the interface lost from a counter log.

With pulse times a drop-out shows as a row whose duration spans more than its counts' face
interval (:func:`dropouts`); without times, as a jump in the sequence of faces
(:func:`phase_break`). Either way the revolution it breaks is excluded, never stitched (see
:meth:`goniometry.stretches.Walker._stretch`).
"""

from __future__ import annotations

import numpy as np

# A row's interval is a drop-out when its duration exceeds this many times what its counts
# take at the table's local speed (seconds per count of the rows around it): the
# counts of the lost rows are lost with them, so the row after a gap of k rows holds one face
# interval's counts and k + 1 intervals' time (ratio ~k + 1). A missing autocollimator pulse
# has both doubled (ratio 1) and a glint both split; a table whose speed changed by a third
# within one face interval is no table a goniometer runs on. A table that slows (coasts) or
# speeds up over the log lengthens its intervals' time AND counts together: the seconds per
# count change only as slowly as the speed, which the neighbours follow.
DROPOUT_RATIO = 1.5


def local_seconds_per_count(count: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """The table's local seconds per count at each row [s]: the mean of its four neighbours'
    (two rows each side) duration / counts without the largest and the smallest (the chunk's
    ends mirrored). A drop-out row is one outlier among them (two drop-outs within two rows:
    the largest is dropped); a coasting table changes its speed by a few per cent over them.
    Hand-written (min/max of four shifted arrays) rather than a sliding median: a median per
    row cost a quarter of the pass. Rows without a finite ratio (the first row's unknown
    duration) count as infinitely slow, so as a largest they drop out."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = dt / count
    ratio = np.where(np.isfinite(ratio), ratio, np.inf)
    if len(ratio) < 5:
        return np.full(len(ratio), float(np.median(ratio)))
    p = np.pad(ratio, 2, mode="reflect")
    nb = (p[:-4], p[1:-3], p[3:-1], p[4:])
    # the two middle values of four: of the pairs (a, b) and (c, d), the larger of the
    # smaller ones and the smaller of the larger ones (no sum less the extremes: an infinite
    # largest would make inf - inf)
    mid_hi = np.minimum(np.maximum(nb[0], nb[1]), np.maximum(nb[2], nb[3]))
    mid_lo = np.maximum(np.minimum(nb[0], nb[1]), np.minimum(nb[2], nb[3]))
    return (mid_hi + mid_lo) / 2


def dropouts(count: np.ndarray, dt: np.ndarray | None) -> np.ndarray:
    """Rows whose interval spans a communication drop-out (see ``DROPOUT_RATIO``): their
    duration [s] beyond DROPOUT_RATIO times their counts at the local seconds per count
    (:func:`local_seconds_per_count`). All False without times (then only the count pattern
    tells, see :func:`phase_break`)."""
    if dt is None or len(count) < 2:
        return np.zeros(len(count), bool)
    if np.count_nonzero(np.isfinite(dt / np.where(count == 0, np.nan, count))) < 2:
        return np.zeros(len(count), bool)
    limit = DROPOUT_RATIO * local_seconds_per_count(count, dt)
    with np.errstate(invalid="ignore"):  # (the first row's unknown duration: NaN, no gap)
        return dt > limit * count


def phase_break(count: np.ndarray, inc: np.ndarray, tol: float,
                ends_at_ref: bool) -> int | None:
    """Without times, a drop-out from the count pattern: the first row (index into
    ``count``, the rows after a face-0 anchor) where the sequence of faces jumps.

    The lost rows take their counts with them, so every logged interval is still one genuine
    face interval — before the gap they follow the faces 0, 1, 2, ... from the anchor, after
    it at another phase. A missing autocollimator pulse (two intervals merged) or a spurious
    one (an interval split) fits no single face, and is left to the walk. Needs faces whose
    intervals differ by more than ``tol`` (else the phase cannot be seen: None); a whole
    number of revolutions lost keeps the phase, and then the stitched revolution's intervals
    are the genuine ones (without times no Earth-rate correction carries the gap).
    """
    n = len(inc)
    d = np.abs(inc[:, None] - inc[None, :])
    if n < 2 or np.min(d[~np.eye(n, dtype=bool)]) <= 2 * tol:
        return None
    fits = np.abs(count[:, None] - inc[None, :]) <= tol
    one = fits.sum(1) == 1
    face = np.argmax(fits, 1)
    expect = 0  # the face interval the next row should be: 0 -> 1 first
    for i in range(len(count)):
        if not one[i]:
            return None  # a pulse fault first: the walk decides
        if face[i] != expect:
            # Lost rows (their number mod n: the phase jump), if the next rows go on at the
            # new phase; else it is something the walk handles.
            # (or the stretch ends there: at the reference mark the new phase predicts, or at
            # the end of the log).
            after = range(1, min(3, len(count) - i))
            if all(one[i + m] and face[i + m] == (face[i] + m) % n for m in after) and (
                    len(after) == 2 or not ends_at_ref
                    or (face[i] + len(after) + 1) % n == 0):
                return i
            return None
        expect = (expect + 1) % n
    return None

