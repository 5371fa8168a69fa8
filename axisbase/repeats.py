"""Duplicated data in a table: every row written twice, the file written twice, a block pasted.

Each shrinks the stated uncertainty by sqrt(2) without adding information. One rule finds a
copy in any sequence of rows given one 64-bit key per row (:func:`row_keys`): a run of
consecutive rows equal, row for row, to an earlier run (:func:`find_copy`). What makes it
proof, not chance, is each format's to say (:func:`check_repeats` for the tables a user
brings; :mod:`goniometry.repeats` for a counter log's revolutions):

* **a time column repeating is decisive**: a valid file's times increase strictly, so two
  rows equal in every column, time included, can only be a copy (:data:`TIMED_COPY_ROWS`);
* **without a time** (or with one made from ``--rate``, which is no evidence) the run must be
  long (:data:`COPY_ROWS`), lie beside its original rather than overlap it (a periodic or stuck
  signal matches itself at its period, over-lapping; a copy does not), and carry information a
  chance match cannot have: :data:`COPY_BITS` plus 2 log2 n bits of its rows' empirical
  entropy (a stuck or noise-free stretch has ~0; a quantised accelerometer at rest ~2-3 bits a
  row, so 100 rows of it are ~250 bits).

A format whose rows are deterministic (a steady table's counter log without times comes back
count for count after a near-period, see :mod:`goniometry.repeats`) asks more: half the log.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa

from axisbase.errors import InputError

if TYPE_CHECKING:
    from axisbase.tabledata import Table

PAIR_ROWS = 20
"""Fewest rows for the 'every row written twice' test: with quantised raw counts two
successive rows can be equal by chance (p per row pair up to ~0.3 for a 1-count noise in
three axes), but 10 pairs all equal by chance is p < 1e-5."""

COPY_ROWS = 100
"""Fewest rows of a copy in a table without a (measured) time column."""

COPY_BITS = 64.0
"""Fewest bits of information (the run's rows' empirical entropy times its length) in a copy,
beyond the 2 log2 n bits of choosing its start and offset among n rows: a chance match of
independent rows is then p < 2^-64."""

TIMED_COPY_ROWS = 2
"""Fewest rows of a copy when the rows carry a measured time: one row again right after
itself is a repeated time (the time check names it); two rows again are a pasted block."""

CANDIDATES = 8
"""Offsets checked row for row, the most frequent among equal windows first."""

_MIX = np.uint64(0x9E3779B97F4A7C15)


@dataclass(frozen=True)
class Copy:
    """A run of rows equal, row for row, to an earlier run.

    Attributes
    ----------
    first : int
        Index of the original's first row (0-based).
    start : int
        Index of the copy's first row.
    rows : int
        Rows in the run.
    """

    first: int
    start: int
    rows: int


def row_keys(columns: list[np.ndarray]) -> np.ndarray:
    """One 64-bit key per row: each column's values as their bytes (labels by their code in
    the column's distinct values), mixed and combined (numpy's uint64 arithmetic wraps
    without a word). Equal rows have equal keys; unequal rows collide with p ~ 2^-64.

    Parameters
    ----------
    columns : list of ndarray
        Columns of one length: numbers (any dtype of 8 bytes or fewer) or labels (objects).

    Returns
    -------
    ndarray of uint64
        The keys.
    """
    n = len(columns[0]) if columns else 0
    key = np.zeros(n, np.uint64)
    for x in columns:
        x = np.asarray(x)
        if x.dtype.kind in "OUS":  # (pyarrow's hash table: 8x numpy's sort of strings)
            codes = pa.array(x, type=pa.string()).dictionary_encode().indices
            v = np.asarray(codes.to_numpy(zero_copy_only=False), np.int64).view(np.uint64)
        elif x.dtype.kind == "f":
            v = (x.astype(np.float64) + 0.0).view(np.uint64)  # (+0.0: -0.0 is 0.0)
        else:
            v = x.astype(np.int64).view(np.uint64)
        v = (v ^ (v >> np.uint64(29))) * _MIX  # spread the bits before combining
        key = (key ^ (key >> np.uint64(31))) * np.uint64(0xBF58476D1CE4E5B9) + v
    return key


def entropy_bits(keys: np.ndarray) -> float:
    """Information of a run of rows [bits]: its length times the empirical entropy of its
    keys (0 for a stuck run; log2 of the length when every row differs)."""
    counts = np.unique(keys, return_counts=True)[1]
    return float(-(counts * np.log2(counts / len(keys))).sum())


def window_keys(keys: np.ndarray, w: int) -> np.ndarray:
    """One 64-bit key per window of ``w`` consecutive rows (``n - w + 1`` of them), in O(n)
    whatever ``w``: a polynomial hash mod 2^64, sum of key[i+m]·B^-m, from one cumulative sum
    of key[j]·B^-j (B odd, so invertible mod 2^64; numpy's uint64 products and sums wrap
    without a word). Written here because no library offers a rolling hash over array rows.
    """
    n = len(keys)
    b = 0x9E3779B97F4A7C15
    inv = np.full(n, pow(b, -1, 1 << 64), np.uint64)
    inv[0] = 1
    inv_pow = np.cumprod(inv)  # B^-j
    fwd = np.full(n - w + 1, b, np.uint64)
    fwd[0] = 1
    s = np.concatenate([[np.uint64(0)], np.cumsum(keys * inv_pow)])
    return (s[w:] - s[:n - w + 1]) * np.cumprod(fwd)  # (x B^i: the window's own origin)


def find_copy(keys: np.ndarray, least: int, min_bits: float = 0.0) -> Copy | None:
    """The first copy in ``keys``: a run of consecutive rows equal to an earlier run at one
    offset ``d``, beside it (``run <= d``: a run longer than its offset repeats itself, as a
    periodic signal does — unless it spans the whole file, which is then one block written
    k times), whose rows beside the original (``min(run, d)``) are at least ``least`` and
    carry ``min_bits`` bits (:func:`entropy_bits`). None when there is none.

    Candidate offsets are those of equal windows of ``least`` rows (:func:`window_keys`; a
    stable sort: each window's latest earlier twin), most frequent first; each is then
    checked row for row. Windows as long as a copy must be are unique in any data but a
    copy's, a stuck stretch's and a periodic signal's (whose offsets are short), even when
    single rows repeat often (a steady table's 7 distinct revolutions in 300). O(n log n)
    for the sort, O(n) per candidate (at most :data:`CANDIDATES`).

    Parameters
    ----------
    keys : ndarray of uint64
        One key per row (:func:`row_keys`).
    least : int
        Fewest rows of a copy beside its original.
    min_bits : float
        Fewest bits of information in those rows.

    Returns
    -------
    Copy or None
        The copy whose first row comes first.
    """
    keys = np.asarray(keys, np.uint64)
    n = len(keys)
    least = max(int(least), 1)
    if n < 2 * least:
        return None
    win = window_keys(keys, least)
    order = np.argsort(win, kind="stable")  # (equal windows in position order)
    same = win[order][1:] == win[order][:-1]
    if not same.any():
        return None
    vals, cnt = np.unique((order[1:] - order[:-1])[same], return_counts=True)
    best: Copy | None = None
    for d in vals[np.argsort(-cnt, kind="stable")][:CANDIDATES]:
        d = int(d)
        eq = np.concatenate([[0], (keys[d:] == keys[:-d]).view(np.int8), [0]])
        edges = np.flatnonzero(np.diff(eq))
        starts, ends = edges[::2], edges[1::2]
        for s, e in zip(starts, ends, strict=True):
            if e - s > d and not (s == 0 and e + d == n):
                continue  # over-lapping itself: a periodic stretch (a file written k times
                # is one too, but spans the file: from its first row to its last)
            rows = min(int(e - s), d)
            if rows < least or (best is not None and s + d >= best.start):
                continue
            if min_bits and entropy_bits(keys[s:s + rows]) < min_bits:
                continue
            best = Copy(int(s), int(s) + d, int(e - s))
            break
    return best


def _copy_message(table: Table, c: Copy) -> str:
    n = len(table)
    a, b, f, g = table.lines([c.start, c.start + c.rows - 1, c.first, c.first + c.rows - 1])
    whole = c.first == 0 and c.start + c.rows == n
    what = ("the file was written twice? keep one copy" if whole
            else "a block of rows pasted again? keep one copy")
    if table.in_memory:
        return (f"{table.path}: rows {a}-{b} repeat rows {f}-{g} exactly ({c.rows} rows): "
                f"{what}")
    return (f"{table.path}:{a}: lines {a}-{b} repeat lines {f}-{g} exactly ({c.rows} rows): "
            f"{what}")


def check_repeats(table: Table) -> None:
    """Refuse duplicated data: every row written twice in a row (``a a b b c c ...``), or a
    run of rows that repeats an earlier run (the file written twice, whole or in part, or a
    block pasted again; see the module's rule). A time column made from the sample rate
    (``--rate``) is no evidence and is left out of the comparison; a measured one is
    decisive.

    Parameters
    ----------
    table : Table
        The table as read.

    Raises
    ------
    InputError
        Naming the file and the lines of both copies, and what to do.
    """
    n = len(table)
    spec = table.spec
    timed = spec.time in table.data and not table.time_from_rate
    names = [c.name for c in spec.columns if c.name in table.data
             and not (c.name == spec.time and table.time_from_rate)]
    if n < 2 * TIMED_COPY_ROWS or not names:
        return
    if timed:
        t = table.data[spec.time]
        if bool((t[1:] > t[:-1]).all()):
            return  # times all distinct: no row can equal another (O(n), no keys needed)
    cols = [table.data[c] for c in names]
    keys = row_keys(cols)
    copy = (find_copy(keys, TIMED_COPY_ROWS) if timed
            else find_copy(keys, COPY_ROWS, COPY_BITS + 2 * np.log2(n)))
    if copy is not None:
        raise InputError(_copy_message(table, copy))
    if n < PAIR_ROWS or n % 2 or bool((keys[1:] == keys[:-1]).all()):
        return  # (a constant file: nothing to tell)
    if bool((keys[0::2] == keys[1::2]).all()) and (keys[1:-1:2] == keys[2::2]).mean() < 0.5:
        raise InputError(f"{table.path}:{table.line(1)}: every row is written twice in "
                         f"a row ({n // 2} pairs of identical rows): duplicated samples? "
                         "Each sample must appear once")


def first_row(table: Table) -> tuple[float, int, int] | None:
    """A streamed table's first row as :func:`restarted` needs it: (time, key, line), or None
    without a measured time."""
    spec = table.spec
    if not len(table) or spec.time not in table.data or table.time_from_rate:
        return None
    key = row_keys([table.data[c.name][:1] for c in spec.columns if c.name in table.data])
    return float(table.data[spec.time][0]), int(key[0]), table.line(0)


def restarted(chunk: Table, first: tuple[float, int, int] | None) -> None:
    """A streamed table (a counter log of 10⁸ rows is never whole in memory) whose rows start
    again from its first row — time and every column — was written twice: refused naming
    where the copy starts (a measured time is decisive; its end is not known yet). One
    comparison a row; a copy of another stretch is named by the time check ("runs
    backwards")."""
    if first is None:
        return
    t0, key0, line0 = first
    t = chunk.data[chunk.spec.time]
    hits = np.flatnonzero(t == t0)
    hits = hits[hits + chunk.row0 > 0]
    if not len(hits):
        return
    k = int(hits[0])
    cols = [chunk.data[c.name][k:k + 1] for c in chunk.spec.columns if c.name in chunk.data]
    if int(row_keys(cols)[0]) == key0:
        line = chunk.line(k)
        raise InputError(f"{chunk.path}:{line}: lines {line}- repeat lines {line0}- exactly "
                         f"(the rows start again from the first, t = {t0:g}): the file was "
                         "written twice? keep one copy")
