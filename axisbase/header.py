"""A table's header line: which column is which, and the units written in it.

The header is the first line that is neither blank nor a ``#`` comment. Its delimiter (``,``,
``;`` or tab) is the one it holds most of; each name is compared case- and
white-space-insensitively with the format's columns and their aliases (or with the name the
user maps, ``--columns ux=ax``), a unit in brackets allowed (``Ux [V]``, ``t (s)``). The units
written there are what :func:`header_units` reads for the accelerometer's output unit
(:data:`OUTPUT_UNITS`) and what the reader converts from.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from axisbase.errors import InputError
from axisbase.units import DECLARED_TIME_UNITS, time_scale, value_unit

if TYPE_CHECKING:
    from axisbase.tablespec import TableSpec

_UNIT = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")



@dataclass(frozen=True)
class Header:
    names: list[str]           # canonical name, or '' for a column the format does not know
    raw: list[str]             # as written
    units: dict[str, str]
    delimiter: str
    skip: int                  # lines before the first data row (comments + header)
    header_line: int
    meta: tuple[str, ...] = ()  # lines before the header that are not the table's (a logger's
    # metadata, e.g. "Fs,100"): skipped, and said in a note (see meta_note)


def _norm(text: str) -> tuple[str, str]:
    """'  Ux [V] ' -> ('ux', 'V'); quotes and surrounding white space dropped."""
    t = text.strip().strip('"').strip("'").strip()
    unit = ""
    m = _UNIT.match(t)
    if m:
        t, unit = m.group(1), m.group(2)
    return re.sub(r"\s+", "_", t.strip().lower()), unit


_SAFE = re.compile(r"^[\w .,\[\]()%/°²µ^+-]{0,24}$")


def show_header(raw: list[str]) -> str:
    """The header for a message — but never a file's contents: if a field does not look like
    a column name (e.g. the first line of a file that is not a table at all), only the number
    of fields is given."""
    names = [r.strip() for r in raw]
    if all(_SAFE.match(n) for n in names):
        return "(" + ", ".join(names) + ")"
    return f"({len(names)} field(s), not column names)"


def show_cell(v: str) -> str:
    """A bad cell for a message: short ones quoted, longer ones only described."""
    return repr(v) if _SAFE.match(v) and len(v) <= 16 else f"a {len(v)}-character text"


def parse_column_map(text: str | None, flag: str = "--columns") -> dict[str, str]:
    """``'ux=ax, uy=ay'`` -> ``{'ux': 'ax', 'uy': 'ay'}`` (canonical name = header name).

    Parameters
    ----------
    text : str or None
        The flag's or key's value.
    flag : str
        The flag (or session.toml key) it came from, for the messages.

    Returns
    -------
    dict of str to str
        Canonical name (lower case) -> header name (normalised as headers are).

    Raises
    ------
    InputError
        An item that is not NAME=HEADER, an empty side, a name mapped twice.
    """
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


MAX_META_LINES = 64
"""Lines before the header a logger may write (its settings: "Fs,100", "Logging Type,0")."""


def _header_lines(f) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are neither blank nor ``#`` comments, up to
    the first and MAX_META_LINES after it."""
    out = []
    for ln, line in enumerate(f, start=1):
        if line.strip() and not line.lstrip().startswith("#"):
            out.append((ln, line))
            if len(out) > MAX_META_LINES:
                break
    return out


def _fields(path: Path, ln: int, line: str, spec: TableSpec) -> tuple[str, list[str]]:
    text = line.rstrip("\r\n")
    if "\x00" in text:
        raise InputError(f"{path}:{ln}: NUL bytes in the header: UTF-16 text or a binary "
                         f"file? a {spec.what} is UTF-8 CSV text")
    delimiter = max(",;\t", key=text.count)
    return delimiter, next(csv.reader([text], delimiter=delimiter))


