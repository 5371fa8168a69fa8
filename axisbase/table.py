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
"""

from __future__ import annotations

import csv
import io
import re
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from axisbase.errors import InputError
from axisbase.units import TIME_UNITS, time_scale, value_unit

KINDS = ("float", "int", "label")
MAX_MAGNITUDE = 1e100
"""Largest |value| a float column takes (see :func:`_check`)."""
_ARROW = {"float": pa.float64(), "int": pa.int64(), "label": pa.string()}
_UNIT = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")


@dataclass(frozen=True)
class Column:
    """One column of a format: canonical ``name``, ``kind`` ('float', 'int' or 'label'),
    whether it is ``required``, and the other header spellings accepted for it."""

    name: str
    kind: str = "float"
    required: bool = True
    aliases: tuple[str, ...] = ()


@dataclass(frozen=True)
class TableSpec:
    """A table format: what it is called in messages (``what``) and its columns. ``time``
    names the column that must increase strictly (and that ``rate_hz`` may supply).
    ``distinct_rows``: a file whose rows are each written twice, or which holds the same block
    of rows twice, is refused (see :func:`check_repeats`)."""

    what: str
    columns: tuple[Column, ...]
    time: str | None = None
    distinct_rows: bool = False
    rate_hz_range: tuple[float, float] | None = None
    """Plausible sample rates of the sensor [Hz]: a median interval outside is a warning
    naming the likely time unit (see :func:`rate_warning`)."""

    def column(self, name: str) -> Column:
        return next(c for c in self.columns if c.name == name)

    @property
    def layout(self) -> str:
        """The header a user should write, e.g. ``pose,ux,uy,uz[,t][,temp]``."""
        req = ",".join(c.name for c in self.columns if c.required)
        return req + "".join(f"[,{c.name}]" for c in self.columns if not c.required)


@dataclass(frozen=True)
class Table:
    """Parsed columns under their canonical names (float64 / int64 arrays, labels as an object
    array of str), ``first_line``: the file line of the first row, ``ignored``: header names no
    column of the format took, ``units``: units written in the header (``{'ux': 'V'}``),
    ``time_from_rate``: the time column was made from the sample rate, ``row0``: the index in
    the file of this table's first row (a chunk of a streamed file)."""

    path: Path
    spec: TableSpec
    data: dict[str, np.ndarray]
    first_line: int
    ignored: tuple[str, ...] = ()
    units: dict[str, str] = field(default_factory=dict)
    time_from_rate: bool = False
    row0: int = 0

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
        they are counted by scanning the file — only called when reporting an error."""
        return _row_lines(self.path, self.first_line, [self.row0 + row])[0]

    def fail(self, row: int, column: str, what: str) -> InputError:
        """The error for a bad value, in the house form ``file:line: column: what``."""
        return InputError(f"{self.path}:{self.line(row)}: {column}: {what}")


# ----------------------------------------------------------------------------- header

@dataclass(frozen=True)
class _Header:
    names: list[str]           # canonical name, or '' for a column the format does not know
    raw: list[str]             # as written
    units: dict[str, str]
    delimiter: str
    skip: int                  # lines before the first data row (comments + header)
    header_line: int


def _norm(text: str) -> tuple[str, str]:
    """'  Ux [V] ' -> ('ux', 'V'); quotes and surrounding white space dropped."""
    t = text.strip().strip('"').strip("'").strip()
    unit = ""
    m = _UNIT.match(t)
    if m:
        t, unit = m.group(1), m.group(2)
    return re.sub(r"\s+", "_", t.strip().lower()), unit


_SAFE = re.compile(r"^[\w .,\[\]()%/°²µ^+-]{0,24}$")


def _show_header(raw: list[str]) -> str:
    """The header for a message — but never a file's contents: if a field does not look like
    a column name (e.g. the first line of a file that is not a table at all), only the number
    of fields is given."""
    names = [r.strip() for r in raw]
    if all(_SAFE.match(n) for n in names):
        return "(" + ", ".join(names) + ")"
    return f"({len(names)} field(s), not column names)"


def _show_cell(v: str) -> str:
    """A bad cell for a message: short ones quoted, longer ones only described."""
    return repr(v) if _SAFE.match(v) and len(v) <= 16 else f"a {len(v)}-character text"


def parse_column_map(text: str | None, flag: str = "--columns") -> dict[str, str]:
    """``'ux=ax, uy=ay'`` -> ``{'ux': 'ax', 'uy': 'ay'}`` (canonical name = header name)."""
    if not text:
        return {}
    out: dict[str, str] = {}
    for item in text.split(","):
        if "=" not in item:
            raise InputError(f"{flag} {text!r}: {item.strip()!r} is not NAME=HEADER "
                             "(e.g. ux=ax,uy=ay,uz=az)")
        k, v = (s.strip() for s in item.split("=", 1))
        if not k or not v:
            raise InputError(f"{flag} {text!r}: {item.strip()!r} has an empty side")
        if k.lower() in out:
            raise InputError(f"{flag} {text!r}: {k} is mapped twice")
        out[k.lower()] = _norm(v)[0]
    return out


def _read_header(path: Path, spec: TableSpec, mapping: Mapping[str, str]) -> _Header:
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            skip = 0
            for line in f:
                skip += 1
                if line.strip() and not line.lstrip().startswith("#"):
                    break
            else:
                raise InputError(f"{path}: empty file: expected a header line "
                                 f"{spec.layout} ({spec.what})")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a {spec.what}") from None
    except PermissionError:
        raise InputError(f"{path}: not readable (permission denied)") from None
    except UnicodeDecodeError:
        raise (_not_utf8(path, spec) or InputError(
            f"{path}: not a UTF-8 text file (a {spec.what} is CSV text)")) from None
    text = line.rstrip("\r\n")
    if "\x00" in text:
        raise InputError(f"{path}:{skip}: NUL bytes in the header: UTF-16 text or a binary "
                         f"file? a {spec.what} is UTF-8 CSV text")
    delimiter = max(",;\t", key=text.count)
    raw = next(csv.reader([text], delimiter=delimiter))
    normed = [_norm(r) for r in raw]
    where = f"{path}:{skip}: header"
    known = {c.name for c in spec.columns}
    unknown_map = sorted(set(mapping) - known)
    if unknown_map:
        raise InputError(f"--columns: {', '.join(unknown_map)} not a column of a {spec.what} "
                         f"({', '.join(sorted(known))})")
    names = [""] * len(raw)
    for col in spec.columns:
        wanted = [mapping[col.name]] if col.name in mapping else [col.name, *col.aliases]
        hits = [i for i, (n, _) in enumerate(normed) if n in wanted]
        if len(hits) > 1:
            raise InputError(f"{where}: {col.name}: given {len(hits)} times "
                             f"{_show_header([raw[i] for i in hits])}")
        if hits:
            if names[hits[0]]:
                raise InputError(f"{where}: {raw[hits[0]].strip()!r} would be both "
                                 f"{names[hits[0]]} and {col.name}")
            names[hits[0]] = col.name
        elif col.name in mapping:
            raise InputError(f"{where}: --columns {col.name}={mapping[col.name]}: no such "
                             f"column in the header {_show_header(raw)}")
    missing = [c.name for c in spec.columns if c.required and c.name not in names]
    if missing:
        raise InputError(f"{where}: {_show_header(raw)} lacks {', '.join(missing)}; a "
                         f"{spec.what} has "
                         f"{spec.layout} (name other headers with --columns, e.g. "
                         f"{missing[0]}=YOUR_NAME)")
    units = {n: u for n, (_, u) in zip(names, normed, strict=True) if n and u}
    return _Header(names, raw, units, delimiter, skip, skip)


def _quiet_undecodable_rows(unraisable) -> None:
    """pyarrow decodes an invalid row's text (e.g. a comment line) before it calls the
    handler; a line that is not UTF-8 fails there and pyarrow prints it as 'Exception
    ignored' with a traceback. The file is refused anyway, naming that line (_not_utf8):
    the traceback is not the user's to read. Anything else goes to the previous hook."""
    if (isinstance(unraisable.exc_value, UnicodeDecodeError)
            and unraisable.object is _skip_comment):
        return
    _previous_unraisablehook(unraisable)


