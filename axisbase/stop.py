"""Stopping cleanly: SIGTERM and SIGINT as an exception, never in the middle of a commit.

A run told to stop (Ctrl-C, ``kill``, the end of a batch's parent) unwinds like any exception,
so every ``finally`` removes its temporary files. The moments that must not be cut are held
(:func:`stops_held`): the *commit* — the few renames that put a session's files into place (see
:class:`axisbase.output.OutputSet`), so the files appear all together or not at all — and the
few steps between a temporary file's creation and its record for removal, and that removal. A
stop that arrives then is raised as soon as the block has finished.

Exit statuses follow the shell's convention, 128 + the signal number: 130 for SIGINT, 143 for
SIGTERM.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


class Stopped(KeyboardInterrupt):
    """The run was told to stop by a signal (a KeyboardInterrupt, so that only code that
    means to catch an interruption catches it).

    Parameters
    ----------
    signum : int
        The signal (SIGINT, SIGTERM); its name is the exception's message.
    """

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    @property
    def exit_status(self) -> int:
        return 128 + self.signum


class _State(threading.local):
    holding = False
    pending: Stopped | None = None


_STATE = _State()


def on_signal(signum: int, frame: object) -> None:
    """The signal handler: raise :class:`Stopped`, or hold it back during a commit."""
    stop = Stopped(signum)
    if _STATE.holding:  # the renames finish first; stops_held raises it after
        _STATE.pending = stop
        return
    raise stop


def raise_on_signals() -> dict:
    """From now on SIGINT and SIGTERM raise :class:`Stopped` in the main thread; returns the
    previous handlers (for :func:`restore`). Outside the main thread it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}


def restore(previous: dict) -> None:
    for sig, handler in previous.items():
        signal.signal(sig, handler)


@contextmanager
def stops_held() -> Iterator[None]:
    """A block during which a stop is held back and raised when the block ends (a commit; the
    creation of a temporary file until it is recorded for removal; that removal)."""
    outer = _STATE.holding
    _STATE.holding = True
    try:
        yield
    finally:
        _STATE.holding = outer
        if not outer and _STATE.pending is not None:
            stop, _STATE.pending = _STATE.pending, None
            raise stop
