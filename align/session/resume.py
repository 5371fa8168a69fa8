"""``--resume``: which sessions an interrupted batch already finished, and whether their
outputs can be trusted (by content: the result must read back as this tool's complete,
``ok`` session result from this folder, with the same settings and unchanged inputs)."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from align.contract import FORMATS
from align.errors import InputError
from align.session.jobs import SessionJob, Summary
from align.session_json import LoadedSession
from axisbase.output import STDOUT
from axisbase.provenance import sha256_file
from axisbase.version import __version__


def is_complete(job: SessionJob) -> bool:
    """Every output ``job`` asks for is in place: a session result JSON, the report, and the
    calibration (unless the JSON says the session gave none). Outputs appear all together or
    not at all, so this is what an interrupted batch finished."""

    if job.json == STDOUT or not (job.json or job.report or job.cal):
        return False
    res = None
    if job.json is not None:
        res = _loaded(job.json)
        if res is None:
            return False
    if job.report is not None and not Path(job.report).is_file():
        return False
    if job.cal is not None and not Path(job.cal).is_file():
        return res is not None and res.platform_calibration is None
    return True


def _raw(path: str) -> object:
    """The JSON value in ``path``; None when it is missing or unreadable (truncated)."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _loaded(path: str) -> LoadedSession | None:
    """The session result in ``path`` as the one reader reads it; None when there is none
    (missing, truncated, another kind of file, or not readable as a session result)."""
    d = _raw(path)
    if not isinstance(d, dict) or d.get("format") != "axis-align/session":
        return None
    try:
        return LoadedSession.from_dict(d, path)
    except InputError:  # not a result of this tool: the caller treats it as absent
        return None


def skipped(job: SessionJob) -> Summary:
    """The summary of a session a previous batch finished (``--resume``)."""
    res = _loaded(job.json) if job.json else None
    ok = res.ok if res is not None else True
    warnings = []
    made = res.provenance.settings.get("alpha") if res is not None else None
    if made is not None and made != job.alpha:
        # a lot of results made with different significance levels is not one lot
        ok = False
        warnings.append(f"{job.json}: made with alpha = {made:g}, this batch asks {job.alpha:g}"
                        ": not resumed (redo it with --force)")
    return {"session": job.name, "folder": job.folder, "ok": ok, "bad_input": not ok,
            "skipped": True, "json": _raw(job.json) if res is not None else None,
            "warnings": warnings,
            "outputs": {k: v for k, v in (("json", job.json), ("report", job.report),
                                          ("cal", job.cal)) if v and Path(v).is_file()}}


NUMBER_SETTINGS = ("alpha", "tolerance_arcsec", "decision", "guard_k")
"""The run settings that change a session's result: its numbers (``alpha``) or its verdict
(the decision flags); everything else that does is in session.toml, an input checked by its
sha256."""


def reuse_verdict(job: SessionJob) -> tuple[str, str | None]:
    """Whether ``--resume`` may reuse ``job``'s outputs: ``("reuse", None)``; ``("run",
    None)`` when none is there yet; ``("redo", why)`` when they are there but cannot be
    trusted (redone, replacing them); ``("refuse", why)`` when the result belongs to another
    session folder (never replaced).

    Trusted by content, not by name: the JSON must read back as a complete session result of
    this tool version and format version, made from this session folder with the same
    number-changing settings, from inputs whose sha256 still match, and ``ok``; the report
    and calibration asked for must be there too."""


    asked = [p for p in (job.json, job.report, job.cal) if p is not None]
    if job.json == STDOUT or not asked or not any(Path(p).exists() for p in asked):
        return "run", None
    if job.json is None:
        return "redo", "no result JSON asked for, so nothing to check the outputs against"
    doc = _raw(job.json)
    if doc is None:
        return "redo", f"{job.json} is missing or unreadable (truncated?)"
    if not isinstance(doc, dict) or doc.get("format") != "axis-align/session":
        return "refuse", f"{job.json} is not a session result (format {doc.get('format')!r})" \
            if isinstance(doc, dict) else f"{job.json} is not a session result"
    try:
        res = LoadedSession.from_dict(doc, job.json)
    except InputError as exc:  # a result this tool cannot read: whose it is decides
        if not _same_folder(doc.get("folder"), job.folder):
            return "refuse", (f"{job.json} holds the result of another session folder "
                              f"({doc.get('folder')}); not replaced — give this batch another "
                              "output folder")
        return "redo", str(exc)
    if res.folder is None or not _same_folder(res.folder, job.folder):
        return "refuse", (f"{job.json} holds the result of another session folder "
                          f"({res.folder}); not replaced — give this batch another output folder")
    if res.format_version != FORMATS["session"]:
        return "redo", (f"{job.json} has format version {res.format_version}, this tool "
                        f"writes {FORMATS['session']}")
    prov = res.provenance
    if prov.tool_version != __version__:
        return "redo", (f"{job.json} was made by version {prov.tool_version}, this is "
                        f"{__version__}")
    made = prov.settings
    for key in NUMBER_SETTINGS:
        if key in job.settings and made.get(key) != job.settings[key] or \
                key not in job.settings and made.get(key) != getattr(job, key, None):
            want = job.settings.get(key, getattr(job, key, None))
            return "redo", f"{job.json} was made with {key} = {made.get(key)}, this run asks {want}"
    if not prov.inputs:
        return "redo", f"{job.json} records no inputs to check"
    for rec in prov.inputs:
        try:
            now = sha256_file(rec.path)
        except OSError:
            return "redo", f"its input {rec.path} is gone"
        if now != rec.sha256:
            return "redo", f"its input {rec.path} changed since (sha256 differs)"
    if not res.ok:
        return "redo", f"{job.json} was not ok"
    if job.report is not None and not Path(job.report).is_file():
        return "redo", f"the report {job.report} is missing"
    if job.cal is not None and not Path(job.cal).is_file() and \
            res.platform_calibration is not None:
        return "redo", f"the calibration {job.cal} is missing"
    return "reuse", None


def _same_folder(recorded: object, folder: str) -> bool:
    if not isinstance(recorded, str):
        return False
    try:
        return Path(recorded).resolve() == Path(folder).resolve()
    except OSError:
        return False


def refused(job: SessionJob, why: str) -> Summary:
    """The summary of a session ``--resume`` will not run (its output is another's)."""
    return {"session": job.name, "folder": job.folder, "ok": False, "bad_input": True,
            "error": f"--resume: {why}"}


def resume(jobs: Sequence[SessionJob], say: Callable[[str], None] | None = None
           ) -> tuple[list[Summary], list[SessionJob]]:
    """``--resume``: the summaries of the jobs a previous batch finished and that are
    trusted (:func:`reuse_verdict`; :func:`skipped`) or refused, and the jobs still to run —
    those whose outputs cannot be trusted are redone (replacing them), each reason given to
    ``say``."""

    done: list[Summary] = []
    todo: list[SessionJob] = []
    for j in jobs:
        verdict, why = reuse_verdict(j)
        if verdict == "reuse":
            done.append(skipped(j))
        elif verdict == "refuse":
            done.append(refused(j, why or ""))
        elif verdict == "redo":
            if say is not None:
                say(f"--resume: session {j.folder} redone: {why}")
            todo.append(replace(j, force=True))
        else:
            todo.append(j)
    return done, todo


