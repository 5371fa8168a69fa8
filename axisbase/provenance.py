"""What every JSON file and report carries about how it was made, and the format check on
reading one back.

A written result has, at the top level, ``format`` (what kind of file it is, e.g.
``axis-align/calibration``), ``format_version`` (an integer raised whenever a reader of the
previous version would misread the file) and ``provenance``: the tool and its version, the UTC
time, the command line, the settings and the SHA-256 of every input file.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from axisbase.errors import InputError
from axisbase.version import TOOL, __version__

_COMMAND: list[list[str]] = []


def set_command(argv: Iterable[str]) -> None:
    """Record the command line of this run (the CLI calls it once)."""
    _COMMAND[:] = [list(argv)]


def command_line() -> list[str]:
    return _COMMAND[0] if _COMMAND else list(sys.argv)


def sha256_file(path: str | Path, block: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(block):
            h.update(chunk)
    return h.hexdigest()


def utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace(
        "+00:00", "Z")


def provenance(settings: Mapping[str, Any] | None = None,
               inputs: Iterable[str | Path] = ()) -> dict:
    """The ``provenance`` block: tool, version, UTC time, command line, settings, inputs."""
    files = []
    for p in inputs:
        p = Path(p)
        try:
            files.append({"path": str(p), "sha256": sha256_file(p), "bytes": p.stat().st_size})
        except OSError:
            files.append({"path": str(p), "sha256": None, "bytes": None})
    return {"tool": TOOL, "version": __version__, "written_utc": utc_now(),
            "command_line": command_line(), "settings": dict(settings or {}),
            "inputs": files}


def envelope(fmt: str, version: int, body: Mapping[str, Any],
             settings: Mapping[str, Any] | None = None,
             inputs: Iterable[str | Path] = (), prov: dict | None = None) -> dict:
    """``{format, format_version, provenance, **body}``: a result ready to write. ``prov``:
    a provenance block already made for the same run (inputs are hashed once)."""
    return {"format": fmt, "format_version": version,
            "provenance": prov if prov is not None else provenance(settings, inputs), **body}


def check_format(d: Mapping[str, Any], fmt: str, readable: Iterable[int], where: str,
                 unversioned: int | None = 1) -> int:
    """The format version of ``d`` if this tool can read it, else ``InputError`` saying which.

    Files written before versions existed carry no ``format_version``: they are version
    ``unversioned`` (None: refuse them).
    """
    readable = sorted(readable)
    got_fmt = d.get("format")
    if got_fmt is not None and got_fmt != fmt:
        raise InputError(f"{where}: a {got_fmt!r} file, not {fmt!r}")
    v = d.get("format_version", unversioned)
    if v is None:
        raise InputError(f"{where}: no format_version: not a {fmt} file")
    if isinstance(v, bool) or not isinstance(v, int):
        raise InputError(f"{where}: format_version {v!r} is not an integer")
    if v not in readable:
        newer = v > readable[-1]
        raise InputError(f"{where}: {fmt} format version {v} "
                         + ("is newer than this tool (" if newer else "is not readable (")
                         + f"axis-align {__version__} reads versions "
                         + ", ".join(map(str, readable))
                         + (")" if not newer else "); update axis-align"))
    return v
