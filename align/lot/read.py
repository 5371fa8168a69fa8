"""Reading a lot: session results (``align run --json``, format ``axis-align/session``) from
files and folders, each read by the one reader of session results
(:class:`align.session_json.LoadedSession`, format and version checked).

One unit is one session result: its six misalignment angles E_ij with their standard
uncertainties [rad], the fusion's χ², its warnings, its failed stages and the session's
``[metadata]``. A file that cannot be read as a session result is never fatal: it becomes a
:class:`Rejected` entry with one line saying why, and the lot goes on.
"""

from __future__ import annotations

import codecs
import datetime as _dt
import hashlib
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import orjson

from align.errors import InputError
from align.session_json import ANGLE_INDEX as _INDEX
from align.session_json import ANGLE_NAMES, LoadedSession
from axisbase.units import ARCSEC

_ID_KEYS = ("unit", "serial")
"""Metadata keys naming the unit (in this order of preference; else the session name)."""
_WHEN_KEYS = ("datetime", "date")
"""Metadata keys giving when the session was measured (``date`` may come with ``time``)."""


@dataclass(frozen=True)
class Rejected:
    """A file given as a session result that could not be read as one.

    Attributes
    ----------
    file : str
        The file; unit —.
    reason : str
        Why, in one line; unit —.
    """

    file: str
    reason: str

    def to_dict(self) -> dict:
        return {"file": self.file, "reason": self.reason}


