"""Batches of sessions: one job per session folder, run by an executor.

A :class:`SessionJob` says everything one session needs (folder, output paths, settings) and
:func:`run_job` runs it end to end and writes its outputs — all together or not at all
(:func:`align.session.output.session_outputs`). Executors run jobs and hand back one summary
per job as each finishes:

* :class:`LocalPool` (the default): worker processes on this machine. They end with their
  parent — they watch its process id and stop if it disappears (SIGKILL included), and the
  parent stops them when it is told to stop (SIGINT/SIGTERM). A worker that dies takes none of
  the other sessions with it: the pool is rebuilt and the unfinished sessions run again.
* :class:`DaskCluster`: the sessions run on an existing ``dask.distributed`` cluster; the
  scheduler reruns a session whose worker died (up to its ``allowed-failures``), and a session
  it gives up on is reported, not lost. The workers must see the session folders and the
  output folders at the same paths as this machine.

One failing session never stops the others: it comes back as a summary with ``ok`` false and
its ``error``. :func:`is_complete` tells which sessions a previous, interrupted batch has
already finished (``align run --resume``).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from align.contract import FORMATS
from align.decision import resolve
from align.errors import InputError
from align.session.config import load_session
from align.session.output import session_outputs
from align.session.run import run_session
from axisbase.errors import EXIT_INPUT, EXIT_INTERNAL, EXIT_OK, EXIT_REJECTED
from axisbase.output import STDOUT, OutputPlan
from axisbase.provenance import set_command, sha256_file
from axisbase.stop import Stopped, on_signal
from axisbase.version import __version__

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
    warnings = list(js["warnings"])
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
    import json

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


NUMBER_SETTINGS = ("alpha",)
"""The run settings that change a session's numbers (everything else that does is in
session.toml, an input checked by its sha256)."""


def reuse_verdict(job: SessionJob) -> tuple[str, str | None]:
    """Whether ``--resume`` may reuse ``job``'s outputs: ``("reuse", None)``; ``("run",
    None)`` when none is there yet; ``("redo", why)`` when they are there but cannot be
    trusted (redone, replacing them); ``("refuse", why)`` when the result belongs to another
    session folder (never replaced).

    Trusted by content, not by name: the JSON must read back as a complete session result of
    this tool version and format version, made from this session folder with the same
    number-changing settings, from inputs whose sha256 still match, and ``ok``; the report
    and calibration asked for must be there too."""
    import json as _json


    asked = [p for p in (job.json, job.report, job.cal) if p is not None]
    if job.json == STDOUT or not asked or not any(Path(p).exists() for p in asked):
        return "run", None
    if job.json is None:
        return "redo", "no result JSON asked for, so nothing to check the outputs against"
    try:
        doc = _json.loads(Path(job.json).read_text(encoding="utf-8"))
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
    from dataclasses import replace

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
    :func:`crashed`)."""
    js = summary.get("json")
    error = None
    if not summary["ok"]:
        error = summary.get("error") or "; ".join(
            f"{e['stage']}: {e['message']}" for e in (js or {}).get("errors", []))
    common = {"session": summary["session"], "ok": summary["ok"],
              "skipped": bool(summary.get("skipped")),
              "outputs": dict(summary.get("outputs", {})), "error": error,
              "verdict": ((js or {}).get("disposition") or {}).get("verdict")}
    if js is None or js.get("misalignment_arcsec") is None:
        return BatchRow(**common)
    E = [abs(v) for row in js["misalignment_arcsec"] for v in row]
    U = [v for row in js["misalignment_u_arcsec"] for v in row]
    return BatchRow(**common, e_max_arcsec=float(max(E)), u_max_arcsec=float(max(U)),
                    chi2=js["chi2"], dof=js["dof"],
                    consistent=not js["unexplained_structure"])


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


# ----------------------------------------------------------------------------- executors

class Executor(Protocol):
    def run(self, jobs: Sequence[SessionJob], on_done: OnDone) -> None:
        """Run every job; call ``on_done`` with each summary as it finishes (in this
        process's main thread). Raises :class:`axisbase.stop.Stopped` when told to stop,
        after stopping its workers."""


