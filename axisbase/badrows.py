"""Rows pyarrow's parser cannot take as they are, and the error that names a bad line.

pyarrow has no comment character: a comment line after the header has (almost always) the
wrong number of fields and :func:`skip_comment` (its ``invalid_row_handler``) skips it; a file
with comments the parser cannot tell from rows, or with numbers written ``+190972``, is read
again through :class:`Uncommented`. When pyarrow refuses a file, :func:`refused` scans it once
more with Python's csv module to name the line, the column and what is wrong
(``file:line: column: what``).
"""

from __future__ import annotations

import csv
import io
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from axisbase.errors import InputError
from axisbase.header import Header, not_utf8, show_cell

if TYPE_CHECKING:
    from axisbase.tablespec import TableSpec


def _quiet_undecodable_rows(unraisable) -> None:
    """pyarrow decodes an invalid row's text (e.g. a comment line) before it calls the
    handler; a line that is not UTF-8 fails there and pyarrow prints it as 'Exception
    ignored' with a traceback. The file is refused anyway, naming that line (not_utf8):
    the traceback is not the user's to read. Anything else goes to the previous hook."""
    if (isinstance(unraisable.exc_value, UnicodeDecodeError)
            and unraisable.object is skip_comment):
        return
    _previous_unraisablehook(unraisable)


_previous_unraisablehook = sys.unraisablehook
sys.unraisablehook = _quiet_undecodable_rows


def is_comment(line: str | bytes) -> bool:
    return line.lstrip().startswith("#" if isinstance(line, str) else b"#")


def skip_comment(row) -> str:
    """pyarrow's handler of a row with the wrong number of fields: a comment line is skipped,
    anything else is an error (named by :func:`locate`). A 'row' spanning lines (a quote
    opened in a comment) is an error too: skipping it would drop the data rows inside."""
    try:
        text = row.text or ""
    except UnicodeDecodeError:  # not UTF-8: refused, with its line (see not_utf8)
        return "error"
    if not text.strip():  # spaces or a tab only: a blank line to any editor (and to locate)
        return "skip"
    return "skip" if is_comment(text) and "\n" not in text else "error"


_PLUS = re.compile(rb"(?:(?<=^)|(?<=[,;\t| ]))\+(?=[0-9.])")
"""A '+' that opens a number in a field (``+190972``): pyarrow's integer parser refuses it
(its float parser takes it); the fallback reader drops it. Not the '+' of an exponent
(``1e+05``: preceded by 'e')."""


class Uncommented(io.RawIOBase):
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
            self._buf = b"".join(_PLUS.sub(b"", ln) for ln in lines if not is_comment(ln))
            self._pos = 0
        n = min(len(b), len(self._buf) - self._pos)
        b[:n] = self._buf[self._pos:self._pos + n]
        self._pos += n
        return n

    def close(self) -> None:
        self._f.close()
        super().close()


def may_have_comments(path: Path, h: Header) -> bool:
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


def row_lines(path: Path, first_line: int, rows: list[int]) -> list[int]:
    """File line numbers of data rows (blank lines are not rows)."""
    want = sorted(set(rows))
    found: dict[int, int] = {}
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        for _ in range(first_line - 1):
            next(f, None)
        row = 0
        for ln, line in enumerate(f, start=first_line):
            if not line.strip() or is_comment(line):
                continue
            if row in want:
                found[row] = ln
                if len(found) == len(want):
                    break
            row += 1
    return [found.get(r, -1) for r in rows]


def refused(path: Path, spec: TableSpec, h: Header, retry_without_comments: bool
             ) -> InputError | None:
    """After pyarrow refused the file: the error naming the first line that is not valid, or
    None when a read without the comment lines may still succeed (``retry_without_comments``
    and the file has '#' after its header and is UTF-8 throughout)."""
    bad = not_utf8(path, spec)
    if bad is not None:
        return bad
    if retry_without_comments and may_have_comments(path, h):
        return None
    return locate(path, spec, h)


def locate(path: Path, spec: TableSpec, h: Header) -> InputError:
    """Slow path, only after pyarrow refused a UTF-8 file: the first row that is not
    valid."""
    kinds = {c.name: c.kind for c in spec.columns}
    n = len(h.names)
    with open(path, encoding="utf-8-sig", newline="") as f:
        for _ in range(h.skip):
            next(f)
        for ln, line in enumerate(f, start=h.skip + 1):
            if not line.strip() or is_comment(line):
                continue
            row = next(csv.reader([line.rstrip("\r\n")], delimiter=h.delimiter))
            if len(row) != n:
                return InputError(f"{path}:{ln}: {len(row)} fields, the header has {n}"
                                  " (truncated line or a stray delimiter?)")
            for name, v in zip(h.names, row, strict=True):
                if not name:
                    continue
                bad = bad_value(v.strip(), kinds[name])
                if bad:
                    return InputError(f"{path}:{ln}: {name}: {show_cell(v.strip())} {bad}")
    return InputError(f"{path}: not a valid {spec.what} (pyarrow refused it, no line found)")


def bad_value(v: str, kind: str) -> str:
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
