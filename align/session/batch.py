"""Batches of sessions: one job per session folder, run by an executor.

The parts, one job each:

* :mod:`align.session.jobs` — :class:`SessionJob` (everything one session needs: folder,
  output paths, settings), :func:`run_job` (one session end to end, its outputs all together
  or not at all), :func:`batch_jobs`, and the batch's rows and exit status;
* :mod:`align.session.resume` — ``--resume``: which sessions a previous, interrupted batch
  finished and whether their outputs can be trusted;
* :mod:`align.session.pool` — :class:`LocalPool` (the default): worker processes on this
  machine, ending with their parent;
* :mod:`align.session.cluster` — :class:`DaskCluster`: the sessions on an existing
  ``dask.distributed`` cluster.

Executors run jobs and hand back one summary per job as each finishes; one failing session
never stops the others: it comes back as a summary with ``ok`` false and its ``error``. This
module ties them together (:func:`run_batch`, :func:`executor_for`) and keeps the batch's
public names in one place.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from typing import Protocol

from align.session.cluster import DaskCluster, probe_scheduler
from align.session.jobs import (
    BatchRow,
    OnDone,
    SessionJob,
    Summary,
    batch_jobs,
    batch_row,
    check_distinct_outputs,
    crashed,
    exit_status,
    in_folder,
    rejected,
    run_job,
)
from align.session.pool import PARENT_POLL_S, LocalPool
from align.session.resume import (
    NUMBER_SETTINGS,
    is_complete,
    refused,
    resume,
    reuse_verdict,
    skipped,
)

__all__ = ["BatchRow", "DaskCluster", "Executor", "LocalPool", "NUMBER_SETTINGS", "OnDone",
           "PARENT_POLL_S", "SessionJob", "Summary", "batch_jobs", "batch_row",
           "check_distinct_outputs", "crashed", "executor_for", "exit_status", "in_folder",
           "is_complete", "probe_scheduler", "refused", "rejected", "resume", "reuse_verdict",
           "run_batch", "run_job", "skipped"]


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
