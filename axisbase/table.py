"""The one reader for every table the tool takes in (counter logs, static poses, readings).

A table is a delimited text file with one header line. Whatever program wrote it, the same
data give the same numbers:

* encoding UTF-8 with or without a byte-order mark (every Windows export has one); CRLF or LF;
* delimiter ``,``, ``;`` or tab, taken from the header line;
* header names compared case- and white-space-insensitively, with a unit in brackets allowed
  (``Ux [V]``, ``t (s)``), each column under its canonical name or one of its aliases, or
  under any name the user maps to it (``--columns ux=ax,uy=ay,uz=az``);
* columns in any order; columns the format does not know are listed in ``Table.ignored``;
* lines starting with ``#`` are comments, before the header and anywhere after it.

Parsing is pyarrow's C++ CSV reader (whole file, or record batches of bounded size for logs
of 10⁸ rows). It has no comment character: a comment line after the header has (almost
always) the wrong number of fields, and its ``invalid_row_handler`` skips it at no cost; a
comment the parser cannot tell from a row (as many fields as the header, or a label column's
value) makes the file be read once more without its comment lines (Python-filtered, rare).
When pyarrow rejects a row, the file is scanned once more by Python's csv module to name the
line, the column and what is wrong: ``file:line: column: what``. Rows are checked after
parsing: numbers finite, labels not blank, integer columns whole, a time column strictly
increasing. A file without a time column can be given one from its sample rate (``rate_hz``).

Rows already in memory (a mapping of column name to values, a numpy structured array, a
pyarrow Table) go through the same name matching, unit conversion and checks
(:func:`iter_rows`); a bad row is then named by its index, ``rows: row k: column: what``.
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from axisbase.badrows import Uncommented, refused, skip_comment
from axisbase.csvblocks import parallel_batches, read_batches
from axisbase.errors import InputError
from axisbase.header import (
    Header,
    declare_time_unit,
    match_names,
    meta_note,
    read_header,
    show_cell,
)
from axisbase.repeats import check_repeats, first_row, restarted
from axisbase.tabledata import Table
from axisbase.tablespec import KINDS, Column, TableSpec
from axisbase.units import (
    DECLARED_TEMPERATURE_UNITS,
    TIME_UNITS,
    temperature_kelvin,
    time_scale,
    value_unit,
)

__all__ = ["KINDS", "MAX_MAGNITUDE", "Column", "Table", "TableSpec", "iter_rows", "iter_table",
           "rate_warning", "read_table"]
"""The reader's interface; the format and result types live in :mod:`axisbase.tablespec` and
:mod:`axisbase.tabledata` (so the modules the reader uses can name them without a cycle)."""

MAX_MAGNITUDE = 1e100
"""Largest |value| a float column takes (see :func:`_check`)."""
_ARROW = {"float": pa.float64(), "int": pa.int64(), "label": pa.string()}


# ----------------------------------------------------------------------------- parsing

def _commented_labels(h: Header, spec: TableSpec, columns: Mapping[str, pa.Array]) -> bool:
    """A comment line with the header's number of fields whose first column is a label
    parses as a row: its label starts with '#'."""
    first = h.names[0]
    if not first or spec.column(first).kind != "label" or first not in columns:
        return False
    import pyarrow.compute as pc  # here: 0.1 s of import, and only label columns need it

    col = columns[first]
    # a plain substring search first (4x faster than the regex on 10⁶ labels)
    return (bool(pc.any(pc.match_substring(col, "#")).as_py())
            and bool(pc.any(pc.match_substring_regex(col, r"^\s*#")).as_py()))


def _arrow_options(path: Path, spec: TableSpec, h: Header, block_bytes: int | None,
                   threads: bool) -> tuple:
    kinds = {c.name: c.kind for c in spec.columns}
    cols = [n if n else f"_ignored_{i}" for i, n in enumerate(h.names)]
    ro = pacsv.ReadOptions(column_names=cols, skip_rows=h.skip, use_threads=threads,
                           encoding="utf8", **({"block_size": block_bytes} if block_bytes
                                               else {}))
    po = pacsv.ParseOptions(delimiter=h.delimiter, invalid_row_handler=skip_comment)
    co = pacsv.ConvertOptions(column_types={n: _ARROW[kinds[n]] for n in h.names if n},
                              include_columns=[n for n in h.names if n],
                              null_values=[""], strings_can_be_null=True,
                              quoted_strings_can_be_null=True)
    return ro, po, co



# ----------------------------------------------------------------------------- reading

def _numpy(col: pa.Array | pa.ChunkedArray, kind: str) -> np.ndarray:
    """Numbers as zero-copy views where possible (``to_numpy`` of a table imports pandas:
    0.4 s of a run); labels as an object array of str."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks() if col.num_chunks != 1 else col.chunk(0)
    if kind == "label":
        return np.array(col.to_pylist(), dtype=object)
    dtype = np.int64 if kind == "int" else np.float64
    size = np.dtype(dtype).itemsize
    return np.frombuffer(col.buffers()[1], dtype=dtype, count=len(col),
                         offset=col.offset * size)


