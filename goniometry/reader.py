"""Streaming reader of counter logs (``count,counter,ref[,t]``), with validation.

Read through the tool's one table reader (:mod:`axisbase.table`: BOM, CRLF, header case,
aliases and ``--columns`` handled there) in record batches, so memory does not grow with the
log; every problem is reported as ``file:line: column: what is wrong``. Rows already in memory
(a mapping of column name to values, a numpy structured array, a pyarrow Table) go through
the same reader (:func:`axisbase.table.iter_rows`); their problems name the row's index.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axisbase.errors import InputError
from axisbase.table import Column, Table, TableSpec, iter_rows, iter_table
from goniometry.errors import LogError

COUNTER_LOG = TableSpec(
    "counter log",
    (Column("count", "int", aliases=("counts", "periods")),
     Column("counter", "int", aliases=("counter_id",)),
     Column("ref", "int", aliases=("reference", "ref_pulse")),
     Column("t", "float", required=False, aliases=("time", "t_s", "time_s", "timestamp"))),
    time="t", rate_hz_range=(1e-2, 1e4))
"""(Plausible pulse rates: a face every 100 s — a 4-face table at 0.9 °/s, about where a ring
laser's lock-in ends — to 10⁴ faces a second, a 24-face polygon at 400 rev/s; times in ms or
µs read as seconds fall below, and a warning names the unit.)"""
COLUMNS = ("count", "counter", "ref")
ROWS = "rows"
"""What messages call a log given as rows in memory."""


def source_name(log: object) -> str | Path:
    """The file of a log given as a path; :data:`ROWS` for rows in memory."""
    return log if isinstance(log, str | Path) else ROWS


def where(source: str | Path, line: int) -> str:
    """``file:line`` for a file, ``rows: row k`` for rows in memory (``line`` their index)."""
    return f"{ROWS}: row {line}" if source == ROWS else f"{source}:{line}"


@dataclass(frozen=True)
class Chunk:
    """Rows of the log, as read and validated.

    Attributes
    ----------
    count : ndarray of int64
        Ring-laser periods between a pulse and the one before [counts].
    counter : ndarray of int64
        Which of the two counters wrote the row (1 or 2; they alternate).
    ref : ndarray of int64
        1 where the reference (face 0) signal marked the pulse, else 0.
    t : ndarray of float, or None
        Pulse times [s], None when the log has no ``t`` column.
    first_line : int
        File line of the first row (blank lines not counted); for rows in memory, the
        first row's index.
    """

    count: np.ndarray
    counter: np.ndarray
    ref: np.ndarray
    t: np.ndarray | None
    first_line: int


def iter_log(path: str | Path | object, block_bytes: int = 1 << 20,
             columns: Mapping[str, str] | None = None, threads: bool = True,
             time_unit: str | None = None) -> Iterator[Chunk]:
    """Yield the log in chunks (about ``block_bytes`` of text each), parsed ahead on a
    pool of threads (``threads``; see :func:`axisbase.table.iter_table`); rows in memory in
    chunks of :data:`axisbase.table.ROWS_PER_CHUNK` rows (:func:`axisbase.table.iter_rows`).

    Small chunks keep the pass's numpy temporaries cache-sized; the parse itself works on
    larger blocks, a bounded number in flight, so memory does not grow with the log.

    Parameters
    ----------
    path : str, Path, mapping of str to array-like, numpy structured array or pyarrow Table
        The counter log (``count,counter,ref[,t]``): its file, or its rows in memory.
    block_bytes : int
        Text per chunk [bytes].
    columns : mapping of str to str, optional
        Canonical name -> header name (``--columns``).
    threads : bool
        Parse on a pool of threads.
    time_unit : str, optional
        The ``t`` column's unit when its header says none (``--time-unit``, the session's
        ``time_unit``; see :func:`axisbase.header.declare_time_unit`).

    Yields
    ------
    Chunk
        Validated rows.

    Raises
    ------
    LogError
        Naming the file, the line, the column and what is wrong.
    """
    try:
        tables = (iter_table(path, COUNTER_LOG, columns, block_bytes, parallel=threads,
                             time_unit=time_unit)
                  if isinstance(path, str | Path) else
                  iter_rows(path, COUNTER_LOG, columns, name=ROWS, time_unit=time_unit))
        for tab in tables:
            _validate(tab)
            yield Chunk(tab["count"], tab["counter"], tab["ref"], tab.get("t"),
                        tab.first_line + tab.row0)
    except LogError:
        raise
    except InputError as exc:
        raise LogError(str(exc)) from None


def _validate(tab: Table) -> None:
    def fail(mask: np.ndarray, column: str, what: str) -> None:
        raise LogError(str(tab.fail(int(np.flatnonzero(mask)[0]), column, what)))

    count, counter, ref = tab["count"], tab["counter"], tab["ref"]
    # Cheap range checks first; the masks (line numbers) only when something is wrong.
    # 0 is a count: two pulses within one ring-laser period (a double trigger), which the
    # face pattern then resolves; a negative count is not.
    if count.min() < 0:
        fail(count < 0, "count", "must not be negative (ring-laser periods between two "
             "pulses)")
    if counter.min() < 1 or counter.max() > 2:
        fail((counter < 1) | (counter > 2), "counter", "must be 1 or 2")
    if ref.min() < 0 or ref.max() > 1:
        fail((ref < 0) | (ref > 1), "ref", "must be 0 or 1")