_previous_unraisablehook = sys.unraisablehook
sys.unraisablehook = _quiet_undecodable_rows


def _is_comment(line: str | bytes) -> bool:
    return line.lstrip().startswith("#" if isinstance(line, str) else b"#")


def _skip_comment(row) -> str:
    """pyarrow's handler of a row with the wrong number of fields: a comment line is skipped,
    anything else is an error (named by :func:`_locate`). A 'row' spanning lines (a quote
    opened in a comment) is an error too: skipping it would drop the data rows inside."""
    try:
        text = row.text or ""
    except UnicodeDecodeError:  # not UTF-8: refused, with its line (see _not_utf8)
        return "error"
    if not text.strip():  # spaces or a tab only: a blank line to any editor (and to _locate)
        return "skip"
    return "skip" if _is_comment(text) and "\n" not in text else "error"


_PLUS = re.compile(rb"(?:(?<=^)|(?<=[,;\t| ]))\+(?=[0-9.])")
"""A '+' that opens a number in a field (``+190972``): pyarrow's integer parser refuses it
(its float parser takes it); the fallback reader drops it. Not the '+' of an exponent
(``1e+05``: preceded by 'e')."""


class _Uncommented(io.RawIOBase):
    """The file without the comment lines after its header, and without the '+' that opens
    a number (:data:`_PLUS`), for pyarrow (the fallback when its own parse cannot skip them;
    see the module's docstring). The lines up to the header stay as they are, so
    ``skip_rows`` and every line number still hold."""

    def __init__(self, path: Path, keep: int) -> None:
        self._f = open(path, "rb")  # noqa: SIM115 - closed by close()
        self._buf = b"".join(self._f.readline() for _ in range(keep))
        self._pos = 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        while self._pos >= len(self._buf):
            lines = self._f.readlines(1 << 20)
            if not lines:
                return 0
            self._buf = b"".join(_PLUS.sub(b"", ln) for ln in lines if not _is_comment(ln))
            self._pos = 0
        n = min(len(b), len(self._buf) - self._pos)
        b[:n] = self._buf[self._pos:self._pos + n]
        self._pos += n
        return n

    def close(self) -> None:
        self._f.close()
        super().close()