def run_batch(jobs: Iterable[SessionJob], executor: Executor,
              on_done: OnDone | None = None) -> list[Summary]:
    """Run ``jobs`` on ``executor``; returns one summary per job (in the order they
    finished)."""
    out: list[Summary] = []

    def done(r: Summary) -> None:
        out.append(r)
        if on_done is not None:
            on_done(r)

    executor.run(list(jobs), done)
    return out


def executor_for(scheduler: str | None, jobs: int | None) -> Executor:
    """A :class:`DaskCluster` on ``scheduler`` if given, else a :class:`LocalPool` of
    ``jobs`` processes (default: every core)."""
    if scheduler:
        return DaskCluster(scheduler)
    return LocalPool(jobs or os.cpu_count() or 1)


# --- local processes

_IN_JOB = [False]


def _worker_init(parent: int) -> None:
    """Each pool worker: Ctrl-C (sent to the whole process group) is the parent's to handle;
    SIGTERM stops the session in hand cleanly; the worker ends when its parent does."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _worker_signal)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                     name="watch-parent").start()


def _worker_signal(signum: int, frame: object) -> None:
    if not _IN_JOB[0]:
        os._exit(128 + signum)
    on_signal(signum, frame)  # raises Stopped in the job (held back during a commit)


# How often a worker looks for its parent [s]: the longest an orphan lives before it starts
# to stop.
PARENT_POLL_S = 0.2


def _watch_parent(parent: int) -> None:
    """Stop this worker when ``parent`` (the ``align`` process) has gone, even by SIGKILL,
    which nobody can catch: this process's parent id then changes. Portable (no prctl)."""
    import _thread
    import signal
    import time

    # With the 'fork' start method the pool's process is the parent; with 'forkserver' or
    # 'spawn' it is a helper: watch both (a dead, reaped process no longer exists).
    mine = os.getppid()
    while os.getppid() == mine and _exists(parent):
        time.sleep(PARENT_POLL_S)
    # Unwinds the session (temporary files removed). A real signal to the main thread, not
    # only interrupt_main's flag: a main thread blocked in a system call (waiting on a lock,
    # or writing a result into a pipe the dead parent no longer reads) is woken by it.
    if hasattr(signal, "pthread_kill"):
        signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)
    else:
        _thread.interrupt_main(signal.SIGTERM)
    time.sleep(30)
    os._exit(128 + signal.SIGTERM)  # the main thread was stuck in a long C call


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _pool_job(job: SessionJob) -> Summary:
    try:
        _IN_JOB[0] = True
        return run_job(job)
    except Stopped as stop:  # its finally blocks have run: no temporary file is left
        os._exit(stop.exit_status)
    finally:
        _IN_JOB[0] = False


class LocalPool:
    """Worker processes on this machine (``processes`` of them).

    A worker that dies (killed, out of memory) breaks the pool: it is rebuilt and every
    session that had not finished runs again, each at most ``retries`` more times before it
    is reported as lost to dead workers."""

    def __init__(self, processes: int, retries: int = 2):
        self.processes = int(processes)
        self.retries = retries

    def run(self, jobs: Sequence[SessionJob], on_done: OnDone) -> None:
        from concurrent.futures import ProcessPoolExecutor, as_completed
        from concurrent.futures.process import BrokenProcessPool

        pending = list(jobs)
        tries = dict.fromkeys(range(len(pending)), 0)
        index = {id(j): k for k, j in enumerate(pending)}
        while pending:
            broken: list[SessionJob] = []
            pool = ProcessPoolExecutor(min(self.processes, len(pending)),
                                       initializer=_worker_init, initargs=(os.getpid(),))
            try:
                futs = {pool.submit(_pool_job, j): j for j in pending}
                for fut in as_completed(futs):
                    job = futs[fut]
                    try:
                        r = fut.result()
                    except BrokenProcessPool:
                        broken.append(job)
                        continue
                    except Exception as exc:  # a bug in one session must not stop the rest
                        r = crashed(job, f"internal error: {exc!r}")
                    on_done(r)
            except BaseException:
                _stop_pool(pool)
                raise
            pool.shutdown(wait=True)
            pending = []
            for job in broken:
                k = index[id(job)]
                tries[k] += 1
                if tries[k] > self.retries:
                    on_done(crashed(job, f"its worker process died {tries[k]} times "
                                         "(killed, or out of memory?)"))
                else:
                    pending.append(job)


