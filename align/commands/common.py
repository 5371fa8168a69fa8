"""What every command does the same way: the settings recorded in the provenance, the plan
of its outputs, warnings and 'wrote' lines on the terminal, a progress bar over files."""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

from align.commands.args import UsageError

log = logging.getLogger("align")


def settings(args: argparse.Namespace, skip: Iterable[str] = ()) -> dict:
    """The command's settings for the provenance block (every flag, as given or defaulted;
    not ``skip``)."""
    left_out = {"func", "quiet", "verbose", *skip}
    return {k: v for k, v in vars(args).items()
            if k not in left_out and (v is None or isinstance(v, str | int | float | bool | list))}


def plan(args: argparse.Namespace, inputs: Sequence[str | Path]):
    """The command's :class:`~axisbase.output.OutputPlan` (``--force`` as given)."""
    from axisbase.output import OutputPlan

    return OutputPlan(inputs, force=getattr(args, "force", False))


def table_options(args: argparse.Namespace, paths: Sequence[str], spec,
                  default: str | None = "V") -> tuple[dict, str | None]:
    """``--columns`` as a mapping and the data's output unit (``--units`` checked against
    the units written in the files' headers; ``default`` when neither says)."""
    from axisbase.header import parse_column_map, resolve_units

    cols = parse_column_map(getattr(args, "columns", None))
    units = resolve_units(getattr(args, "units", None), list(paths), spec, cols,
                          ("ux", "uy", "uz"), default=default)
    return cols, units


def same_units(units: str | None, cal_units: str | None, where: str) -> None:
    """Readings whose unit is stated (flag or header) must be in the calibration's unit; if
    unstated they are taken to be."""
    if units is not None and cal_units is not None and units != cal_units:
        raise UsageError(f"the readings are in {units} but {where} was calibrated from "
                         f"{cal_units} (--units, or the header's unit)")


def say(lines: Iterable[str], indent: str = "") -> None:
    """Print result lines on standard output; none with ``-q`` (docs/cli.md: only warnings
    and errors, on stderr), which sets the ``align`` logger to WARNING."""
    if not log.isEnabledFor(logging.INFO):
        return
    for line in lines:
        print(indent + line)


def warn(lines: Sequence[str]) -> None:
    """Warnings on stderr (the log), one a line."""
    for w in lines:
        log.warning("WARNING: %s", w)


def wrote(path: Path | str | None) -> None:
    """Say where an output went (a result line: none with ``-q``)."""
    if path is not None and str(path) != "-":
        say([f"wrote {path}"])


@contextlib.contextmanager
def byte_progress(paths: Sequence[str], desc: str) -> Iterator[Callable[[int], None] | None]:
    """A callback ``on_bytes(n)`` driving a byte-based progress bar on stderr over ``paths``
    (when stderr is a terminal, or with -v; not with -q; only for files over 16 MB); None
    otherwise."""
    total = 0
    for p in paths:
        with contextlib.suppress(OSError):
            total += os.path.getsize(p)
    level = log.getEffectiveLevel()
    show = (level <= logging.DEBUG or (sys.stderr.isatty() and level <= logging.INFO))
    if not show or total < BAR_BYTES:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="B", unit_scale=True, unit_divisor=1024,
               file=sys.stderr, leave=False)

    def on_bytes(n: int) -> None:
        bar.update(min(n, bar.total - bar.n))

    try:
        yield on_bytes
    finally:
        bar.close()


BAR_BYTES = 16 << 20
"""Smallest input that gets a progress bar [bytes] (a smaller log is read in well under 1 s)."""


def progress(items: Sequence[str], desc: str):
    """``items`` with a progress bar on stderr (a terminal, four items or more, not -q)."""
    if len(items) < 4 or not sys.stderr.isatty() or log.getEffectiveLevel() > logging.INFO:
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc)