def _may_have_comments(path: Path, h: _Header) -> bool:
    """Whether a '#' (a comment) or a '+' (a signed number) follows the header anywhere (a
    byte search, memchr speed): if not, a file pyarrow refused has a bad row, not a comment,
    and is not read again."""
    with open(path, "rb") as f:
        for _ in range(h.skip):
            f.readline()
        while block := f.read(1 << 22):
            if b"#" in block or b"+" in block:
                return True
    return False


def _commented_labels(h: _Header, spec: TableSpec, columns: Mapping[str, pa.Array]) -> bool:
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


def _arrow_options(path: Path, spec: TableSpec, h: _Header, block_bytes: int | None,
                   threads: bool) -> tuple:
    kinds = {c.name: c.kind for c in spec.columns}
    cols = [n if n else f"_ignored_{i}" for i, n in enumerate(h.names)]
    ro = pacsv.ReadOptions(column_names=cols, skip_rows=h.skip, use_threads=threads,
                           encoding="utf8", **({"block_size": block_bytes} if block_bytes
                                               else {}))
    po = pacsv.ParseOptions(delimiter=h.delimiter, invalid_row_handler=_skip_comment)
    co = pacsv.ConvertOptions(column_types={n: _ARROW[kinds[n]] for n in h.names if n},
                              include_columns=[n for n in h.names if n],
                              null_values=[""], strings_can_be_null=True,
                              quoted_strings_can_be_null=True)
    return ro, po, co


