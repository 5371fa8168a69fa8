"""The terminal: an ASCII fallback for ″ ± µ ° on consoles that cannot show them, a quiet end
on a closed pipe (``align ... | head -1``) and the one logging set-up of the command line.

Imports nothing heavy: ``align --help`` starts with it.
"""

from __future__ import annotations

import codecs
import contextlib
import logging
import os
import sys
import threading
from collections.abc import Iterator
from typing import TextIO

from axisbase.errors import InputError

_ASCII = {"″": '"', "′": "'", "±": "+/-", "µ": "u", "°": " deg", "²": "^2", "³": "^3",
          "χ": "chi", "α": "alpha", "β": "beta", "σ": "sigma", "Δ": "d", "×": "x", "→": "->",
          "≤": "<=", "≥": ">=", "≈": "~", "−": "-", "—": "-", "–": "-", "√": "sqrt", "·": "*"}


def ascii_fallback(exc: UnicodeError) -> tuple[str, int]:
    """A codec error handler (``align-ascii``): each symbol the console cannot show becomes
    its ASCII spelling (″ -> ", ± -> +/-, µ -> u, ° -> deg), else ``?``."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    bad = exc.object[exc.start:exc.end]
    return "".join(_ASCII.get(ch, "?") for ch in bad), exc.end


codecs.register_error("align-ascii", ascii_fallback)


class ConsoleWriteError(InputError):
    """The terminal's stream cannot be written (a full disk behind ``> file``, an I/O error):
    one line and exit status 2, never a traceback."""


class ClosedPipeSafe:
    """A text stream that stops writing, quietly, once its reader has gone (``| head -1``):
    the run goes on and its files are still written. Any other write error (ENOSPC on
    ``> /dev/full``, EIO) is raised once as :class:`ConsoleWriteError` naming the stream; later
    writes are dropped."""

    def __init__(self, stream: TextIO, name: str = "standard output"):
        self._s = stream
        self._name = name
        self.closed_pipe = False
        self.failed: str | None = None

    def write(self, text: str) -> int:
        if not self.closed_pipe:
            try:
                return self._s.write(text)
            except BrokenPipeError:
                self._gone()
            except OSError as exc:
                self._fail(exc)
        return len(text)

    def flush(self) -> None:
        if not self.closed_pipe:
            try:
                self._s.flush()
            except BrokenPipeError:
                self._gone()
            except OSError as exc:
                self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        self._gone()
        self.failed = f"{self._name}: cannot be written ({exc.strerror or exc})"
        raise ConsoleWriteError(self.failed) from None

    def _gone(self) -> None:
        self.closed_pipe = True
        try:  # no further flush at exit may raise either
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._s.fileno())
        except (OSError, ValueError):
            pass

    def __getattr__(self, name: str):
        return getattr(self._s, name)


def console(stream: TextIO, name: str = "standard output") -> ClosedPipeSafe:
    """``stream`` with an ASCII fallback for ″ ± µ ° when its encoding cannot show them
    (LANG=C, PYTHONIOENCODING=ascii, a Windows code page) and a quiet end on a closed pipe."""
    if isinstance(stream, ClosedPipeSafe):
        return stream
    try:
        "″±µ°".encode(stream.encoding or "ascii")
    except (UnicodeEncodeError, LookupError):
        try:
            stream.reconfigure(errors="align-ascii")  # type: ignore[attr-defined]
        except (AttributeError, ValueError):
            pass
    except AttributeError:
        pass
    return ClosedPipeSafe(stream, name)


@contextlib.contextmanager
def logging_to_stderr(name: str, quiet: bool = False,
                      verbose: bool = False) -> Iterator[logging.Logger]:
    """The logger ``name`` (and its children, the library's loggers) to stderr, message only,
    while the block runs: WARNING with ``quiet``, DEBUG with ``verbose``, else INFO.

    Afterwards the logger is as it was: the command line may run in-process more than once
    (a test, a notebook), and a handler left on the stderr of a finished run would swallow
    the next caller's log records."""
    log = logging.getLogger(name)
    saved = (log.handlers[:], log.level, log.propagate)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.handlers[:] = [handler]
    log.setLevel(logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO)
    log.propagate = False
    try:
        yield log
    finally:
        log.handlers[:] = saved[0]
        log.setLevel(saved[1])
        log.propagate = saved[2]


class _Capture(logging.Filter):
    def __init__(self) -> None:
        super().__init__()
        self.thread = threading.get_ident()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno != logging.WARNING or threading.get_ident() != self.thread:
            return True
        self.messages.append(record.getMessage().removeprefix("WARNING: "))
        return False  # the caller shows it, with the result's other warnings


@contextlib.contextmanager
def captured_warnings(name: str = "align") -> Iterator[list[str]]:
    """The warnings logged on logger ``name`` (in this thread) while the block runs, taken
    off the log and collected in the list yielded, so that a result can carry them in its
    ``warnings`` (JSON, report) and the terminal shows them once, with the others."""
    cap = _Capture()
    logger = logging.getLogger(name)
    logger.addFilter(cap)
    try:
        yield cap.messages
    finally:
        logger.removeFilter(cap)
