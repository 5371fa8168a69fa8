"""Streaming reader of counter logs (``count,counter,ref[,t]``), with validation.

Read in record batches by pyarrow's C++ CSV reader, so memory does not grow with the log;
every problem is reported with the file, the line number and what is wrong.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from goniometry.errors import LogError

COLUMNS = ("count", "counter", "ref")


@dataclass(frozen=True)
class Chunk:
    """Rows of the log: counts [ring-laser periods], counter (1/2), ref (0/1), t [s] or None;
    ``first_line``: the file line number of the first row."""

    count: np.ndarray
    counter: np.ndarray
    ref: np.ndarray
    t: np.ndarray | None
    first_line: int


def _header(path: Path) -> list[str]:
    try:
        with open(path, newline="") as f:
            head = f.readline()
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise LogError(f"{path}: not a text CSV file") from None
    cols = [c.strip().lower() for c in head.strip().split(",")]
    missing = [c for c in COLUMNS if c not in cols]
    if missing:
        raise LogError(f"{path}, line 1: header {cols} lacks {missing}; expected "
                       "count,counter,ref[,t]")
    return cols


def _locate(path: Path, ncols: int) -> str:
    """Slow path, only after a parse error: the first line that is not a valid row."""
    with open(path, newline="") as f:
        rows = csv.reader(f)
        next(rows)
        for ln, row in enumerate(rows, start=2):
            if len(row) != ncols:
                return f"line {ln}: {len(row)} fields, expected {ncols} (truncated line?)"
            for v in row:
                try:
                    float(v)
                except ValueError:
                    return f"line {ln}: {v!r} is not a number"
    return "unreadable row"


def iter_log(path: str | Path, block_bytes: int = 1 << 20) -> Iterator[Chunk]:
    """Yield the log in chunks (about ``block_bytes`` of text each).

    1 MiB blocks keep Arrow's pool flat (41 MB peak for 2e6 and 6e6 rows); with 4 MiB
    blocks its read-ahead grew with the log (64 -> 161 MB).
    """
    path = Path(path)
    cols = _header(path)
    types = {"count": pa.float64(), "counter": pa.float64(), "ref": pa.float64(),
             "t": pa.float64()}
    try:
        reader = pacsv.open_csv(
            path, read_options=pacsv.ReadOptions(block_size=block_bytes, use_threads=False),
            convert_options=pacsv.ConvertOptions(
                column_types={c: types[c] for c in cols if c in types},
                include_columns=[c for c in cols if c in types]))
    except pa.ArrowInvalid:
        raise LogError(f"{path}: {_locate(path, len(cols))}") from None
    line = 2
    has_t = "t" in cols
    while True:
        try:
            batch = reader.read_next_batch()
        except StopIteration:
            return
        except pa.ArrowInvalid:
            raise LogError(f"{path}: {_locate(path, len(cols))}") from None
        count = batch.column("count").to_numpy()
        counter = batch.column("counter").to_numpy()
        ref = batch.column("ref").to_numpy()
        t = batch.column("t").to_numpy() if has_t else None
        _validate(path, line, count, counter, ref, t)
        yield Chunk(count.astype(np.int64), counter.astype(np.int8), ref.astype(np.int8), t,
                    line)
        line += len(count)


def _validate(path: Path, line: int, count, counter, ref, t) -> None:
    def fail(mask: np.ndarray, what: str) -> None:
        i = int(np.flatnonzero(mask)[0])
        raise LogError(f"{path}, line {line + i}: {what}")

    for name, col in (("count", count), ("counter", counter), ("ref", ref)):
        bad = ~np.isfinite(col)
        if bad.any():
            fail(bad, f"{name} is empty or not a number")
    if (count <= 0).any():
        fail(count <= 0, "count must be positive (ring-laser periods between two pulses)")
    if (count != np.round(count)).any():
        fail(count != np.round(count), "count is not a whole number")
    if not np.isin(counter, (1, 2)).all():
        fail(~np.isin(counter, (1, 2)), "counter must be 1 or 2")
    if not np.isin(ref, (0, 1)).all():
        fail(~np.isin(ref, (0, 1)), "ref must be 0 or 1")
    if t is not None and not np.all(np.isfinite(t)):
        fail(~np.isfinite(t), "t is not a number")