def _check(table: Table, prev_t: float | None = None) -> None:
    """Values every format needs: no blanks, finite numbers, a strictly increasing time."""
    spec = table.spec
    for c in spec.columns:
        x = table.data.get(c.name)
        if x is None or not len(x):
            continue
        if c.kind == "label":
            blank = np.fromiter((v is None or not v.strip() for v in x), bool, len(x))
            if blank.any():
                raise table.fail(int(np.flatnonzero(blank)[0]), c.name,
                                 "is blank: every row needs a label")
        elif c.kind == "float":
            # |x| <= MAX_MAGNITUDE keeps sums of squares finite: a value beyond it is no
            # measurement in any unit, and would overflow later with no line to name.
            with np.errstate(invalid="ignore"):
                bad = ~(np.abs(x) <= MAX_MAGNITUDE)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise table.fail(k, c.name, "is not a finite number" if not np.isfinite(x[k])
                                 else f"{float(x[k]):g} is beyond any measurement "
                                 f"(|value| > {MAX_MAGNITUDE:g})")
    if spec.time and spec.time in table.data and not table.time_from_rate:
        t = table.data[spec.time]
        d = np.diff(t) if prev_t is None else np.diff(t, prepend=prev_t)
        if len(d) and d.min() <= 0:
            k = int(np.flatnonzero(d <= 0)[0]) + (1 if prev_t is None else 0)
            what = "repeats the previous row's time" if d.min() == 0 else "runs backwards"
            raise table.fail(k, spec.time, f"{float(t[k]):g} {what} (duplicated or unsorted "
                             "rows?)")


def _table(path: Path, spec: TableSpec, h: Header, columns: Mapping[str, pa.Array],
           row0: int = 0, in_memory: bool = False) -> Table:
    kinds = {c.name: c.kind for c in spec.columns}
    first = 0 if in_memory else h.skip + 1
    data = {}
    for n, col in columns.items():
        if col.null_count:
            rows = np.flatnonzero(np.asarray(col.is_null()))
            t = Table(path, spec, {}, first, row0=row0, in_memory=in_memory)
            what = ("is blank: every row needs a label" if kinds[n] == "label"
                    else "is empty")
            raise t.fail(int(rows[0]), n, what)
        data[n] = _numpy(col, kinds[n])
    ignored = tuple(r.strip() for r, n in zip(h.raw, h.names, strict=True) if not n)
    data, units = _in_own_units(path, spec, h, data)
    return Table(path, spec, data, first, ignored, units, row0=row0, in_memory=in_memory)