# ----------------------------------------------------------------------------- errors

def _row_lines(path: Path, first_line: int, rows: list[int]) -> list[int]:
    """File line numbers of data rows (blank lines are not rows)."""
    want = sorted(set(rows))
    found: dict[int, int] = {}
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        for _ in range(first_line - 1):
            next(f, None)
        row = 0
        for ln, line in enumerate(f, start=first_line):
            if not line.strip() or _is_comment(line):
                continue
            if row in want:
                found[row] = ln
                if len(found) == len(want):
                    break
            row += 1
    return [found.get(r, -1) for r in rows]


def _not_utf8(path: Path, spec: TableSpec) -> InputError | None:
    """The first line that is not UTF-8 text, as the error naming it (None if there is none).
    Only on the error paths: the parser itself does not check the bytes of lines it skips
    (comments) and names no line for a cell it cannot decode."""
    with open(path, "rb") as f:
        for ln, raw in enumerate(f, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                byte = raw[exc.start]
                return InputError(f"{path}:{ln}: not a UTF-8 text file (byte 0x{byte:02X} at "
                                  f"column {exc.start + 1}): a {spec.what} is UTF-8 CSV; save "
                                  "it as UTF-8")
    return None


def _refused(path: Path, spec: TableSpec, h: _Header, retry_without_comments: bool
             ) -> InputError | None:
    """After pyarrow refused the file: the error naming the first line that is not valid, or
    None when a read without the comment lines may still succeed (``retry_without_comments``
    and the file has '#' after its header and is UTF-8 throughout)."""
    bad = _not_utf8(path, spec)
    if bad is not None:
        return bad
    if retry_without_comments and _may_have_comments(path, h):
        return None
    return _locate(path, spec, h)


def _locate(path: Path, spec: TableSpec, h: _Header) -> InputError:
    """Slow path, only after pyarrow refused a UTF-8 file: the first row that is not
    valid."""
    kinds = {c.name: c.kind for c in spec.columns}
    n = len(h.names)
    with open(path, encoding="utf-8-sig", newline="") as f:
        for _ in range(h.skip):
            next(f)
        for ln, line in enumerate(f, start=h.skip + 1):
            if not line.strip() or _is_comment(line):
                continue
            row = next(csv.reader([line.rstrip("\r\n")], delimiter=h.delimiter))
            if len(row) != n:
                return InputError(f"{path}:{ln}: {len(row)} fields, the header has {n}"
                                  " (truncated line or a stray delimiter?)")
            for name, v in zip(h.names, row, strict=True):
                if not name:
                    continue
                bad = _bad_value(v.strip(), kinds[name])
                if bad:
                    return InputError(f"{path}:{ln}: {name}: {_show_cell(v.strip())} {bad}")
    return InputError(f"{path}: not a valid {spec.what} (pyarrow refused it, no line found)")


def _bad_value(v: str, kind: str) -> str:
    if kind == "label":
        return "" if v else "is blank: every row needs a label"
    try:
        x = float(v)
    except ValueError:
        if "," in v:
            return "is not a number (a decimal comma? write 1.5, not 1,5)"
        return "is not a number" if v else "is empty"
    if not np.isfinite(x):
        return "is not a finite number"
    if kind == "int" and x != int(x):
        return "is not a whole number"
    if kind == "int":
        try:
            k = int(v)
        except ValueError:
            return "is not written as a whole number"
        if not -(1 << 63) <= k < 1 << 63:
            return "is beyond a 64-bit integer"
    return ""


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


def _table(path: Path, spec: TableSpec, h: _Header, columns: Mapping[str, pa.Array],
           row0: int = 0) -> Table:
    kinds = {c.name: c.kind for c in spec.columns}
    data = {}
    for n, col in columns.items():
        if col.null_count:
            rows = np.flatnonzero(np.asarray(col.is_null()))
            t = Table(path, spec, {}, h.skip + 1, row0=row0)
            what = ("is blank: every row needs a label" if kinds[n] == "label"
                    else "is empty")
            raise t.fail(int(rows[0]), n, what)
        data[n] = _numpy(col, kinds[n])
    ignored = tuple(r.strip() for r, n in zip(h.raw, h.names, strict=True) if not n)
    data, units = _in_own_units(path, spec, h, data)
    return Table(path, spec, data, h.skip + 1, ignored, units, row0=row0)


def _in_own_units(path: Path, spec: TableSpec, h: _Header, data: dict[str, np.ndarray]
                  ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The columns whose header declares a unit (``t [ms]``, ``ux [mg]``) converted to the
    tool's own (seconds; g, m/s², V, counts) by the one table in :mod:`axisbase.units`; the
    units as they now are. A time in a unit that is not one is refused by name."""
    units = dict(h.units)
    for n, u in h.units.items():
        if n not in data or data[n].dtype.kind != "f" or not u.strip():
            continue
        if n == spec.time:
            scale = time_scale(u)
            if scale is None:
                raise InputError(f"{path}:{h.header_line}: {n}: time unit {u!r} not known; "
                                 f"use one of s, ms, us, ns, min, h")
            unit = "s"
        else:
            vu = value_unit(u)
            if vu is None:
                continue  # temperature [°C] and the like: carried, not converted
            unit, scale = vu
        if scale != 1.0:
            data[n] = data[n] * scale
        units[n] = unit
    return data, units


def read_table(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None = None,
               rate_hz: float | None = None) -> Table:
    """Read a whole table.

    Parameters
    ----------
    path : the file.
    spec : its format.
    columns : canonical name -> header name, for headers the format does not know.
    rate_hz : sample rate [Hz] for a file without the time column: row k gets t = k / rate.

    Raises
    ------
    InputError
        naming the file, the line, the column and what is wrong.
    """
    path = Path(path)
    h = _read_header(path, spec, columns or {})
    ro, po, co = _arrow_options(path, spec, h, None, threads=True)
    try:
        at = pacsv.read_csv(path, read_options=ro, parse_options=po, convert_options=co)
        again = _commented_labels(h, spec, dict(zip(at.column_names, at.columns, strict=True)))
    except pa.ArrowInvalid:
        err = _refused(path, spec, h, retry_without_comments=True)
        if err is not None:
            raise err from None
        again = True
    if again:
        try:
            with _Uncommented(path, h.skip) as src:
                at = pacsv.read_csv(io.BufferedReader(src), read_options=ro, parse_options=po,
                                    convert_options=co)
        except pa.ArrowInvalid:
            raise _refused(path, spec, h, retry_without_comments=False) from None
    if at.num_rows == 0:
        raise InputError(f"{path}: the header has no rows under it (a {spec.what} needs data)")
    table = _table(path, spec, h, {n: at.column(n) for n in at.column_names})
    table = _with_rate(table, rate_hz)
    _check(table)
    if spec.distinct_rows:
        check_repeats(table)
    warning = rate_warning(table)
    if warning:
        import logging

        logging.getLogger("align").warning("WARNING: %s", warning)
    return table


def rate_warning(table: Table) -> str | None:
    """A sentence when the table's median sample interval (within a pose, if labelled) is
    implausible for its sensor (``spec.rate_hz_range``), naming the time unit that would make
    it plausible (times in ms under a plain ``t``: a 20 Hz recording read as 0.02 Hz)."""
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
              if fits else "")
    return (f"{table.path}: {spec.time}: median sample interval {dt:g} {unit} "
            f"({1.0 / dt:.3g} Hz) is implausible for a {spec.what} ({lo:g} Hz to {hi:g} Hz)"
            f"{likely}")


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
    check."""
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


OUTPUT_UNITS = {"g": "g/g", "m/s2": "(m/s²)/g", "counts": "counts/g", "V": "V/g"}
"""Output unit of an accelerometer -> the unit of its scale factor (per g of input)."""


def header_units(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None,
                 names: tuple[str, ...]) -> str | None:
    """The output unit written in the header for ``names`` (e.g. ``ux [V]``), normalised to
    a key of :data:`OUTPUT_UNITS`; None when none is written. Different units for different
    axes, or a unit the tool does not know, are refused."""
    h = _read_header(Path(path), spec, columns or {})
    found = {n: h.units[n] for n in names if n in h.units}
    if not found:
        return None
    keys = {n: (value_unit(u) or (None,))[0] for n, u in found.items()}
    bad = [n for n, k in keys.items() if k is None]
    if bad:
        raise InputError(f"{path}:{h.header_line}: {bad[0]}: unit {found[bad[0]]!r} not "
                         f"known; use one of {', '.join(OUTPUT_UNITS)} (or mg, µg, mm/s2, "
                         "mV: converted)")
    if len(set(keys.values())) > 1:
        raise InputError(f"{path}:{h.header_line}: header: the axes are in different units "
                         f"({', '.join(f'{n} [{u}]' for n, u in found.items())})")
    return next(iter(keys.values()))


def resolve_units(given: str | None, paths: list[str | Path], spec: TableSpec,
                  columns: Mapping[str, str] | None, names: tuple[str, ...],
                  flag: str = "--units", default: str | None = "V") -> str | None:
    """The output unit of the data: ``given`` (the flag/key) checked against the units
    written in the headers of ``paths``; else the header's; else ``default``."""
    if given is not None and given not in OUTPUT_UNITS:
        raise InputError(f"{flag} {given!r}: one of {', '.join(OUTPUT_UNITS)}")
    unit = given
    for p in paths:
        hu = header_units(p, spec, columns, names)
        if hu is None:
            continue
        if unit is not None and hu != unit:
            src = flag if given is not None else "another file's header"
            raise InputError(f"{p}: the header says {hu}, {src} says {unit}")
        unit = hu
    return unit or default


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
                 table.row0)


def iter_table(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None = None,
               block_bytes: int = 1 << 20, parallel: bool = False) -> Iterator[Table]:
    """Read a table in chunks of about ``block_bytes`` of text, each a checked :class:`Table`
    (a time column is checked across chunk boundaries too). Memory stays flat in the file's
    length: 1 MiB blocks kept Arrow's pool at 41 MB for 2·10⁶ and 6·10⁶ rows.

    ``parallel``: parse on a pool of threads (see :func:`_parallel_batches`); for tables of
    numbers only (a label could hold a quoted line break, which only a serial parse follows).
    """
    if parallel and any(c.kind == "label" for c in spec.columns):
        raise ValueError("iter_table(parallel=True) is for tables of numbers only")
    path = Path(path)
    h = _read_header(path, spec, columns or {})
    ro, po, co = _arrow_options(path, spec, h, block_bytes, threads=False)
    row0 = 0
    prev_t = None
    empty = True
    for filtered in (False, True):
        # The file as it is; then, only if pyarrow met a comment it could not skip, the file
        # without its comment lines, from the top, past the rows already given.
        done = row0
        try:
            source = io.BufferedReader(_Uncommented(path, h.skip)) if filtered else path
            batches = (_parallel_batches(path, h, ro, po, co) if parallel and not filtered
                       else _batches(source, ro, po, co))
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
                empty = False
                chunk = _table(path, spec, h, cols, row0)
                _check(chunk, prev_t)
                if spec.time and spec.time in chunk.data:
                    prev_t = float(chunk.data[spec.time][-1])
                row0 += len(chunk)
                yield chunk
            break
        except (pa.ArrowInvalid, _Commented):
            err = _refused(path, spec, h, retry_without_comments=not filtered)
            if err is not None:
                raise err from None
    if empty:
        raise InputError(f"{path}: the header has no rows under it (a {spec.what} needs data)")


class _Commented(Exception):
    """A comment line parsed as a row (see :func:`_commented_labels`): read again."""


def _batches(source, ro, po, co) -> Iterator[dict[str, pa.Array]]:
    reader = pacsv.open_csv(source, read_options=ro, parse_options=po, convert_options=co)
    try:
        for batch in reader:
            yield dict(zip(batch.schema.names, batch.columns, strict=True))
    finally:
        if not isinstance(source, str | Path):
            source.close()


# Text per parse task, and tasks in flight: 2 workers and one block ready ahead keep both
# cores busy; memory is ~4 x (2 MiB of text + its columns), whatever the file's length (4 MiB
# blocks: 19 MB more at the peak of a 10⁷-row log, no faster).
PARALLEL_BLOCK = 2 << 20
PARALLEL_WORKERS = 2
PARALLEL_AHEAD = 3


def _text_blocks(path: Path, skip: int, size: int) -> Iterator[bytes]:
    """The file after its first ``skip`` lines, in blocks of ~``size`` bytes cut after a line
    end (rows never span blocks: pyarrow's own parallel reader cuts the same way, values with
    line breaks not being allowed)."""
    with open(path, "rb") as f:
        for _ in range(skip):
            f.readline()
        while block := f.read(size):
            if not block.endswith(b"\n"):
                block += f.readline()
            yield block


def _parallel_batches(path: Path, h: _Header, ro, po, co) -> Iterator[dict[str, pa.Array]]:
    """Like :func:`_batches`, parsed on ``PARALLEL_WORKERS`` threads: blocks of text cut at
    line ends, each parsed whole by ``pyarrow.csv.read_csv`` (which releases the GIL), handed
    on in file order as record batches of about ``ro.block_size`` bytes of text. pyarrow's
    streaming reader parses one block at a time; its whole-file ``read_csv`` holds the whole
    table (0.9 GB for a 10⁷-row log). A file with lone carriage returns as line ends is read
    serially (it is not cut at lines here)."""
    from concurrent.futures import ThreadPoolExecutor

    ro1 = pacsv.ReadOptions(column_names=ro.column_names, skip_rows=0, use_threads=False,
                            encoding=ro.encoding, block_size=min(PARALLEL_BLOCK * 2, 1 << 30))
    with open(path, "rb") as f:
        head = f.read(PARALLEL_BLOCK)
    if head.count(b"\r") != head.count(b"\r\n"):
        yield from _batches(path, ro, po, co)
        return

    def parse(text: bytes) -> tuple[pa.Table, int]:
        return pacsv.read_csv(pa.py_buffer(text), read_options=ro1, parse_options=po,
                              convert_options=co), len(text)

    pool = ThreadPoolExecutor(PARALLEL_WORKERS, thread_name_prefix="csv")
    pending: list = []
    try:
        for text in _text_blocks(path, h.skip, PARALLEL_BLOCK):
            pending.append(pool.submit(parse, text))
            if len(pending) < PARALLEL_AHEAD:
                continue
            yield from _pieces(*pending.pop(0).result(), ro.block_size)
        for fut in pending:
            yield from _pieces(*fut.result(), ro.block_size)
        pending = []
    finally:
        for fut in pending:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)


def _pieces(table: pa.Table, text_bytes: int, block_bytes: int
            ) -> Iterator[dict[str, pa.Array]]:
    """A parsed block (of ``text_bytes`` of text) as batches of about ``block_bytes`` of text
    (zero-copy slices): the consumer's temporaries stay cache-sized."""
    table = table.combine_chunks()
    rows = table.num_rows
    if not rows:
        return
    step = max(1, rows * block_bytes // text_bytes)
    for s in range(0, rows, step):
        part = table.slice(s, step)
        yield {name: part.column(name).chunk(0) for name in part.column_names}