def read_header(path: Path, spec: TableSpec, mapping: Mapping[str, str],
                time_unit: str | None = None) -> Header:
    """The header of a table file: the first line that is neither blank nor a ``#`` comment
    — or, when that line lacks the format's columns, the first of the next MAX_META_LINES
    that has them (a logger's metadata lines before the header are then skipped; the
    :class:`Header` lists them for :func:`meta_note`).

    Parameters
    ----------
    path : Path
        The file.
    spec : TableSpec
        Its format.
    mapping : mapping of str to str
        Canonical name -> header name (``--columns``).
    time_unit : str, optional
        The time column's unit when the header says none (``--time-unit``, the session's
        ``time_unit``; a key of :data:`axisbase.units.TIME_UNITS`).

    Returns
    -------
    Header
        Names, units, delimiter and where the data start.

    Raises
    ------
    InputError
        No header, the columns not found, or a time unit the header contradicts, naming
        the file and line.
    """
    declare_time_unit({}, None, time_unit, str(path))  # an unknown unit: before the file
    try:
        with open(path, encoding="utf-8-sig", newline="") as f:
            lines = _header_lines(f)
        if not lines:
            raise InputError(f"{path}: empty file: expected a header line "
                             f"{spec.layout} ({spec.what})")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a {spec.what}") from None
    except PermissionError:
        raise InputError(f"{path}: not readable (permission denied)") from None
    except UnicodeDecodeError:
        raise (not_utf8(path, spec) or InputError(
            f"{path}: not a UTF-8 text file (a {spec.what} is CSV text)")) from None
    ln, line = lines[0]
    delimiter, raw = _fields(path, ln, line, spec)
    meta: tuple[str, ...] = ()
    try:
        names, units = match_names(raw, spec, mapping, f"{path}:{ln}: header")
    except InputError as first:
        # A logger's metadata before the header: the first later line that has the
        # format's columns (none: the first line's error stands).
        for k, (ln_k, line_k) in enumerate(lines[1:], start=1):
            d_k, raw_k = _fields(path, ln_k, line_k, spec)
            try:
                names, units = match_names(raw_k, spec, mapping, f"{path}:{ln_k}: header")
            except InputError:
                continue
            meta = tuple(x.rstrip("\r\n") for _, x in lines[:k])
            ln, delimiter, raw = ln_k, d_k, raw_k
            break
        else:
            raise first from None
    time = spec.time if spec.time in names else None
    units = declare_time_unit(units, time, time_unit, f"{path}:{ln}")
    return Header(names, raw, units, delimiter, ln, ln, meta)


def declare_time_unit(units: Mapping[str, str], time: str | None, time_unit: str | None,
                      where: str) -> dict[str, str]:
    """The units of a header (or of rows in memory) with a declared time unit applied: the
    one rule for ``--time-unit`` / ``time_unit`` of every command that reads times.

    Parameters
    ----------
    units : mapping of str to str
        Canonical name -> the unit written with it.
    time : str or None
        The time column's canonical name, None when the table has none (nothing to do).
    time_unit : str or None
        The declared unit (a key of :data:`axisbase.units.TIME_UNITS`), None if none.
    where : str
        What a refusal names (``'log.csv:1'``).

    Returns
    -------
    dict of str to str
        ``units``, the time column's unit set to ``time_unit`` when the header says none.

    Raises
    ------
    InputError
        ``time_unit`` not a time unit, or the header saying another one (naming ``where``,
        the column and the flag/key).
    """
    if time_unit is not None and time_scale(time_unit) is None:
        raise InputError(f"--time-unit / time_unit {time_unit!r}: not a time unit; one of "
                         f"{', '.join(DECLARED_TIME_UNITS)}")
    if time_unit is None or time is None:
        return dict(units)
    said = units.get(time)
    if said is None:
        return {**units, time: time_unit}
    if time_scale(said) != time_scale(time_unit):
        raise InputError(f"{where}: {time}: the header says [{said}], the declared "
                         f"time unit (--time-unit / time_unit) says {time_unit}: give "
                         "one or make them agree")
    return dict(units)


