"""The jobs of a batch: one :class:`SessionJob` per session folder, :func:`run_job` running one
end to end, the jobs of a batch of folders (:func:`batch_jobs`), and what a batch says of each
session (:func:`batch_row`) and of all of them (:func:`exit_status`).

:func:`run_job` writes a session's outputs all together or not at all
(:func:`align.session.output.session_outputs`); one failing session never stops the others:
it comes back as a summary with ``ok`` false and its ``error``.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from align.decision import resolve
from align.errors import InputError
from align.session.config import load_session
from align.session.output import session_outputs
from align.session.run import run_session
from align.session_json import LoadedSession
from axisbase.errors import EXIT_INPUT, EXIT_INTERNAL, EXIT_OK, EXIT_REJECTED
from axisbase.output import OutputPlan
from axisbase.provenance import set_command
from axisbase.units import ARCSEC

Summary = dict
OnDone = Callable[[Summary], None]


@dataclass(frozen=True)
class SessionJob:
    """One session of a batch.

    ``json``/``report``/``cal``: output paths (None: not asked for; ``json`` may be ``-``
    for standard output); ``settings``: the settings recorded in the provenance; ``command``:
    the command line recorded there (a worker on another machine does not know it);
    ``decision``: see the field;
    ``keep_result``: return the :class:`~align.session.SessionResult` itself (one session in
    this process, to print it)."""

    folder: str
    json: str | None = None
    report: str | None = None
    cal: str | None = None
    alpha: float = 1e-3
    force: bool = False
    allow_outside: bool = False
    settings: dict = field(default_factory=dict)
    command: tuple[str, ...] = ()
    keep_result: bool = False
    cal_flag: str = "--platform-calibration"
    """How the user named ``cal`` (the older ``--calibration`` is an alias): messages say it."""
    decision: dict = field(default_factory=dict)
    """The command line's decision flags, :func:`align.decision.resolve`'s keywords
    (``tolerance`` (lower, upper) [″], ``rule``, ``k``): they override session.toml's
    ``[tolerance]``."""

    @property
    def name(self) -> str:
        return Path(self.folder).resolve().name


# Reports are drawn with matplotlib's pyplot, which is not thread-safe: a Dask worker may run
# several sessions in threads of one process.
_PLOT_LOCK = threading.Lock()


def run_job(job: SessionJob, progress: Callable[[str], None] | None = None) -> Summary:
    """One session end to end; returns its summary (never raises for bad input or a failed
    stage: ``ok`` false, ``bad_input`` true and ``error`` say what).

    Every output is checked before anything is computed; a stage that failed still gives
    the result (``ok: false``)."""

    if job.command:
        set_command(job.command)
    try:
        s = load_session(job.folder, allow_outside=job.allow_outside)
        if job.cal is not None and s.calibration is None:
            raise InputError(f"{job.cal_flag} {job.cal}: the session {s.folder} has no "
                             "[calibration] section, so there is no platform calibration "
                             "to write")
        plan = OutputPlan(s.inputs, force=job.force)
        outs = {"json": plan.add("--json", job.json, stdout_ok=True),
                "report": plan.add("--report", job.report),
                "cal": plan.add(job.cal_flag, job.cal)}
    except InputError as exc:
        return {"session": job.folder, "folder": job.folder, "ok": False, "bad_input": True,
                "error": str(exc)}
    res = run_session(s, progress=progress or (lambda m: None), alpha=job.alpha)
    if job.decision:
        res.tolerance = resolve(s.tolerance, **job.decision)
    settings = job.settings or {"alpha": job.alpha}
    try:
        if outs["report"] is not None:
            with _PLOT_LOCK:
                written, js = session_outputs(res, outs, job.force, settings)
        else:
            written, js = session_outputs(res, outs, job.force, settings)
    except InputError as exc:  # an output that appeared while computing: not replaced
        return {"session": job.folder, "folder": job.folder, "ok": False, "bad_input": True,
                "error": str(exc)}
    # What makes a result that ran not ok leads (the JSON has it under "problems").
    warnings = [f"NOT OK: {p}" for p in js.get("problems", ())] + list(js["warnings"])
    if outs["cal"] is not None and "cal" not in written:
        warnings.append(f"{job.cal_flag} {outs['cal']}: NOT written: no platform "
                        "calibration (the calibration or the fusion failed)")
    return {"session": s.name, "folder": job.folder, "ok": res.ok,
            "bad_input": not res.ok and not res.internal_error,
            "result": res if job.keep_result else None, "json": js, "warnings": warnings,
            "outputs": {k: str(v) for k, v in written.items()}}


def crashed(job: SessionJob, why: str) -> Summary:
    """The summary of a session whose job did not return (an internal error, a dead worker)."""
    return {"session": job.name, "folder": job.folder, "ok": False, "bad_input": False,
            "error": why}


# ----------------------------------------------------------------------------- planning

def batch_jobs(sessions: Sequence[str], json: str | None = None, report: str | None = None,
               cal: str | None = None, **common) -> list[SessionJob]:
    """The jobs of a batch whose ``json``/``report``/``cal`` name folders (one
    ``<session>.json``, ``<session>.html``, ``<session>.cal.json`` each, named after the
    session's folder). The folders are created and checked writable now; ``common``: the
    other :class:`SessionJob` fields."""

    names = [Path(s).resolve().name for s in sessions]
    if len(set(names)) != len(names):
        raise InputError("two sessions have the same folder name; outputs would collide")
    flags = (("--json", json), ("--report", report),
             (common.get("cal_flag", "--platform-calibration"), cal))
    for flag, folder in flags:
        if folder == "-":
            raise InputError(f"{flag} -: standard output takes one session, not a batch")
    plan = OutputPlan(sessions, force=common.get("force", False))
    for flag, folder in flags:
        plan.add(flag, folder, folder=True)

    def path_in(folder: str | None, name: str, ext: str) -> str | None:
        return None if folder is None else str(Path(folder) / f"{name}{ext}")

    jobs = [SessionJob(s, path_in(json, n, ".json"), path_in(report, n, ".html"),
                       path_in(cal, n, ".cal.json"), **common)
            for s, n in zip(sessions, names, strict=True)]
    check_distinct_outputs(jobs)
    return jobs


def in_folder(path: str | None, session: str, ext: str) -> str | None:
    """An output given as a folder (``--json out/``, with the trailing slash) as the file
    a batch would write there (``out/<session folder name><ext>``); else ``path``."""
    if path is None or not path.endswith(("/", os.sep)):
        return path
    return str(Path(path) / f"{Path(session).resolve().name}{ext}")


def check_distinct_outputs(jobs: Sequence[SessionJob]) -> None:
    """Refuse, before anything is computed, two outputs of a batch that are one file (a
    session folder named ``u2.cal`` writes ``u2.cal.json``, which is also session ``u2``'s
    calibration when ``--json`` and ``--calibration`` name one folder)."""
    seen: dict[str, tuple[str, str]] = {}
    for j in jobs:
        for flag, p in (("--json", j.json), ("--report", j.report), ("--calibration", j.cal)):
            if p is None or p == "-":
                continue
            key = os.path.normcase(os.path.abspath(p))
            if key in seen:
                other, other_flag = seen[key]
                raise InputError(f"{p}: both the {other_flag} output of session {other} and "
                                 f"the {flag} output of session {j.folder}; rename a session "
                                 "folder or give each output its own folder")
            seen[key] = (j.folder, flag)


@dataclass(frozen=True)
class BatchRow:
    """What a batch says of one session: the verdict, the largest |E| and u [″], the
    fusion's chi2 on its degrees of freedom (None when no result JSON), the outputs in place
    and, for a session not ok, why."""

    session: str
    ok: bool
    skipped: bool
    outputs: dict
    e_max_arcsec: float | None = None
    u_max_arcsec: float | None = None
    chi2: float | None = None
    dof: int | None = None
    consistent: bool = True
    error: str | None = None
    verdict: str | None = None


def batch_row(summary: Summary) -> BatchRow:
    """The :class:`BatchRow` of a session's summary (:func:`run_job`, :func:`skipped`,
    :func:`crashed`); its result JSON read by the one reader (:class:`LoadedSession`)."""
    js = summary.get("json")
    res = None if js is None else LoadedSession.from_dict(js, summary["session"])
    error = None
    if not summary["ok"]:
        error = summary.get("error") or "; ".join(
            f"{e.stage}: {e.message}" for e in (res.errors if res is not None else ()))
    common = {"session": summary["session"], "ok": summary["ok"],
              "skipped": bool(summary.get("skipped")),
              "outputs": dict(summary.get("outputs", {})), "error": error,
              "verdict": None if res is None else res.verdict}
    if res is None or res.e_rad is None:
        return BatchRow(**common)
    return BatchRow(**common, e_max_arcsec=max(abs(v) for v in res.e_rad) / ARCSEC,
                    u_max_arcsec=max(res.u_rad) / ARCSEC, chi2=res.chi2, dof=res.dof,
                    consistent=res.consistent)


def exit_status(summaries: Sequence[Summary], fail_on_reject: bool = False) -> int:
    """The exit status of ``align run`` (one session or a batch): 1 if a session hit an
    internal error (in one of its stages, or its job crashed), else 2 if a session failed
    (bad input, or a failed stage: its result is written with ``ok: false``), else with
    ``fail_on_reject`` 3 if a verdict is FAIL or INCONCLUSIVE, else 0 — as ``align marks``
    for its images."""
    if any(not r["ok"] and not r.get("bad_input", False) for r in summaries):
        return EXIT_INTERNAL
    if any(not r["ok"] for r in summaries):
        return EXIT_INPUT
    if fail_on_reject and rejected(batch_row(r).verdict for r in summaries):
        return EXIT_REJECTED
    return EXIT_OK


def rejected(verdicts: Iterable[str | None]) -> bool:
    """Whether any verdict is FAIL or INCONCLUSIVE (what ``--fail-on-reject`` exits 3 on)."""
    return any(v in ("FAIL", "INCONCLUSIVE") for v in verdicts)


