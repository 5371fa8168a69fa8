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


def local_seconds_per_count(ratio: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The table's local seconds per count [s] at ``rows`` (indexes into ``ratio``, each row's
    duration / counts): the mean of the four neighbours' ratios (two rows each side, the ends
    mirrored) without the largest and the smallest. A drop-out row is one outlier among
    them (two drop-outs within two rows: the largest is dropped); a coasting table changes
    its speed by a few per cent over them. Rows without a finite ratio (the first row's
    unknown duration) count as infinitely slow, so as a largest they drop out."""
    n = len(ratio)
    if n < 5:
        fin = ratio[np.isfinite(ratio)]
        return np.full(len(rows), float(np.median(fin)) if fin.size else np.inf)
    idx = rows[:, None] + np.array([-2, -1, 1, 2])
    idx = np.where(idx < 0, -idx, idx)
    idx = np.where(idx > n - 1, 2 * (n - 1) - idx, idx)
    nb = ratio[idx]
    nb = np.sort(np.where(np.isfinite(nb), nb, np.inf), axis=1)
    return (nb[:, 1] + nb[:, 2]) / 2


def dropouts(count: np.ndarray, dt: np.ndarray | None) -> np.ndarray:
    """Rows whose interval spans a communication drop-out (see ``DROPOUT_RATIO``): their
    duration [s] beyond DROPOUT_RATIO times their counts at the local seconds per count
    (:func:`local_seconds_per_count`). All False without times (then only the count pattern
    tells, see :func:`phase_break`).

    Only rows beyond DROPOUT_RATIO times the chunk's smallest seconds per count can be one,
    so only theirs are compared with their neighbours (on a steady table a few rows: the
    neighbours of every row cost ~5 times the pass's share of this test)."""
    out = np.zeros(len(count), bool)
    if dt is None or len(count) < 2:
        return out
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = dt / count
        lo = float(np.fmin.reduce(ratio))  # (NaN ignored: the first row's unknown duration)
        if not np.isfinite(lo):
            return out
        rows = np.flatnonzero(ratio > DROPOUT_RATIO * lo)
    if rows.size:
        out[rows] = ratio[rows] > DROPOUT_RATIO * local_seconds_per_count(ratio, rows)
    return out


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

