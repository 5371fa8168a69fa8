"""``align run``: whole sessions (one here, several in parallel: a batch)."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Callable

from align.commands.args import (
    ALPHA,
    UsageError,
    add_decision_flags,
    add_max_pixels,
    decision_keywords,
    number,
    unique,
)
from align.commands.common import log, say, settings, warn
from align.commands.parents import examples

# Flags that say how a batch runs, not what it computes: left out of the results' settings,
# so a batch gives the same JSON however it is run.
EXECUTION = ("jobs", "scheduler", "resume", "calibration_flag")


def cmd_run(args: argparse.Namespace) -> int:
    from align.session.batch import exit_status

    if len(args.sessions) > 1:
        unique(args.sessions, "sessions")
        return _run_batch(args)
    if args.scheduler:  # one session runs in this process (--scheduler is for batches)
        log.info("one session: it runs here (--scheduler is for batches)")
    job = _single_job(args)
    if args.resume:
        job = _resume_one(job, args)
        if isinstance(job, int):
            return job
    out = run_here(job)
    show_session(out, args.budget, args.plan, args.quiet)
    return exit_status([out], args.fail_on_reject)


def _single_job(args: argparse.Namespace):
    """The one session's job (an output ending in '/' is a folder, as for a batch)."""
    from align.session.batch import SessionJob, in_folder

    one = args.sessions[0]
    return SessionJob(one, in_folder(args.json, one, ".json"),
                      in_folder(args.report, one, ".html"),
                      in_folder(args.calibration, one, ".cal.json"), args.alpha,
                      args.force, args.allow_outside, settings(args, EXECUTION),
                      keep_result=True, cal_flag=args.calibration_flag,
                      decision=decision_keywords(args))


def _resume_one(job, args: argparse.Namespace):
    """--resume for one session: its exit status when its outputs are complete and trusted
    (skipped), else the job to run."""
    from align.session.batch import exit_status, resume

    done, todo = resume([job], say=log.warning)
    if todo:
        return todo[0]
    if done[0].get("error"):
        raise UsageError(done[0]["error"])
    if not args.quiet:
        print(f"session {args.sessions[0]}: outputs complete and trusted, skipped (--resume)")
    return exit_status(done, args.fail_on_reject)


def run_here(job) -> dict:
    """One session end to end in this process, its progress on the log; bad input raised."""
    from align.session.batch import run_job

    out = run_job(job, progress=lambda m: log.info("  [%s] %s", job.name, m))
    if "error" in out:
        raise UsageError(out["error"])
    return out


def show_session(out: dict, budget: bool = False, plan: bool = False,
                 quiet: bool = False) -> None:
    """A session's result, its verdict (with ``budget``/``plan`` the budget and what to
    measure next), stage timings, warnings and outputs on the terminal; ``quiet`` (-q): only
    the warnings (a failed stage is one of them, said once, on stderr)."""
    from align.present import decision_lines, session_lines, timing_lines
    from align.session_json import LoadedSession

    if not quiet:
        print(f"session {out['session']}:")
        say(session_lines(out["result"]))
        say(decision_lines(LoadedSession.from_dict(out["json"], out["session"]), budget, plan))
        say(timing_lines(out["result"].timings))
        say([f"  note: {n}" for n in out["json"].get("notes", ())])
    warn(out["warnings"])
    if not quiet:
        for k, v in out["outputs"].items():
            if v != "-":
                print(f"  wrote {k}: {v}")


def _run_batch(args: argparse.Namespace) -> int:
    """Several sessions in parallel (local processes, or a Dask cluster with --scheduler);
    --json/--report/--calibration name folders."""
    from align.session.batch import batch_jobs, executor_for, exit_status, resume
    from axisbase.provenance import command_line

    jobs = batch_jobs(args.sessions, args.json, args.report, args.calibration,
                      alpha=args.alpha, force=args.force, allow_outside=args.allow_outside,
                      settings=settings(args, EXECUTION), command=tuple(command_line()),
                      cal_flag=args.calibration_flag, decision=decision_keywords(args))
    results = []
    if args.resume:
        results, jobs = resume(jobs, say=log.warning)
        if results:
            log.info("--resume: %d of %d sessions already complete and trusted, skipped",
                     sum(bool(r.get("skipped")) for r in results), len(results) + len(jobs))
    scheduler = args.scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS") or None
    if scheduler:
        log.info("running %d sessions on the Dask cluster at %s", len(jobs), scheduler)
    results += _run_jobs(jobs, executor_for(scheduler, args.jobs))
    _show_batch(results, args.quiet)
    return exit_status(results, args.fail_on_reject)


