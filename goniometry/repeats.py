"""A counter log written twice: a block of its revolutions repeated count for count.

Each revolution's counts are hashed as they are read (:func:`revolution_hash`, 8 bytes a
revolution); after the pass :func:`repeated_block` looks for half the log repeated beside
itself. (Logs with times need neither: the table reader refuses a time that repeats.)
"""

from __future__ import annotations

import numpy as np


def revolution_hash(counts: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row of counts (polynomial, wrapping: numpy's uint64 arithmetic
    wraps without a word)."""
    c = np.asarray(counts).astype(np.int64).astype(np.uint64)
    h = np.zeros(len(c), np.uint64)
    for j in range(c.shape[1]):
        h = h * np.uint64(1000003) + c[:, j]
    return h


def repeated_block(h: np.ndarray, window: int = 16, least: int = 32
                   ) -> tuple[int, int, int] | None:
    """A log written twice: a block of half its revolutions (and at least ``least``)
    repeated count for count beside itself: (first revolution, first of its repeat,
    length), else None.

    Why half and not any block: a steady table turns a nearly constant fraction of a count
    further each revolution, so its counts (quantised, with the autocollimator's jitter on
    top, ~0.1 count) come back count for count after some near-period — over tens of
    revolutions by chance (29 of a 120-revolution log was seen). Jitter makes each
    revolution differ with probability ~0.1 at such a return, so a match over half a log
    of >= 64 revolutions (0.9^32 ~ 3 %, times the few-percent chance of a near-period that
    close) is no chance. A shorter block pasted again is not detected. Candidate offsets
    come from equal windows of ``window`` revolution hashes.
    """
    R = len(h)
    need = max(least, window, (R - 1) // 2)
    if R < window + need:
        return None
    key = np.zeros(R - window + 1, np.uint64)
    for k in range(window):
        key = key * np.uint64(0x9E3779B97F4A7C15) + h[k:R - window + 1 + k]
    order = np.argsort(key, kind="stable")  # (ties in position order)
    ks = key[order]
    same = ks[1:] == ks[:-1]
    if not same.any():
        return None
    offsets = (order[1:] - order[:-1])[same]
    vals, cnt = np.unique(offsets[offsets > 0], return_counts=True)
    if not len(vals):
        return None
    d = int(vals[np.argmax(cnt)])
    eq = np.concatenate([[False], h[:-d] == h[d:], [False]])
    edges = np.flatnonzero(np.diff(eq.astype(np.int8)))
    starts, ends = edges[::2], edges[1::2]
    k = int(np.argmax(ends - starts))
    run = int(ends[k] - starts[k])
    # A copy lies beside its block (d >= run); a log whose revolutions repeat with a short
    # period (a steady table, a whole number of counts a revolution, no jitter: every
    # revolution alike) matches itself at that period over nearly all of it (d < run) —
    # no sign of a copy, and nothing a copy could be told apart from.
    if run < need or d < run:
        return None
    return int(starts[k]), int(starts[k]) + d, run

