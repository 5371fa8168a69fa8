"""``--resume``: which sessions an interrupted batch already finished, and whether their
outputs can be trusted (by content: the result must read back as this tool's complete,
``ok`` session result from this folder, with the same settings and unchanged inputs)."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from align.contract import FORMATS
from align.session.jobs import SessionJob, Summary
from axisbase.output import STDOUT
from axisbase.provenance import sha256_file
from axisbase.version import __version__


def is_complete(job: SessionJob) -> bool:
    """Every output ``job`` asks for is in place: a session result JSON, the report, and the
    calibration (unless the JSON says the session gave none). Outputs appear all together or
    not at all, so this is what an interrupted batch finished."""

    if job.json == STDOUT or not (job.json or job.report or job.cal):
        return False
    doc = None
    if job.json is not None:
        doc = _session_json(job.json)
        if doc is None:
            return False
    if job.report is not None and not Path(job.report).is_file():
        return False
    if job.cal is not None and not Path(job.cal).is_file():
        return doc is not None and doc.get("platform_calibration") is None
    return True


def _session_json(path: str) -> dict | None:

    try:
        d = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) and d.get("format") == "axis-align/session" else None


def skipped(job: SessionJob) -> Summary:
    """The summary of a session a previous batch finished (``--resume``)."""
    doc = _session_json(job.json) if job.json else None
    ok = bool(doc.get("ok")) if doc is not None else True
    warnings = []
    made = (doc or {}).get("settings", {}).get("alpha")
    if made is not None and made != job.alpha:
        # a lot of results made with different significance levels is not one lot
        ok = False
        warnings.append(f"{job.json}: made with alpha = {made:g}, this batch asks {job.alpha:g}"
                        ": not resumed (redo it with --force)")
    return {"session": job.name, "folder": job.folder, "ok": ok, "bad_input": not ok,
            "skipped": True, "json": doc, "warnings": warnings,
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
    try:
        doc = json.loads(Path(job.json).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "redo", f"{job.json} is missing or unreadable (truncated?)"
    if not isinstance(doc, dict) or doc.get("format") != "axis-align/session":
        return "refuse", f"{job.json} is not a session result (format {doc.get('format')!r})" \
            if isinstance(doc, dict) else f"{job.json} is not a session result"
    made_in = doc.get("folder")
    if made_in is None or not _same_folder(made_in, job.folder):
        return "refuse", (f"{job.json} holds the result of another session folder "
                          f"({made_in}); not replaced — give this batch another output folder")
    if doc.get("format_version") != FORMATS["session"]:
        return "redo", (f"{job.json} has format version {doc.get('format_version')}, this tool "
                        f"writes {FORMATS['session']}")
    if doc.get("tool_version") != __version__:
        return "redo", (f"{job.json} was made by version {doc.get('tool_version')}, this is "
                        f"{__version__}")
    made = doc.get("settings") or {}
    for key in NUMBER_SETTINGS:
        if key in job.settings and made.get(key) != job.settings[key] or \
                key not in job.settings and made.get(key) != getattr(job, key, None):
            want = job.settings.get(key, getattr(job, key, None))
            return "redo", f"{job.json} was made with {key} = {made.get(key)}, this run asks {want}"
    inputs = doc.get("inputs") or []
    if not inputs:
        return "redo", f"{job.json} records no inputs to check"
    for rec in inputs:
        path, sha = rec.get("path"), rec.get("sha256")
        try:
            now = sha256_file(path)
        except (OSError, TypeError):
            return "redo", f"its input {path} is gone"
        if now != sha:
            return "redo", f"its input {path} changed since (sha256 differs)"
    if doc.get("ok") is not True:
        return "redo", f"{job.json} was not ok"
    if job.report is not None and not Path(job.report).is_file():
        return "redo", f"the report {job.report} is missing"
    if job.cal is not None and not Path(job.cal).is_file() and \
            doc.get("platform_calibration") is not None:
        return "redo", f"the calibration {job.cal} is missing"
    return "reuse", None


def _same_folder(recorded: str, folder: str) -> bool:
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


