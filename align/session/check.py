"""``align check``: is a session folder ready to run? Every problem at once, nothing computed.

A session is checked in four passes, each going on past what it finds: the TOML itself; its
keys against the shipped JSON Schema (``align/schemas/session-toml.schema.json``: names,
types, ranges, required keys); every file it names (that it exists; a table's header and
units through the one reader's header pass, :func:`axisbase.table.header_units`; an image's
header, which says it is an image and its size, without decoding it); and last the session
loader's own checks of what the keys mean together (a view naming no camera, a housing and
view that contradict, nominal angles not summing to 360°), reported when no earlier pass
already named that part of the file.
"""

from __future__ import annotations

import datetime as _dt
import json
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path

from align.calibration import STATIC
from align.contract import schema
from align.errors import InputError
from align.session.config import load_session
from axisbase.header import header_units, parse_column_map
from goniometry.reader import COUNTER_LOG
from imaging.camera import CameraModel

MIN_SIDE_PX = 16
"""An image smaller than this on a side cannot hold a mark (``imaging.read_image`` refuses it
too)."""


def _plain(v: object) -> object:
    """The TOML document as JSON sees it (dates as ISO text), so the schema applies as an
    editor applies it."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_plain(x) for x in v]
    if isinstance(v, _dt.date | _dt.time):
        return v.isoformat()
    return v


def _where(path: list) -> str:
    """A schema error's location the way session.toml is written: ``[calibration] static``,
    ``[[images]] #3 housing``, ``[cameras.A] roll_arcsec``."""
    if not path:
        return "top level"
    head, rest = str(path[0]), path[1:]
    if head == "images" and rest and isinstance(rest[0], int):
        return " ".join([f"[[images]] #{rest[0] + 1}", *map(str, rest[1:])]).strip()
    if head in ("cameras", "views") and rest:
        return " ".join([f"[{head}.{rest[0]}]", *map(str, rest[1:])]).strip()
    if head == "platform" and len(rest) >= 2 and rest[0] == "poses":
        return " ".join([f"[platform.poses] {rest[1]}", *map(str, rest[2:])]).strip()
    if isinstance(path, list) and len(path) == 1 and head not in _SECTIONS:
        return head
    return " ".join([f"[{head}]", *map(str, rest)]).strip()


_SECTIONS = {"calibration", "goniometer", "cameras", "views", "images", "platform",
             "tolerance", "metadata"}


def schema_problems(d: dict, src: str) -> list[str]:
    """Every disagreement of the document with the shipped schema, one line each."""
    import jsonschema


    v = jsonschema.Draft7Validator(schema("session-toml"))
    out = []
    for e in sorted(v.iter_errors(_plain(d)), key=lambda e: [str(x) for x in e.absolute_path]):
        if e.validator == "additionalProperties":
            known = sorted(e.schema.get("properties", {}))
            extra = sorted(set(e.instance) - set(known))
            msg = f"unknown key(s) {', '.join(extra)}" + (f"; known: {', '.join(known)}"
                                                          if known else "")
        elif e.validator == "anyOf" and not e.absolute_path:
            msg = "names no sources (images, goniometer, calibration, platform)"
        elif e.validator in ("oneOf", "anyOf"):
            msg = f"{e.instance!r}: {e.schema.get('description', 'not a valid value')}"
        else:
            msg = e.message
        out.append(f"{src}: {_where(list(e.absolute_path))}: {msg}")
    return out


PLACEHOLDER = "FILL IN"
"""The value 'align init' writes where only the user knows what goes."""


def _placeholders(d: object, where: str = "") -> Iterator[str]:
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _placeholders(v, f"{where} {k}".strip() if where else
                                     (f"[{k}]" if isinstance(v, dict) else k))
    elif d == PLACEHOLDER:
        yield where