@dataclass(frozen=True)
class UnitResult:
    """One unit of the lot: what the lot report needs of one session result.

    Attributes
    ----------
    file : str
        The result file read; unit —.
    session : str
        The session's name; unit —.
    label : str
        The unit (metadata ``unit`` or ``serial``, else the session name); unit —.
    ok, fused : bool
        As in the result (every stage succeeded and fused / a matrix exists); unit —.
    e_rad, u_rad : tuple of float or None
        The six angles E_ij in :data:`ANGLE_NAMES` order and their standard uncertainties
        [rad] (None when not fused).
    chi2, dof, p_value : float, int, float or None
        The fusion's consistency (None when not fused) — dimensionless.
    warnings : tuple of str
        The result's warnings; unit —.
    failed_stages : tuple of (str, str)
        (stage, message) of each failure; unit —.
    metadata : Mapping
        The session's ``[metadata]`` (texts, numbers, booleans; dates as ISO text), as the
        user wrote them; unit —.
    format_version : int
        The result's format version — dimensionless.
    sha256 : str or None
        The file's SHA-256 (None when built in memory); unit —.
    created_utc : str or None
        When the result was written (ISO 8601, UTC); unit —.
    inputs_sha256 : tuple of str
        The SHA-256 of every input file of the session, sorted (the same data give the same
        tuple); unit —.
    covariance : tuple of tuple of float or None
        The 6×6 covariance of ``e_rad`` [rad²].
    disposition : Mapping or None
        The result's verdict block (:class:`align.decision.Disposition`); unit —.
    problems : tuple of (str, str)
        (code, text) of each of the result's problems (:mod:`align.problem_codes`); unit —.
    undetermined : tuple of Mapping
        The nuisances its fusion carried undetermined (what a re-judgement under another
        tolerance needs: :func:`align.decision.judge_result`); unit —.
    """

    file: str
    session: str
    label: str
    ok: bool
    fused: bool
    e_rad: tuple[float, ...] | None
    u_rad: tuple[float, ...] | None
    chi2: float | None
    dof: int | None
    p_value: float | None
    warnings: tuple[str, ...] = ()
    failed_stages: tuple[tuple[str, str], ...] = ()
    metadata: Mapping[str, Any] = field(default_factory=dict)
    format_version: int = 3
    sha256: str | None = None
    created_utc: str | None = None
    inputs_sha256: tuple[str, ...] = ()
    covariance: tuple[tuple[float, ...], ...] | None = None
    disposition: Mapping[str, Any] | None = None
    problems: tuple[tuple[str, str], ...] = ()
    undetermined: tuple[Mapping[str, Any], ...] = ()

    @property
    def when(self) -> _dt.datetime | None:
        """When the session was measured (metadata ``datetime``, or ``date`` [+ ``time``]);
        None when the metadata do not say or cannot be read as ISO 8601."""
        return when_of(self.metadata)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str) -> UnitResult:
        """A unit from a session result's JSON (``InputError`` naming ``where`` and the key
        when it is not a readable session result, or not one a lot takes)."""
        return cls.of(LoadedSession.from_dict(d, where))

    @classmethod
    def of(cls, r: LoadedSession) -> UnitResult:
        """A unit from a session result as read by the one reader (:class:`LoadedSession`);
        a lot also refuses an angle beyond :data:`MAX_E_RAD`."""
        if r.e_rad is not None:
            for (i, j), v in zip(_INDEX, r.e_rad, strict=True):
                if abs(v) > MAX_E_RAD:
                    raise InputError(f"{r.where}: misalignment_rad[{i}][{j}] = {v:.6g} rad "
                                     f"({math.degrees(v):.4g}°): beyond "
                                     f"{math.degrees(MAX_E_RAD):g}°, no mounting error of a "
                                     "triad")
        meta = r.metadata
        # A serial as written, less the white space around it ('SN-4 ' is 'SN-4'); units
        # are compared case-folded (align.lot.duplicates).
        label = next((str(meta[k]).strip() for k in _ID_KEYS
                      if meta.get(k) is not None and str(meta[k]).strip()),
                     r.session.strip())
        digests = tuple(sorted(i.sha256 for i in r.provenance.inputs
                               if isinstance(i.sha256, str)))
        return cls(r.where, r.session, label, r.ok, r.fused, r.e_rad, r.u_rad, r.chi2, r.dof,
                   r.p_value, r.warnings, tuple((e.stage, e.message) for e in r.errors),
                   dict(meta), r.format_version,
                   created_utc=r.provenance.created_utc or None, inputs_sha256=digests,
                   covariance=r.covariance, disposition=r.disposition,
                   problems=tuple(zip(r.problem_codes, r.problems, strict=True)),
                   undetermined=r.undetermined)

    def to_dict(self) -> dict:
        """The unit as the lot JSON lists it (angles in arc-seconds: that is the edge)."""

        return {"file": self.file, "session": self.session, "unit": self.label,
                "ok": self.ok, "fused": self.fused,
                "misalignment_arcsec": None if self.e_rad is None else dict(
                    zip(ANGLE_NAMES, (v / ARCSEC for v in self.e_rad), strict=True)),
                "misalignment_u_arcsec": None if self.u_rad is None else dict(
                    zip(ANGLE_NAMES, (v / ARCSEC for v in self.u_rad), strict=True)),
                "chi2": self.chi2, "dof": self.dof, "p_value": self.p_value,
                "warnings": list(self.warnings),
                "failed_stages": [{"stage": s, "message": m} for s, m in self.failed_stages],
                "metadata": dict(self.metadata)}


MAX_E_RAD = 5 * math.pi / 180
"""Largest |E_ij| a lot takes [rad] (5°): the fusion's model is first order in the small
angles (at 5° its second-order terms reach 0.4 % of E); a larger value is no mounting error
of a navigation triad but a corrupt file or a failed measurement."""


def when_of(meta: Mapping[str, Any]) -> _dt.datetime | None:
    """The session's date and time from its metadata (naive times are taken as they are;
    aware ones are converted to UTC and made naive, so both sort together)."""
    for key in _WHEN_KEYS:
        v = meta.get(key)
        if not isinstance(v, str) or not v.strip():
            continue
        text = v.strip()
        t = meta.get("time") if key == "date" else None
        if isinstance(t, str) and t.strip() and "T" not in text:
            text = f"{text}T{t.strip()}"
        try:
            w = _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
        except ValueError:
            return None
        if w.tzinfo is not None:
            w = w.astimezone(_dt.UTC).replace(tzinfo=None)
        return w
    return None


