"""The ``align`` parser: the top level and one subcommand per module of this package."""

from __future__ import annotations

import argparse

from align.commands import calibrate, gonio, lot, marks, plan, run, session, synth
from align.commands.parents import FMT, Parser, common, examples, writes
from axisbase.version import __version__

DESCRIPTION = ("Align and calibrate navigation accelerometers: scribe marks in images, "
               "ring-laser goniometer logs, ellipsoid calibration of the triad, fused into "
               "the misalignment matrix E with its uncertainty.")

EPILOG = examples("align demo", "align run SESSION --json result.json --report report.html",
                  "align COMMAND --help") + (
    "\n\nexit status: 0 success; 1 internal error (please report); 2 bad input or usage,\n"
    "  or a result that cannot be trusted (written, with ok: false); 130 interrupted;\n"
    "  143 stopped (SIGTERM)")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="align", description=DESCRIPTION, formatter_class=FMT, epilog=EPILOG)
    p.add_argument("--version", action="version", version=f"axis-align {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND", parser_class=Parser)
    parents = [common(), writes()]

    def add(name: str, help: str, *more: argparse.ArgumentParser,
            epilog: str | None = None) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help, description=help, formatter_class=FMT,
                              parents=[*parents, *more], epilog=epilog)

    marks.add_marks(add)
    marks.add_camera(add)
    calibrate.add_calibrate(add)
    calibrate.add_tilt(add)
    gonio.add_gonio(add)
    run.add_run(add)
    calibrate.add_apply(add)
    lot.add_lot(add)
    plan.add_plan(add)
    synth.add_synth(sub, parents)
    synth.add_demo(add)
    session.add_init(add)
    session.add_check(add)
    return p