def _files(d: dict) -> Iterator[tuple[str, object, str, dict]]:
    """(where, value, kind, section) of every file session.toml names."""
    cal, gon, plat = d.get("calibration"), d.get("goniometer"), d.get("platform")
    if isinstance(cal, dict):
        for key in ("static", "check"):
            if key in cal:
                yield f"[calibration] {key}", cal[key], "static", cal
    if isinstance(gon, dict):
        for key in ("log", "reverse_log"):
            if key in gon:
                yield f"[goniometer] {key}", gon[key], "log", gon
    if isinstance(plat, dict) and "static" in plat:
        yield "[platform] static", plat["static"], "static", plat
    cams = d.get("cameras")
    if isinstance(cams, dict):
        for name, c in cams.items():
            if isinstance(c, dict) and "model" in c:
                yield f"[cameras.{name}] model", c["model"], "camera", c
    imgs = d.get("images")
    if isinstance(imgs, list):
        for k, im in enumerate(imgs, start=1):
            if isinstance(im, dict) and "file" in im:
                yield f"[[images]] #{k} file", im["file"], "image", im


def image_header(path: Path) -> tuple[int, int]:
    """(width, height) [px] from the image's header alone (Pillow opens lazily: nothing is
    decoded); ``InputError`` when it is not an image Pillow knows."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return im.size
    except (UnidentifiedImageError, OSError) as exc:
        raise InputError(f"not an image ({exc.__class__.__name__}: {exc})") from None


def _file_problem(folder: Path, where: str, value: object, kind: str,
                  section: dict) -> str | None:

    if not isinstance(value, str) or not value.strip():
        return None  # the schema pass has said so
    p = folder / value
    if not p.exists():
        return f"{where} = {value!r}: no such file"
    if not p.is_file():
        return f"{where} = {value!r}: not a file"
    try:
        if kind in ("static", "log"):
            cols = section.get("columns")
            if isinstance(cols, dict):
                cols = ",".join(f"{k}={v}" for k, v in cols.items())
            mapping = parse_column_map(cols if isinstance(cols, str) else None,
                                       f"{where.split(']')[0]}] columns")
            if kind == "static":

                header_units(p, STATIC, mapping, ("ux", "uy", "uz"))
            else:

                header_units(p, COUNTER_LOG, mapping, ())
        elif kind == "image":
            w, h = image_header(p)
            if min(w, h) < MIN_SIDE_PX:
                return f"{where} = {value!r}: only {w}x{h} px, too small for a mark"
        elif kind == "camera":
            problems = CameraModel.load(p).problems  # every key checked as align run does
            if problems:  # its views are of two cameras: align run would refuse it
                return f"{where} = {value!r}: {problems[0]}"
    except InputError as exc:
        return f"{where} = {value!r}: {exc}"
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return f"{where} = {value!r}: not a camera model JSON ({exc})"
    return None


def check_session(folder: str | Path) -> list[str]:
    """Every problem of the session in ``folder`` (or of that session.toml), one line each
    naming the file and key; [] when it is ready to run."""
    folder = Path(folder)
    path = folder / "session.toml" if folder.is_dir() else folder
    folder = path.parent
    src = str(path)
    if not path.is_file():
        return [f"{src}: no such file (a session is a folder with a session.toml; "
                "'align init FOLDER' writes one)"]
    try:
        d = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except tomllib.TOMLDecodeError as exc:
        return [f"{src}: not valid TOML ({exc})"]
    except UnicodeDecodeError:
        return [f"{src}: not UTF-8 text (TOML is UTF-8)"]
    problems = schema_problems(d, src)
    problems += [f"{src}: {where} = {PLACEHOLDER!r}: not filled in"
                 for where in _placeholders(d)]
    for where, value, kind, section in _files(d):
        msg = _file_problem(folder, where, value, kind, section)
        if msg is not None:
            problems.append(f"{src}: {msg}")
    # The loader's checks of the keys together: reported unless a pass above already named
    # the same part of the file (its first problem would be the same one, said again).

    try:
        load_session(folder)
    except InputError as exc:
        msg = str(exc)
        part = re.split(r" = |: ", msg.removeprefix(f"{src}: "), maxsplit=1)[0]
        if not any(p.removeprefix(f"{src}: ").startswith(part) for p in problems) and (
                msg not in problems):
            problems.append(msg)
    return problems
