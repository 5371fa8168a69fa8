"""The ``align`` command. Exit status: 0 success; 2 bad input or usage, or a result that cannot
be trusted (a failed stage: the result is still written, with ``ok: false``); 1 internal
error; 130 interrupted (Ctrl-C, SIGINT); 143 stopped (SIGTERM).

The commands parse arguments and print; what they compute lives in the library, and how a
result reads on the terminal in :mod:`align.present`. Heavy libraries (numpy, scipy, OpenCV,
matplotlib, pyarrow) are imported inside the command functions, so ``align --help`` starts in
a fraction of a second.
"""

from __future__ import annotations

import argparse
import functools
import io
import os
import sys
import traceback
from collections.abc import Callable, Sequence

from align.commands.args import attach_signs
from align.commands.parser import build_parser
from axisbase.console import ConsoleWriteError, console, logging_to_stderr
from axisbase.errors import EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, InputError
from axisbase.threads import one_blas_thread


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``align`` with ``argv`` (default: the command line); returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    given_out, given_err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = console(sys.stdout), console(sys.stderr, "standard error")
    try:
        status = _main(argv)
        try:  # what is still buffered: a full disk shows only now (> /dev/full)
            sys.stdout.flush()
        except ConsoleWriteError as exc:
            print(f"align: {exc}", file=sys.stderr)
            return EXIT_INPUT
        return status
    finally:
        for s in (sys.stdout, sys.stderr):
            try:
                s.flush()
            except (OSError, ValueError):
                pass
        sys.stdout, sys.stderr = given_out, given_err


@functools.cache
def _parser() -> argparse.ArgumentParser:
    """The parser, built once per process: ~6 ms of CPU a build (argparse looks up its
    message catalogue for every group), which ``main()`` called in-process paid per call.
    Parsing leaves it as it was (each parse fills a new namespace)."""
    return build_parser()


def _command(func: Callable) -> Callable:
    """The command function as its module holds it when it runs (the parser is built once,
    so a function replaced since — a test's stand-in — is the one called)."""
    return getattr(sys.modules.get(func.__module__), func.__name__, func)


def _main(argv: list[str]) -> int:
    try:
        args = _parser().parse_args(attach_signs(argv))
    except SystemExit as exc:
        return int(exc.code or 0) and EXIT_INPUT
    with logging_to_stderr("align", getattr(args, "quiet", False),
                           getattr(args, "verbose", False)):
        return _run(args, argv)


def _run(args, argv: list[str]) -> int:
    """The parsed command, with this run's global settings (the command line in the
    provenance, where ``-`` outputs go, the pixel budget, signal handlers) undone afterwards:
    ``main()`` may be called in-process more than once."""
    from axisbase.output import set_real_stdout
    from axisbase.provenance import set_command
    from axisbase.stop import Stopped, raise_on_signals, restore

    set_command(["align", *argv])
    real_stdout = sys.stdout
    set_real_stdout(real_stdout)
    budget_before = os.environ.get("ALIGN_MAX_PIXELS")
    if getattr(args, "max_pixels", None) is not None:  # the image reader's budget, here
        from imaging.io import set_max_pixels  # (and in the processes a batch starts)

        set_max_pixels(args.max_pixels)
    handlers = raise_on_signals()  # SIGTERM unwinds like Ctrl-C: no half-written outputs
    if getattr(args, "json", None) == "-":
        # The JSON owns standard output: messages go to stderr, or nowhere with -q (which
        # leaves stderr to warnings and errors).
        sys.stdout = io.StringIO() if getattr(args, "quiet", False) else sys.stderr
    try:
        with one_blas_thread():
            return int(_command(args.func)(args))
    except InputError as exc:
        print(f"align {args.cmd}: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except Stopped as stop:
        print(f"align {args.cmd}: stopped ({stop})", file=sys.stderr)
        return stop.exit_status
    except KeyboardInterrupt:
        print(f"align {args.cmd}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        print(f"align {args.cmd}: internal error (please report):", file=sys.stderr)
        traceback.print_exc()
        return EXIT_INTERNAL
    finally:
        sys.stdout = real_stdout
        restore(handlers)
        set_command(None)
        set_real_stdout(None)
        if budget_before is None:  # main() called in-process: the budget was for this call
            os.environ.pop("ALIGN_MAX_PIXELS", None)
        else:
            os.environ["ALIGN_MAX_PIXELS"] = budget_before
