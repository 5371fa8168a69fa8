"""Sessions of a batch on an existing ``dask.distributed`` cluster (:class:`DaskCluster`).

The scheduler reruns a session whose worker died (up to its ``allowed-failures``), and a
session it gives up on is reported, not lost. The workers must see the session folders and
the output folders at the same paths as this machine.
"""

from __future__ import annotations

import socket
import uuid
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from urllib.parse import urlsplit

from align.errors import InputError
from align.session.jobs import OnDone, SessionJob, crashed, run_job


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

    def a(p: str | None) -> str | None:
        return None if p is None or p == "-" else str(Path(p).absolute())

    return replace(job, folder=a(job.folder), json=a(job.json), report=a(job.report),
                   cal=a(job.cal))
