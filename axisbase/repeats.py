"""Duplicated data in a table: every row written twice, the file twice, a block pasted again.

Each shrinks the stated uncertainty by sqrt(2) without adding information, so a format that
asks for it (``TableSpec.distinct_rows``) is refused by :func:`check_repeats` with the lines.
The tests are chosen so real data never trip them (see the constants).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from axisbase.errors import InputError

if TYPE_CHECKING:
    from axisbase.tabledata import Table

PAIR_ROWS = 20
"""Fewest rows for the 'every row written twice' test: with quantised raw counts two
successive rows can be equal by chance (p per row pair up to ~0.3 for a 1-count noise in
three axes), but 10 pairs all equal by chance is p < 1e-5."""


BLOCK_ROWS = 8
"""Fewest rows for the 'file written twice' test: four raw-count rows a b a b by chance is
p ~ 1e-3 with 1-count noise; eight (a b c d a b c d) is p ~ 1e-6."""


def check_repeats(table: Table) -> None:
    """Refuse duplicated data: every row written twice in a row (``a a b b c c ...``), or the
    whole file twice (``a b c a b c``). Both shrink the stated uncertainty by √2 without
    adding information. Tests chosen so real data never trip them: a constant (stuck or
    noise-free) file is not refused (its successive rows are all equal anyway), and the pair
    test needs :data:`PAIR_ROWS` rows and repeats only in pairs (successive rows across pairs
    equal in fewer than half the cases). A repeated time stamp is already refused by the time
    check.

    Parameters
    ----------
    table : Table
        The table as read.

    Raises
    ------
    InputError
        Naming the lines repeated.
    """
    n = len(table)
    if n < BLOCK_ROWS or n % 2:
        return
    cols = [table.data[c.name] for c in table.spec.columns if c.name in table.data]
    if not cols:
        return

    def equal(a: slice, b: slice) -> np.ndarray:
        out = np.ones(len(range(*a.indices(n))), bool)
        for x in cols:
            out &= x[a] == x[b]
        return out

    if bool(equal(slice(0, n - 1), slice(1, n)).all()):
        return  # constant file: nothing to tell
    h = n // 2
    if bool(equal(slice(0, h), slice(h, n)).all()):
        raise InputError(f"{table.path}:{table.line(h)}: rows {h + 1}-{n} repeat rows 1-{h} "
                         f"exactly (lines {table.line(0)}-{table.line(h - 1)}): the data "
                         "written twice? Each sample must appear once")
    if n >= PAIR_ROWS and bool(equal(slice(0, n, 2), slice(1, n, 2)).all()):
        across = equal(slice(1, n - 1, 2), slice(2, n, 2))
        if across.mean() < 0.5:
            raise InputError(f"{table.path}:{table.line(1)}: every row is written twice in "
                             f"a row ({n // 2} pairs of identical rows): duplicated samples? "
                             "Each sample must appear once")
    block = repeated_block(cols)
    if block is not None:
        start, length, offset = block
        raise InputError(f"{table.path}:{table.line(start)}: rows {start + 1}-"
                         f"{start + length} repeat rows {start - offset + 1}-"
                         f"{start - offset + length} exactly (lines "
                         f"{table.line(start - offset)}-{table.line(start - offset + length - 1)}"
                         f"): a block of rows pasted twice (one pose's samples?)? Each sample "
                         "must appear once")


BLOCK_REPEAT_ROWS = 32
"""Fewest rows of a block found again elsewhere in the file for :func:`repeated_block`, with
at least half of them distinct: 32 rows of noisy readings repeating at one offset by chance
needs each row to match, p ≤ (1/16)³² even for data with only 16 distinct values."""


def repeated_block(cols: list[np.ndarray]) -> tuple[int, int, int] | None:
    """The first block of :data:`BLOCK_REPEAT_ROWS` or more consecutive rows that repeats an
    earlier block exactly (every column, the same offset for every row), with at least half
    its rows distinct (a stuck or noise-free stretch repeats by itself): ``(start, length,
    offset)`` in rows, or None. Rows are matched by identity, O(n log n) in the rows."""
    n = len(cols[0])
    if n < 2 * BLOCK_REPEAT_ROWS:
        return None
    key = np.zeros(n, np.int64)
    for x in cols:  # one integer per distinct row (re-coded per column: no overflow)
        code = np.unique(np.asarray(x), return_inverse=True)[1].reshape(-1)
        key = np.unique(np.stack([key, code]), axis=1, return_inverse=True)[1].reshape(-1)
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    prev = np.full(n, -1)
    prev[order[1:][same]] = order[:-1][same]  # the latest earlier row with the same values
    offset = np.where(prev >= 0, np.arange(n) - prev, 0)
    # runs of one non-zero offset
    change = np.flatnonzero(np.diff(offset) != 0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [n]])
    for a, b in zip(starts, ends, strict=True):
        if offset[a] == 0 or b - a < BLOCK_REPEAT_ROWS:
            continue
        if len(np.unique(key[a:b])) >= (b - a) / 2:
            return int(a), int(b - a), int(offset[a])
    return None