def _stop_pool(pool) -> None:
    """Stop every worker now: SIGTERM (each unwinds its session: nothing half-written),
    then SIGKILL for one that does not end within 10 s."""
    import multiprocessing

    pool.shutdown(wait=False, cancel_futures=True)
    children = multiprocessing.active_children()
    for p in children:
        p.terminate()
    for p in children:
        p.join(10)
        if p.is_alive():
            p.kill()
            p.join(1)


# --- a Dask cluster

class DaskCluster:
    """Sessions on an existing ``dask.distributed`` cluster (scheduler ``address``, e.g.
    ``tcp://10.0.0.5:8786``).

    The workers import this same package and read/write the same paths: the session folders
    and the output folders must be visible to every worker at the paths given here (a shared
    file system). A worker that dies mid-session: the scheduler runs the session again
    elsewhere; one that keeps killing workers is reported (``KilledWorker``)."""

    def __init__(self, address: str, connect_timeout_s: float = 5.0):
        self.address = address
        self.connect_timeout_s = connect_timeout_s

    def run(self, jobs: Sequence[SessionJob], on_done: OnDone) -> None:
        import uuid

        try:
            from distributed import Client, as_completed
        except ImportError:  # pragma: no cover - a declared dependency
            raise InputError("--scheduler: the 'distributed' package is not installed "
                             "(pip install 'dask[distributed]')") from None
        probe_scheduler(self.address, self.connect_timeout_s)
        try:
            client = Client(self.address, timeout=self.connect_timeout_s,
                            set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler {self.address}: cannot reach a Dask scheduler "
                             f"there ({exc})") from None
        jobs = [_absolute(j) for j in jobs]  # a worker's working folder is not ours
        tag = uuid.uuid4().hex[:8]
        futs = {}
        try:
            for k, j in enumerate(jobs):
                f = client.submit(run_job, j, key=f"align-run-{tag}-{k}-{j.name}", pure=False)
                futs[f] = j
            for fut in as_completed(list(futs), loop=client.loop):
                job = futs[fut]
                try:
                    r = fut.result()
                except Exception as exc:  # KilledWorker, a bug: reported, never lost
                    r = crashed(job, f"{type(exc).__name__}: {exc}")
                on_done(r)
        except BaseException:
            client.cancel(list(futs))
            raise
        finally:
            client.close()


def probe_scheduler(address: str, timeout_s: float = 5.0) -> None:
    """Refuse, at once and in one line, a ``--scheduler`` address that is malformed or where
    nothing listens. Written by hand because a ``distributed.Client`` given such an address
    waits out its connect timeout, and then its finaliser waits 40 s more and prints a
    traceback (distributed 2024-2025); a plain TCP connect answers in milliseconds."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme not in ("tcp", "tls"):
        raise InputError(f"--scheduler {address}: only tcp:// and tls:// addresses are "
                         "supported (e.g. tcp://10.0.0.5:8786)")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or port is None:
        raise InputError(f"--scheduler {address}: expected tcp://HOST:PORT "
                         "(e.g. tcp://10.0.0.5:8786)")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else exc.strerror or str(exc)
        raise InputError(f"--scheduler {address}: cannot reach a Dask scheduler there "
                         f"({reason})") from None


def _absolute(job: SessionJob) -> SessionJob:
    """``job`` with absolute paths (from this process's working folder; symlinks kept)."""
    from dataclasses import replace

    def a(p: str | None) -> str | None:
        return None if p is None or p == "-" else str(Path(p).absolute())

    return replace(job, folder=a(job.folder), json=a(job.json), report=a(job.report),
                   cal=a(job.cal))