def _in_own_units(path: Path, spec: TableSpec, h: Header, data: dict[str, np.ndarray]
                  ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The columns whose header declares a unit (``t [ms]``, ``ux [mg]``) converted to the
    tool's own (seconds; g, m/s², V, counts; kelvin for the temperature) by the one table in
    :mod:`axisbase.units`; the units as they now are. A time or a temperature in a unit that
    is not one is refused by name."""
    units = dict(h.units)
    where = f"{path}:{h.header_line}" if h.header_line else f"{path}"
    for n, u in h.units.items():
        if n not in data or data[n].dtype.kind != "f" or not u.strip():
            continue
        if n == spec.temperature:
            kelvin = temperature_kelvin(u)
            if kelvin is None:
                raise InputError(f"{where}: {n}: temperature unit {u!r} not known; use one of "
                                 f"{', '.join(DECLARED_TEMPERATURE_UNITS)}")
            data[n], units[n] = data[n] * kelvin[0] + kelvin[1], "K"
            continue
        if n == spec.time:
            scale = time_scale(u)
            if scale is None:
                raise InputError(f"{where}: {n}: time unit {u!r} not known; "
                                 f"use one of s, ms, us, ns, min, h")
            unit = "s"
        else:
            vu = value_unit(u)
            if vu is None:
                continue  # a column of no known quantity: carried, not converted
            unit, scale = vu
        if scale != 1.0:
            data[n] = data[n] * scale
        units[n] = unit
    return data, units


def read_table(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None = None,
               rate_hz: float | None = None, time_unit: str | None = None) -> Table:
    """Read a whole table.

    Parameters
    ----------
    path : str or Path
        The file.
    spec : TableSpec
        Its format.
    columns : mapping of str to str, optional
        Canonical name -> header name, for headers the format does not know.
    rate_hz : float, optional
        Sample rate [Hz] for a file without the time column: row k gets t = k / rate.
    time_unit : str, optional
        The time column's unit when its header says none (``us``: a logger's microsecond
        stamps), see :func:`axisbase.header.read_header`.

    Returns
    -------
    Table
        The checked columns.

    Raises
    ------
    InputError
        naming the file, the line, the column and what is wrong.
    """
    path = Path(path)
    h = read_header(path, spec, columns or {}, time_unit)
    _note(meta_note(path, h))
    ro, po, co = _arrow_options(path, spec, h, None, threads=True)
    try:
        at = pacsv.read_csv(path, read_options=ro, parse_options=po, convert_options=co)
        again = _commented_labels(h, spec, dict(zip(at.column_names, at.columns, strict=True)))
    except pa.ArrowInvalid:
        err = refused(path, spec, h, retry_without_comments=True)
        if err is not None:
            raise err from None
        again = True
    if again:
        try:
            with Uncommented(path, h.skip) as src:
                at = pacsv.read_csv(io.BufferedReader(src), read_options=ro, parse_options=po,
                                    convert_options=co)
        except pa.ArrowInvalid:
            raise refused(path, spec, h, retry_without_comments=False) from None
    if at.num_rows == 0:
        raise InputError(f"{path}: the header has no rows under it (a {spec.what} needs data)")
    table = _table(path, spec, h, {n: at.column(n) for n in at.column_names})
    table = _with_rate(table, rate_hz)
    if spec.distinct_rows:  # first: a copy's repeated times are better named as a copy
        check_repeats(table)
    _check(table)
    warning = rate_warning(table)
    if warning:
        _note(f"WARNING: {warning}")
    return table


def _note(text: str | None) -> None:
    """How the file was read, to the log (the commands collect it into their warnings)."""
    if text:
        import logging

        logging.getLogger("align").warning("%s", text)


def rate_warning(table: Table) -> str | None:
    """A sentence when the table's median sample interval (within a pose, if labelled) is
    implausible for its sensor (``spec.rate_hz_range``), naming the time unit that would make
    it plausible (times in ms under a plain ``t``: a 20 Hz recording read as 0.02 Hz).

    Parameters
    ----------
    table : Table
        A table read with its format's ``rate_hz_range``.

    Returns
    -------
    str or None
        The warning, None when the rate is plausible (or cannot be told).
    """
    spec = table.spec
    if spec.rate_hz_range is None or spec.time not in table.data or table.time_from_rate:
        return None
    t = table.data[spec.time]
    d = np.diff(t)
    if "pose" in table.data:
        labels = table.data["pose"]
        d = d[labels[1:] == labels[:-1]]
    if len(d) < 2:
        return None
    dt = float(np.median(d))
    lo, hi = spec.rate_hz_range
    if lo <= 1.0 / dt <= hi:
        return None

    fits = [u for u in ("ms", "us", "ns", "min", "h")
            if lo <= 1.0 / (dt * TIME_UNITS[u]) <= hi]
    unit = table.units.get(spec.time) or "s"
    likely = (f"; were the times in {fits[0]}? say so in the header: {spec.time} [{fits[0]}]"
              f" (or --time-unit {fits[0]})" if fits else "")
    return (f"{table.path}: {spec.time}: median sample interval {dt:g} {unit} "
            f"({1.0 / dt:.3g} Hz) is implausible for a {spec.what} ({lo:g} Hz to {hi:g} Hz)"
            f"{likely}")


def _with_rate(table: Table, rate_hz: float | None) -> Table:
    spec = table.spec
    if rate_hz is None:
        return table
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"--rate {rate_hz:g}: must be a positive sample rate in Hz")
    if spec.time is None:
        raise InputError(f"--rate: a {spec.what} has no time column to make")
    if spec.time in table.data:
        raise InputError(f"--rate {rate_hz:g}: {table.path} has its own time column "
                         f"{spec.time}; give one or the other")
    data = dict(table.data)
    data[spec.time] = np.arange(len(table), dtype=float) / rate_hz
    return Table(table.path, spec, data, table.first_line, table.ignored, table.units, True,
                 table.row0, table.in_memory)


def iter_table(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None = None,
               block_bytes: int = 1 << 20, parallel: bool = False,
               time_unit: str | None = None) -> Iterator[Table]:
    """Read a table in chunks of about ``block_bytes`` of text, each a checked :class:`Table`
    (a time column is checked across chunk boundaries too). Memory stays flat in the file's
    length: 1 MiB blocks kept Arrow's pool at 41 MB for 2·10⁶ and 6·10⁶ rows.

    ``parallel``: parse on a pool of threads (see :func:`parallel_batches`); for tables of
    numbers only (a label could hold a quoted line break, which only a serial parse follows).

    Parameters
    ----------
    path : str or Path
        The file.
    spec : TableSpec
        Its format.
    columns : mapping of str to str, optional
        Canonical name -> header name.
    block_bytes : int
        Text per chunk [bytes].
    parallel : bool
        Parse on a pool of threads.
    time_unit : str, optional
        The time column's unit when its header says none (see :func:`read_table`).

    Yields
    ------
    Table
        Checked chunks, ``row0`` their first row's index in the file.

    Raises
    ------
    InputError
        Naming the file, the line, the column and what is wrong.
    """
    if parallel and any(c.kind == "label" for c in spec.columns):
        raise ValueError("iter_table(parallel=True) is for tables of numbers only")
    path = Path(path)
    h = read_header(path, spec, columns or {}, time_unit)
    _note(meta_note(path, h))
    ro, po, co = _arrow_options(path, spec, h, block_bytes, threads=False)
    row0 = 0
    prev_t = None
    first = None
    empty = True
    for filtered in (False, True):
        # The file as it is; then, only if pyarrow met a comment it could not skip, the file
        # without its comment lines, from the top, past the rows already given.
        done = row0
        try:
            source = io.BufferedReader(Uncommented(path, h.skip)) if filtered else path
            batches = (parallel_batches(path, h, ro, po, co) if parallel and not filtered
                       else read_batches(source, ro, po, co))
            for cols in batches:
                if not filtered and _commented_labels(h, spec, cols):
                    raise _Commented
                n = len(next(iter(cols.values()))) if cols else 0
                if done:
                    cut = min(done, n)
                    cols = {k: v.slice(cut) for k, v in cols.items()}
                    done, n = done - cut, n - cut
                if n == 0:
                    continue
                chunk = _table(path, spec, h, cols, row0)
                first = first or first_row(chunk)
                restarted(chunk, first)
                _check(chunk, prev_t)
                if empty and (warning := rate_warning(chunk)):
                    _note(f"WARNING: {warning}")  # (the first chunk: thousands of rows)
                empty = False
                if spec.time and spec.time in chunk.data:
                    prev_t = float(chunk.data[spec.time][-1])
                row0 += len(chunk)
                yield chunk
            break
        except (pa.ArrowInvalid, _Commented):
            err = refused(path, spec, h, retry_without_comments=not filtered)
            if err is not None:
                raise err from None
    if empty:
        raise InputError(f"{path}: the header has no rows under it (a {spec.what} needs data)")


class _Commented(Exception):
    """A comment line parsed as a row (see :func:`_commented_labels`): read again."""


ROWS_PER_CHUNK = 1 << 16
"""Rows per chunk of rows in memory (:func:`iter_rows`): about the 1 MiB of text of a file's."""