NOT_RESULTS = ("axis-align/platform-calibration",)
"""Formats a results folder may also hold that are not session results (left out of a
folder's files, by their ``format`` field)."""

_FORMAT_KEY = re.compile(rb'"format"\s*:\s*"([^"]{1,80})"')


def _declared_format(path: Path) -> str | None:
    """The ``format`` a JSON file declares in its first 4 kB (where this tool writes it: the
    first key), without reading the whole file; None if it does not say."""
    try:
        with open(path, "rb") as f:
            m = _FORMAT_KEY.search(f.read(4096))
    except OSError:
        return None
    return m.group(1).decode("utf-8", "replace") if m else None


def result_files(paths: Sequence[str | Path]) -> list[Path]:
    """The result files named: files as given, folders as their ``*.json`` files (sorted by
    name, not descending into sub-folders; ``*.cal.json`` platform calibrations left out).
    ``InputError`` for a path that does not exist, an empty folder, or the same file reached
    twice."""
    out: list[Path] = []
    seen: dict[Path, str] = {}
    for given in paths:
        p = Path(given)
        if p.is_dir():
            # 'align run --calibration FOLDER' writes NAME.cal.json, possibly beside the
            # results: platform calibrations, not results — told by their format field, not
            # by their name (a session folder named 'u2.cal' has the result u2.cal.json).
            found = sorted((q for q in p.iterdir() if q.suffix.lower() == ".json"
                            and q.is_file() and not q.name.startswith(".")
                            and _declared_format(q) not in NOT_RESULTS),
                           key=lambda q: q.name)
            if not found:
                raise InputError(f"{p}: a folder with no .json files (session results)")
        elif p.exists():
            found = [p]
        else:
            raise InputError(f"{p}: no such file or folder")
        for q in found:
            real = q.resolve()
            if real in seen:
                raise InputError(f"{q}: given twice (also as {seen[real]})")
            seen[real] = str(q)
            out.append(q)
    return out


@dataclass(frozen=True)
class ReadFile:
    """One input as read: the unit or why it was rejected, and the file's SHA-256 and size
    (for the provenance, so each file is read once)."""

    path: Path
    unit: UnitResult | None
    rejected: Rejected | None
    sha256: str | None
    size: int | None


def read_result(path: str | Path) -> ReadFile:
    """Read one session result; never raises for a bad file (it becomes ``rejected``)."""
    p = Path(path)
    where = str(p)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        return ReadFile(p, None, Rejected(where, f"cannot be read ({exc.strerror})"), None,
                        None)
    digest, size = hashlib.sha256(raw).hexdigest(), len(raw)
    try:
        # orjson parses a 40 kB result 3× faster than json: reading 10⁴ real results is
        # most of a lot's time. It is strict (no NaN tokens: this tool never writes them).
        d = orjson.loads(raw.removeprefix(codecs.BOM_UTF8))
    except orjson.JSONDecodeError as exc:
        why = ("not UTF-8 text" if "UTF-8" in exc.msg else
               f"not valid JSON (line {exc.lineno}: {exc.msg})")
        return ReadFile(p, None, Rejected(where, why), digest, size)
    try:
        unit = UnitResult.from_dict(d, where)
    except InputError as exc:
        reason = str(exc)
        if reason.startswith(where + ": "):
            reason = reason[len(where) + 2:]
        return ReadFile(p, None, Rejected(where, reason), digest, size)
    return ReadFile(p, replace(unit, sha256=digest), None, digest, size)


def read_results(files: Iterable[str | Path]) -> list[ReadFile]:
    """:func:`read_result` of every file, in the order given."""
    return [read_result(f) for f in files]