def _run_jobs(jobs: list, executor) -> list[dict]:
    """Run the jobs with a progress bar on a terminal (a line per session in a log file)."""
    from align.session.batch import run_batch
    from axisbase.stop import Stopped

    bar = None
    if sys.stderr.isatty() and log.getEffectiveLevel() <= logging.INFO and jobs:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc="sessions")
    done: list = []

    def on_done(r: dict) -> None:
        done.append(r)
        if bar is not None:
            bar.update()
        else:  # a log file gets one line per finished session instead of a bar
            log.info("  [%d/%d] %s finished", len(done), len(jobs), r["session"])

    try:
        run_batch(jobs, executor, on_done)
    except Stopped:
        if bar is not None:
            bar.close()
        print(f"stopped: {len(done)} of {len(jobs)} sessions finished (their outputs are "
              "complete; no other session left any); 'align run ... --resume' does the rest",
              file=sys.stderr)
        raise
    finally:
        if bar is not None:
            bar.close()
    return done


def _show_batch(results: list[dict], quiet: bool = False) -> None:
    """A line per session and the count (not with -q: quiet leaves the errors alone)."""
    from align.present import batch_row_line
    from align.session.batch import batch_row

    rows = sorted((batch_row(r) for r in results), key=lambda row: row.session)
    for row in rows:
        line = batch_row_line(row)
        if line is not None and not quiet:
            print(line)
        if not row.ok:
            log.error("%s: FAILED: %s", row.session, row.error)
    failed = sum(not row.ok for row in rows)
    if not quiet:
        print(f"{len(rows) - failed} of {len(rows)} sessions done"
              + (f", {failed} failed" if failed else ""))


class NamedBy(argparse.Action):
    """Stores the value, and in ``<dest>_flag`` which of the option's names the user typed
    (its messages then name that one)."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        setattr(namespace, self.dest, values)
        setattr(namespace, f"{self.dest}_flag", option_string)


def add_run(add: Callable[..., argparse.ArgumentParser]) -> None:
    r = add("run", "run whole sessions: every stage, the loops, the fusion", epilog=examples(
        "align run SESSION --json result.json --report report.html --platform-calibration "
        "pc.json",
        "# a production batch, then the rest of it after a stop",
        "align run S1 S2 S3 --json results/ --report reports/ --jobs 4",
        "align run S1 S2 S3 --json results/ --report reports/ --resume"))
    r.add_argument("sessions", nargs="+", help="session folder(s) holding session.toml")
    r.add_argument("--json", help="result JSON (a folder when several sessions; '-': stdout)")
    r.add_argument("--report", help="HTML report (a folder when several sessions)")
    r.add_argument("--platform-calibration", "--calibration", dest="calibration",
                   action=NamedBy,
                   metavar="OUT", help="write the platform calibration JSON for 'align apply' "
                   "(a folder when several sessions; --calibration: the older name)")
    r.add_argument("--jobs", type=number(1, 1024, integer=True),
                   help="parallel sessions (default: all cores)")
    r.add_argument("--alpha", type=ALPHA, default=1e-3,
                   help="significance of the residual loops' tests")
    r.add_argument("--allow-outside", action="store_true",
                   help="let session.toml name files outside the session folder")
    r.add_argument("--resume", action="store_true",
                   help="skip sessions whose outputs are all in place (an interrupted batch) "
                   "and run the rest")
    add_max_pixels(r)
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the sessions of a batch on this Dask scheduler, e.g. "
                   "tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS, else local processes)")
    add_decision_flags(r)
    r.add_argument("--budget", action="store_true",
                   help="print the uncertainty budget of every angle (largest first)")
    r.add_argument("--plan", action="store_true",
                   help="print what to measure next (as 'align plan' on the result)")
    r.set_defaults(func=cmd_run, calibration_flag="--platform-calibration")

