"""A parsed table (or a chunk of a streamed one): the columns, where its rows came from, and
the house form of an error naming a bad value's file and line."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axisbase.badrows import row_lines
from axisbase.errors import InputError
from axisbase.tablespec import TableSpec


@dataclass(frozen=True)
class Table:
    """A parsed table (or a chunk of a streamed one).

    Attributes
    ----------
    path : Path
        The file.
    spec : TableSpec
        Its format.
    data : dict of str to ndarray
        Columns under their canonical names: float64 / int64 arrays, labels as an object
        array of str; in the tool's units (seconds; g, m/s², V, counts) when the header
        declared another.
    first_line : int
        File line of the file's first data row.
    ignored : tuple of str
        Header names no column of the format took.
    units : dict of str to str
        Units of the columns as they now are (``{'ux': 'V', 't': 's'}``).
    time_from_rate : bool
        The time column was made from the sample rate.
    row0 : int
        Index in the file of this table's first row (a chunk of a streamed file).
    in_memory : bool
        Rows given in memory (:func:`iter_rows`), not read from a file: ``path`` is their
        name for the messages, ``first_line`` 0 and a bad row is named by its index.
    """

    path: Path
    spec: TableSpec
    data: dict[str, np.ndarray]
    first_line: int
    ignored: tuple[str, ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    time_from_rate: bool = False
    row0: int = 0
    in_memory: bool = False

    def __len__(self) -> int:
        return len(next(iter(self.data.values()))) if self.data else 0

    def __contains__(self, name: str) -> bool:
        return name in self.data

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    def get(self, name: str) -> np.ndarray | None:
        return self.data.get(name)

    def line(self, row: int) -> int:
        """The file line of row ``row`` (0-based). Blank lines are skipped by the parser, so
        they are counted by scanning the file — only called when reporting an error. Rows in
        memory: the row's index."""
        if self.in_memory:
            return self.row0 + row
        return row_lines(self.path, self.first_line, [self.row0 + row])[0]

    def lines(self, rows: list[int]) -> list[int]:
        """The file lines of several rows in one scan (see :meth:`line`)."""
        if self.in_memory:
            return [self.row0 + r for r in rows]
        return row_lines(self.path, self.first_line, [self.row0 + r for r in rows])

    def fail(self, row: int, column: str, what: str) -> InputError:
        """The error for a bad value, in the house form ``file:line: column: what`` (rows in
        memory: ``rows: row k: column: what``)."""
        if self.in_memory:
            return InputError(f"{self.path}: row {self.line(row)}: {column}: {what}")
        return InputError(f"{self.path}:{self.line(row)}: {column}: {what}")
