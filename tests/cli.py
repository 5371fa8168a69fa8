"""Running ``align`` from a test: in-process (the default) or as a fresh process.

A fresh ``python -m align`` costs about 1.4 s of CPU in imports (numpy, scipy, OpenCV) before it
reads its first argument, so tests call :func:`align.cli.main` in this process with
:func:`run_cli`. Only a test *about the process boundary* (the exit status the shell sees, what
the console's encoding does, a closed pipe, signals, no traceback on the real stderr) starts one
with :func:`run_cli_proc` — one representative case per behaviour.

Both return a :class:`CliResult`, which unpacks as ``rc, out, err`` and reads like
:class:`subprocess.CompletedProcess` (``.returncode``, ``.stdout``, ``.stderr``).
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NamedTuple

from align.cli import main

ROOT = Path(__file__).resolve().parents[1]


class CliResult(NamedTuple):
    """What ``align ARGS`` gave: its exit status and its two streams."""

    returncode: int
    stdout: str
    stderr: str


@contextlib.contextmanager
def _environment(cwd: str | Path | None, env: Mapping[str, str] | None) -> Iterator[None]:
    """``cwd`` and the variables in ``env`` for the block; both as they were afterwards."""
    old_cwd = os.getcwd()
    saved = {k: os.environ.get(k) for k in (env or {})}
    try:
        os.environ.update(env or {})
        if cwd is not None:
            os.chdir(cwd)
        yield
    finally:
        os.chdir(old_cwd)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _Pipe(io.BytesIO):
    """What a reader like ``head -N`` leaves a writer: its first ``lines`` lines are read,
    then the reader has gone and every write is EPIPE."""

    def __init__(self, lines: int | None):
        super().__init__()
        self.lines = lines

    def write(self, b) -> int:
        if self.lines is not None and self.getvalue().count(b"\n") >= self.lines:
            raise BrokenPipeError(32, "Broken pipe")
        n = super().write(b)
        if self.lines is not None:  # what the reader took: up to its last line
            kept = self.getvalue().split(b"\n")[:self.lines]
            self.seek(0)
            self.truncate()
            super().write(b"\n".join(kept) + (b"\n" if len(kept) == self.lines else b""))
        return n


def _stream(encoding: str = "utf-8", lines: int | None = None) -> io.TextIOWrapper:
    # A text stream with a binary buffer (the JSON writer writes ``-`` to ``.buffer``); UTF-8
    # like a terminal that shows ″ ± µ °, unless told otherwise; strict, like a console.
    return io.TextIOWrapper(_Pipe(lines), encoding=encoding, newline="", write_through=True)


def _text(stream: io.TextIOWrapper) -> str:
    try:
        stream.flush()
    except BrokenPipeError:
        pass
    # Decoded as the console's encoding: raises on any character it could not show.
    return stream.buffer.getvalue().decode(stream.encoding)  # type: ignore[attr-defined]


def _warning_to_stderr(message, category, filename, lineno, file=None, line=None) -> None:
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def run_cli(*args: object, cwd: str | Path | None = None, env: Mapping[str, str] | None = None,
            encoding: str = "utf-8", stdout_lines: int | None = None) -> CliResult:
    """``align ARGS`` in this process, from ``cwd`` with ``env`` added to the environment
    (both restored afterwards); its standard output and error captured.

    ``encoding``: the console's (``"ascii"``: as ``PYTHONIOENCODING=ascii`` or ``LANG=C``).
    ``stdout_lines``: standard output is a pipe whose reader takes that many lines and goes
    (``align ... | head -1``)."""
    out, err = _stream(encoding, stdout_lines), _stream(encoding)
    with _environment(cwd, env), contextlib.redirect_stdout(out), \
            contextlib.redirect_stderr(err), warnings.catch_warnings():
        # A Python warning is a stderr line for the user, as in a fresh process (not only an
        # entry in pytest's summary): a "one line on stderr" check sees it.
        warnings.showwarning = _warning_to_stderr
        try:
            rc = main([str(a) for a in args])
        except SystemExit as exc:  # main() returns its status; argparse's --help exits 0
            rc = exc.code if isinstance(exc.code, int) else 2
    return CliResult(rc, _text(out), _text(err))


def run_cli_proc(*args: object, cwd: str | Path | None = None,
                 env: Mapping[str, str] | None = None, timeout: float = 300) -> CliResult:
    """``python -m align ARGS`` as the user runs it: a fresh process."""
    full_env = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    p = subprocess.run([sys.executable, "-m", "align", *map(str, args)], cwd=cwd,
                       env=full_env, capture_output=True, text=True, timeout=timeout)
    return CliResult(p.returncode, p.stdout, p.stderr)
