"""The files ``align`` writes: their format names and versions, the envelope every one
carries (:mod:`axisbase.provenance`) and the JSON Schema shipped for each.

A format version is raised whenever a reader of the previous version would misread a file.
Version 1 is every file written before versions existed (no ``format_version`` key); readers
that accept it say so in ``READABLE``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from align.errors import InputError
from axisbase.provenance import Provenance, check_format, envelope

FORMATS = {
    "marks": 3, "camera": 6, "calibration": 3, "tilt": 3, "gonio": 4, "session": 5,
    "platform-calibration": 3, "lot": 1, "plan": 1,
}
"""kind -> the version this tool writes."""

INPUT_SCHEMAS = {"session-toml": "session.toml"}
"""Schemas of files the tool reads (not writes; no envelope): ``align check`` validates a
session.toml against ``session-toml.schema.json``, and an editor can complete it from there
(the ``#:schema`` line 'align init' writes)."""

READABLE = {
    "calibration": (1, 2, 3),            # 'align tilt --calibration'
    "platform-calibration": (1, 2, 3),   # 'align apply'
    "session": (1, 2, 3, 4, 5),           # 'align apply' on a result JSON
}
"""kind -> versions this tool reads back. Version 3 moved the provenance from a nested
``provenance`` block to the top level (``tool_version``, ``created_utc``, ``command``,
``inputs``); nothing a reader uses changed. Session version 4: the top-level ``estimate``
and ``u`` of a fusion effect with ``components`` (the table's tilt) are its vector's length
(version 3: the component furthest from 0 in its u); nothing this tool reads changed.
Session version 5: ``problem_codes``, the code of each line of ``problems``
(:mod:`align.problem_codes`); an older result's problems read as ``unknown`` (not ok
whatever the tolerance, as they were)."""


def format_name(kind: str) -> str:
    return f"axis-align/{kind}"


def document(kind: str, body: Mapping[str, Any], settings: Mapping[str, Any] | None = None,
             inputs: Iterable[str | Path] = (), prov: Provenance | None = None) -> dict:
    """``body`` wrapped with format, format_version and provenance (tool, version, UTC time,
    command line, settings, SHA-256 of every input; ``prov`` reuses one already made)."""
    return envelope(format_name(kind), FORMATS[kind], body, settings, inputs, prov)


def check(d: Mapping[str, Any], kind: str, where: str) -> int:
    """The format version of ``d`` if readable as ``kind`` (``InputError`` saying which
    versions this tool reads otherwise)."""
    return check_format(d, format_name(kind), READABLE.get(kind, (FORMATS[kind],)), where)


def schema(kind: str) -> dict:
    """The JSON Schema of ``kind`` (package data ``align/schemas/<kind>.schema.json``). Every
    one refers to ``envelope.schema.json`` (format and provenance keys) by ``$ref``."""
    text = resources.files("align").joinpath("schemas", f"{kind}.schema.json").read_text()
    return json.loads(text)


def validate(d: Mapping[str, Any], kind: str) -> None:
    """Validate ``d`` against the shipped schema of ``kind`` (with the envelope it refers to);
    raises ``jsonschema.ValidationError``. Needs the ``jsonschema`` package (the ``test``
    extra), which the tool itself does not."""
    import jsonschema
    from referencing import Registry, Resource

    env = schema("envelope")
    registry = Registry().with_resource(env["$id"], Resource.from_contents(env))
    jsonschema.Draft202012Validator(schema(kind), registry=registry).validate(d)


def read_json(path: str | Path, what: str) -> dict:
    """A JSON object from a file (``InputError`` naming the file otherwise)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a folder, not {what}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: not JSON ({type(exc).__name__} at position "
                         f"{getattr(exc, 'pos', getattr(exc, 'start', '?'))})") from None
    if not isinstance(d, dict):
        raise InputError(f"{p}: not {what} (a JSON object was expected)")
    return d
