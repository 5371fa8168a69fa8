"""A counter log written twice: a block of its revolutions repeated count for count.

Each revolution's counts are hashed as they are read (:func:`revolution_hash`, 8 bytes a
revolution: the table reader's one row key, :func:`axisbase.repeats.row_keys`, over the
revolution's faces); after the pass :func:`repeated_block` looks for half the log repeated
beside itself with the table reader's one rule (:func:`axisbase.repeats.find_copy`). (Logs
with times need neither: the table reader refuses a time that runs backwards.)
"""

from __future__ import annotations

import numpy as np

from axisbase.repeats import find_copy, row_keys

LEAST_REVOLUTIONS = 32
"""Fewest revolutions of a copy, whatever the log's length."""


def revolution_hash(counts: np.ndarray) -> np.ndarray:
    """A 64-bit key of each revolution's counts (one row of ``counts`` a revolution)."""
    c = np.asarray(counts).astype(np.int64)
    return row_keys([c[:, j] for j in range(c.shape[1])])


def repeated_block(h: np.ndarray, least: int = LEAST_REVOLUTIONS
                   ) -> tuple[int, int, int] | None:
    """A log written twice: a block of half its revolutions (and at least ``least``)
    repeated count for count beside itself: (first revolution, first of its repeat,
    length), else None.

    Why half and not the tables' rule (100 rows of enough information): a steady table
    turns a nearly constant fraction of a count further each revolution, so its counts
    (quantised, with the autocollimator's jitter on top, ~0.1 count) come back count for
    count after some near-period — over tens of revolutions by chance (29 of a
    120-revolution log was seen): deterministic rows, whose entropy is no measure of chance.
    Jitter makes each revolution differ with probability ~0.1 at such a return, so a match
    over half a log of >= 64 revolutions (0.9^32 ~ 3 %, times the few-percent chance of a
    near-period that close) is no chance. A shorter block pasted again is not detected. A
    log whose revolutions repeat with a short period (every revolution alike) matches itself
    over-lapping, which a copy never does (see :func:`axisbase.repeats.find_copy`).
    """
    R = len(h)
    copy = find_copy(h, max(least, (R - 1) // 2))
    if copy is None:
        return None
    return copy.first, copy.start, copy.rows
