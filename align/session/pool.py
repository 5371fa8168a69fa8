"""Sessions of a batch in worker processes on this machine (:class:`LocalPool`).

The workers end with their parent — they watch its process id and stop if it disappears
(SIGKILL included), and the parent stops them when it is told to stop (SIGINT/SIGTERM). A
worker that dies takes none of the other sessions with it: the pool is rebuilt and the
unfinished sessions run again.
"""

from __future__ import annotations

import _thread
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from align.session.jobs import OnDone, SessionJob, Summary, crashed, run_job
from axisbase.stop import Stopped, on_signal

_IN_JOB = [False]


def _worker_init(parent: int) -> None:
    """Each pool worker: Ctrl-C (sent to the whole process group) is the parent's to handle;
    SIGTERM stops the session in hand cleanly; the worker ends when its parent does."""

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

    pool.shutdown(wait=False, cancel_futures=True)
    children = multiprocessing.active_children()
    for p in children:
        p.terminate()
    for p in children:
        p.join(10)
        if p.is_alive():
            p.kill()
            p.join(1)