def _memory_columns(rows: object, name: str) -> dict[str, object]:
    """Column name -> values of rows in memory (keys as written: ``'t [ms]'`` allowed)."""
    if isinstance(rows, pa.Table | pa.RecordBatch):
        return {n: rows.column(n) for n in rows.column_names}
    if isinstance(rows, np.ndarray) and rows.dtype.names:
        return {n: rows[n] for n in rows.dtype.names}
    if isinstance(rows, Mapping):
        return {str(k): v for k, v in rows.items()}
    raise InputError(f"{name}: a {type(rows).__name__} is not rows of a table: give a mapping "
                     "of column name to values, a numpy structured array or a pyarrow Table")


def _memory_array(values: object, kind: str, column: str, name: str) -> pa.Array:
    """One column in memory as the Arrow type its kind has in a file; a value that type
    cannot hold (1.5 as a count, 'x' as a number) refused with its row."""
    if isinstance(values, pa.ChunkedArray):
        values = values.combine_chunks()
    try:
        arr = values if isinstance(values, pa.Array) else pa.array(np.asarray(values))
        return arr.cast(_ARROW[kind])
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
        pass
    # Only on the error path: the values one by one, to name the first bad one's row.
    want = "a whole number" if kind == "int" else "a number" if kind == "float" else "a label"
    seq = values.to_pylist() if isinstance(values, pa.Array) else list(np.ravel(values))
    for k, v in enumerate(seq):
        try:
            pa.array([v]).cast(_ARROW[kind])
        except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
            raise InputError(f"{name}: row {k}: {column}: {show_cell(str(v))} is not "
                             f"{want}") from None
    raise InputError(f"{name}: {column}: values of type {type(values).__name__} cannot be "
                     f"read as {want}s")


