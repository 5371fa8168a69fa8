"""The parser class and the option groups several commands share (-q/-v, --force, the
table options)."""

from __future__ import annotations

import argparse

from align.commands.args import POSITIVE, UNITS
from axisbase.units import DECLARED_TIME_UNITS


class Parser(argparse.ArgumentParser):
    """Usage errors as one line naming the flag (not the whole usage block)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter,
                    argparse.RawDescriptionHelpFormatter):
    """Defaults shown only where there is one (not "(default: None)" or "(default: False)");
    the description and the examples in the epilog kept as written."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default in (None, False, [], argparse.SUPPRESS) or action.required:
            return action.help
        return super()._get_help_string(action)


FMT = HelpFormatter


def examples(*lines: str) -> str:
    """An epilog of example command lines (each '  $ align ...'; a line starting with '#'
    is a comment for the one below)."""
    return "examples:\n" + "\n".join(f"  {line}" if line.startswith("#") else f"  $ {line}"
                                       for line in lines)


def common() -> argparse.ArgumentParser:
    """-q/--quiet and -v/--verbose (every command)."""
    c = argparse.ArgumentParser(add_help=False)
    g = c.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true",
                   help="only warnings and errors on stderr (no result lines, no progress)")
    g.add_argument("-v", "--verbose", action="store_true", help="debugging messages on stderr")
    return c


def writes() -> argparse.ArgumentParser:
    """--force (every command that writes files)."""
    w = argparse.ArgumentParser(add_help=False)
    w.add_argument("--force", action="store_true",
                   help="replace output files that exist (inputs are never replaced)")
    return w


def tables(rate: bool = True, units: bool = True, example: str = "ux=ax,uy=ay,uz=az",
           time_unit: bool | None = None) -> argparse.ArgumentParser:
    """--columns, --units, --rate, --time-unit (commands that read tables; ``time_unit``
    defaults to ``rate``: a counter log has times but no sample rate)."""
    t = argparse.ArgumentParser(add_help=False)
    t.add_argument("--columns", metavar="NAME=HEADER,...",
                   help=f"header names for the format's columns, e.g. {example} "
                   "(case, spaces and [unit] suffixes are ignored anyway)")
    if units:
        t.add_argument("--units", choices=UNITS,
                       help="the readings' unit (scale factors are then per g in it); "
                       "default: the header's [unit], else V")
    if rate:
        t.add_argument("--rate", type=POSITIVE, metavar="HZ",
                       help="sample rate for a file without a time column (row k at k/HZ s)")
    if rate if time_unit is None else time_unit:
        t.add_argument("--time-unit", choices=DECLARED_TIME_UNITS,
                       help="the time column's unit when its header says none (a logger's "
                       "microsecond stamps: us)")
    return t