def meta_note(path: Path, h: Header) -> str | None:
    """A sentence saying which lines before the header were skipped (None if none).

    Parameters
    ----------
    path : Path
        The file.
    h : Header
        Its header.

    Returns
    -------
    str or None
        The note.
    """
    if not h.meta:
        return None
    shown = "; ".join(show_header(next(csv.reader([m], delimiter=h.delimiter)))
                      for m in h.meta[:4])
    more = f" and {len(h.meta) - 4} more" if len(h.meta) > 4 else ""
    return (f"{path}: {len(h.meta)} line(s) before the header at line {h.header_line} "
            f"skipped as the logger's metadata, not rows: {shown}{more}")


def match_names(raw: list[str], spec: TableSpec, mapping: Mapping[str, str], where: str
                ) -> tuple[list[str], dict[str, str]]:
    """Which of the names ``raw`` (a header line's fields, or the keys of rows in memory) is
    which column of ``spec``, and the units written with them.

    Parameters
    ----------
    raw : list of str
        The names as written (``'Ux [V]'``).
    spec : TableSpec
        The format.
    mapping : mapping of str to str
        Canonical name -> name as written (``--columns``).
    where : str
        What the messages name (``'log.csv:1: header'``).

    Returns
    -------
    names : list of str
        Canonical name of each field, '' for one the format does not know.
    units : dict of str to str
        Canonical name -> the unit written with it.

    Raises
    ------
    InputError
        A column given twice, a mapped name not there, a required column missing.
    """
    normed = [_norm(r) for r in raw]
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
                             f"{show_header([raw[i] for i in hits])}")
        if hits:
            if names[hits[0]]:
                raise InputError(f"{where}: {raw[hits[0]].strip()!r} would be both "
                                 f"{names[hits[0]]} and {col.name}")
            names[hits[0]] = col.name
        elif col.name in mapping:
            raise InputError(f"{where}: --columns {col.name}={mapping[col.name]}: no such "
                             f"column in the header {show_header(raw)}")
    missing = [c.name for c in spec.columns if c.required and c.name not in names]
    if missing:
        raise InputError(f"{where}: {show_header(raw)} lacks {', '.join(missing)}; a "
                         f"{spec.what} has "
                         f"{spec.layout} (name other headers with --columns, e.g. "
                         f"{missing[0]}=YOUR_NAME)")
    units = {n: u for n, (_, u) in zip(names, normed, strict=True) if n and u}
    return names, units


def not_utf8(path: Path, spec: TableSpec) -> InputError | None:
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


OUTPUT_UNITS = {"g": "g/g", "m/s2": "(m/s²)/g", "counts": "counts/g", "V": "V/g"}
"""Output unit of an accelerometer -> the unit of its scale factor (per g of input)."""


def header_units(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None,
                 names: tuple[str, ...]) -> str | None:
    """The output unit written in the header for ``names`` (e.g. ``ux [V]``), normalised to
    a key of :data:`OUTPUT_UNITS`; None when none is written. Different units for different
    axes, or a unit the tool does not know, are refused.

    Parameters
    ----------
    path : str or Path
        The file.
    spec : TableSpec
        Its format.
    columns : mapping of str to str, optional
        Canonical name -> header name.
    names : tuple of str
        The columns whose unit is the output's (``('ux', 'uy', 'uz')``).

    Returns
    -------
    str or None
        A key of :data:`OUTPUT_UNITS`, or None.

    Raises
    ------
    InputError
        A unit not known, or different units on different axes.
    """
    h = read_header(Path(path), spec, columns or {})
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
    written in the headers of ``paths``; else the header's; else ``default``.

    Parameters
    ----------
    given : str or None
        The unit the user gave (a key of :data:`OUTPUT_UNITS`).
    paths : list of str or Path
        The files whose headers may say it.
    spec : TableSpec
        Their format.
    columns : mapping of str to str, optional
        Canonical name -> header name.
    names : tuple of str
        The columns whose unit is the output's.
    flag : str
        The flag (or session.toml key) ``given`` came from, for the messages.
    default : str or None
        The unit when nobody says one.

    Returns
    -------
    str or None
        A key of :data:`OUTPUT_UNITS` (or ``default``).

    Raises
    ------
    InputError
        A unit not known, or the flag and a header (or two headers) disagreeing.
    """
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
