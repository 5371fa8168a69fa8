"""Communication drop-outs: rows the interface lost from a counter log.

With pulse times a drop-out shows as a row whose duration spans more than its counts' face
interval (:func:`dropouts`); without times, as a jump in the sequence of faces
(:func:`phase_break`). Either way the revolution it breaks is excluded, never stitched (see
:meth:`goniometry.stretches.Walker._stretch`).
"""

from __future__ import annotations

import numpy as np

# A row's interval is a drop-out when its duration exceeds this many times what its counts
# take at the log's speed (seconds per count, the chunk's median): the counts of the lost
# rows are lost with them, so the row after a gap of k rows holds one face interval's counts
# and k + 1 intervals' time (ratio ~k + 1). A missing autocollimator pulse has both doubled
# (ratio 1) and a glint both split; a table whose speed changed by a third within one face
# interval is no table a goniometer runs on.
DROPOUT_RATIO = 1.5


def dropouts(count: np.ndarray, dt: np.ndarray | None) -> np.ndarray:
    """Rows whose interval spans a communication drop-out (see ``DROPOUT_RATIO``): their
    duration [s] beyond DROPOUT_RATIO times their counts at the median seconds per count
    (of every 16th row: the speed, not each row, is what the median needs; a full median
    per block cost a quarter of the pass). All False without times (then only the count
    pattern tells, see :func:`phase_break`)."""
    if dt is None or len(count) < 2:
        return np.zeros(len(count), bool)
    step = 16 if len(count) >= 256 else 1
    ratio = dt[::step] / count[::step]
    ratio = ratio[np.isfinite(ratio)]
    if len(ratio) < 2:
        return np.zeros(len(count), bool)
    limit = DROPOUT_RATIO * float(np.median(ratio))
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

