"""What every JSON file and report carries about how it was made, and the format check on
reading one back.

A written result has, at the top level, ``format`` (what kind of file it is, e.g.
``axis-align/calibration``), ``format_version`` (an integer raised whenever a reader of the
previous version would misread the file) and the provenance keys of :class:`Provenance`:
``tool``, ``tool_version``, ``created_utc``, ``command``, ``settings`` and ``inputs`` (path,
SHA-256 and size of every input file). Format versions 1 and 2 (before this layout) nested
the same facts in a ``provenance`` block; :meth:`Provenance.from_dict` reads both.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from axisbase.errors import InputError
from axisbase.version import TOOL, __version__

_COMMAND: list[list[str]] = []

PROVENANCE_KEYS = ("tool", "tool_version", "created_utc", "command", "settings", "inputs")
"""The top-level keys :meth:`Provenance.to_dict` writes (format version 3 and later)."""


def set_command(argv: Iterable[str] | None) -> None:
    """Record the command line of this run (the CLI calls it once, and with None at its end:
    then :func:`command_line` is this process's ``sys.argv`` again)."""
    _COMMAND[:] = [] if argv is None else [list(argv)]


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


@dataclass(frozen=True)
class InputFile:
    """One input of a run: its path as given, SHA-256 (hex) and size [bytes]; both None when
    the file could not be read when the result was written."""

    path: str
    sha256: str | None
    bytes: int | None

    @classmethod
    def of(cls, path: str | Path) -> InputFile:
        p = Path(path)
        try:
            return cls(str(p), sha256_file(p), p.stat().st_size)
        except OSError:
            return cls(str(p), None, None)


@dataclass(frozen=True)
class Provenance:
    """How a result was made.

    Attributes
    ----------
    tool, tool_version : str
        The program and its version; unit —.
    created_utc : str
        When the result was made, ISO 8601 UTC to the second (``...Z``); unit —.
    command : tuple of str
        The command line, one string per argument; unit —.
    settings : Mapping
        The settings that shaped the result (α, seeds, flags), JSON values, each in the unit
        its name says; unit —.
    inputs : tuple of InputFile
        Every input file with its SHA-256 and size [bytes].
    """

    tool: str = TOOL
    tool_version: str = __version__
    created_utc: str = field(default_factory=utc_now)
    command: tuple[str, ...] = field(default_factory=lambda: tuple(command_line()))
    settings: Mapping[str, Any] = field(default_factory=dict)
    inputs: tuple[InputFile, ...] = ()

    @classmethod
    def now(cls, settings: Mapping[str, Any] | None = None,
            inputs: Iterable[str | Path] = ()) -> Provenance:
        """This run's provenance (hashes every input once)."""
        return cls(settings=dict(settings or {}), inputs=tuple(InputFile.of(p) for p in inputs))

    def to_dict(self) -> dict:
        return {"tool": self.tool, "tool_version": self.tool_version,
                "created_utc": self.created_utc, "command": list(self.command),
                "settings": dict(self.settings),
                "inputs": [{"path": i.path, "sha256": i.sha256, "bytes": i.bytes}
                           for i in self.inputs]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Provenance:
        """From a result's top level (version ≥ 3) or its ``provenance`` block (1–2; files
        of version 1 without one give an empty provenance)."""
        old = d.get("provenance")
        if isinstance(old, Mapping):
            d = {"tool": old.get("tool", TOOL), "tool_version": old.get("version", ""),
                 "created_utc": old.get("written_utc", ""),
                 "command": old.get("command_line", []), "settings": old.get("settings", {}),
                 "inputs": old.get("inputs", [])}
        return cls(tool=str(d.get("tool", TOOL)), tool_version=str(d.get("tool_version", "")),
                   created_utc=str(d.get("created_utc", "")),
                   command=tuple(str(a) for a in d.get("command", ())),
                   settings=dict(d.get("settings", {})),
                   inputs=tuple(InputFile(str(i["path"]), i.get("sha256"), i.get("bytes"))
                                for i in d.get("inputs", ())))


def provenance(settings: Mapping[str, Any] | None = None,
               inputs: Iterable[str | Path] = ()) -> Provenance:
    """This run's provenance.

    Parameters
    ----------
    settings : mapping, optional
        The settings that shaped the result (α, seeds, flags), JSON values.
    inputs : iterable of str or Path
        Input files (hashed with SHA-256).

    Returns
    -------
    Provenance
        Tool, version, UTC time, command, settings, inputs.
    """
    return Provenance.now(settings, inputs)


def envelope(fmt: str, version: int, body: Mapping[str, Any],
             settings: Mapping[str, Any] | None = None,
             inputs: Iterable[str | Path] = (), prov: Provenance | None = None) -> dict:
    """A result ready to write: ``{format, format_version, <provenance keys>, **body}``.

    Parameters
    ----------
    fmt : str
        The format's name (``axis-align/gonio``).
    version : int
        Its version.
    body : mapping
        The result's own keys.
    settings : mapping, optional
        The settings that shaped the result.
    inputs : iterable of str or Path
        Input files (hashed).
    prov : Provenance, optional
        A provenance already made for the same run (inputs are hashed once).

    Returns
    -------
    dict
        The document.
    """
    p = prov if prov is not None else Provenance.now(settings, inputs)
    clash = set(PROVENANCE_KEYS).intersection(body)
    if clash:   # a body key would silently replace a provenance fact
        raise ValueError(f"result keys {sorted(clash)} are reserved for provenance")
    return {"format": fmt, "format_version": version, **p.to_dict(), **body}


def check_format(d: Mapping[str, Any], fmt: str, readable: Iterable[int], where: str,
                 unversioned: int | None = 1) -> int:
    """The format version of ``d`` if this tool can read it, else ``InputError`` saying which.

    Files written before versions existed carry no ``format_version``: they are version
    ``unversioned`` (None: refuse them).

    Parameters
    ----------
    d : mapping
        The document read.
    fmt : str
        The format expected.
    readable : iterable of int
        Versions this tool reads.
    where : str
        The file, for the message.
    unversioned : int or None
        The version of a file without ``format_version``.

    Returns
    -------
    int
        The version.

    Raises
    ------
    InputError
        Another format, or a version this tool cannot read.
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