def iter_rows(rows: object, spec: TableSpec, columns: Mapping[str, str] | None = None,
              chunk_rows: int = ROWS_PER_CHUNK, name: str = "rows",
              time_unit: str | None = None) -> Iterator[Table]:
    """Rows already in memory as checked chunks, as :func:`iter_table` gives a file's.

    The column names are matched as a header's are (case, aliases, a unit in brackets,
    ``columns``), values converted to the column's kind and unit, and checked the same way;
    a bad value is named by its row's index (``rows: row 12: count: ...``).

    Parameters
    ----------
    rows : mapping of str to array-like, numpy structured array or pyarrow Table
        The table's columns under their names.
    spec : TableSpec
        Its format.
    columns : mapping of str to str, optional
        Canonical name -> the name the rows use.
    chunk_rows : int
        Rows per chunk.
    name : str
        What the messages call the rows.
    time_unit : str, optional
        The time column's unit when its name says none (see :func:`read_table`).

    Yields
    ------
    Table
        Checked chunks (``in_memory``), ``row0`` their first row's index.

    Raises
    ------
    InputError
        Naming the row, the column and what is wrong (or the column names).
    """
    cols = _memory_columns(rows, name)
    raw = list(cols)
    names, units = match_names(raw, spec, columns or {}, f"{name}: column names")
    units = declare_time_unit(units, spec.time if spec.time in names else None, time_unit,
                              f"{name}: column names")
    kinds = {c.name: c.kind for c in spec.columns}
    arrays = {n: _memory_array(cols[r], kinds[n], r, name)
              for r, n in zip(raw, names, strict=True) if n}
    lengths = {len(a) for a in arrays.values()}
    if len(lengths) > 1:
        raise InputError(f"{name}: columns of different lengths ("
                         + ", ".join(f"{n} {len(a)}" for n, a in arrays.items()) + ")")
    n_rows = lengths.pop()
    if n_rows == 0:
        raise InputError(f"{name}: no rows (a {spec.what} needs data)")
    h = Header(names, raw, units, "", 0, 0)
    prev_t = None
    for start in range(0, n_rows, chunk_rows):
        chunk = _table(Path(name), spec, h, {n: a.slice(start, chunk_rows)
                                             for n, a in arrays.items()}, start, True)
        _check(chunk, prev_t)
        if spec.time and spec.time in chunk.data:
            prev_t = float(chunk.data[spec.time][-1])
        yield chunk
