"""``align lot``: a production lot of session results."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.args import POSITIVE
from align.commands.common import plan, say, settings, warn
from align.commands.parents import examples


def cmd_lot(args: argparse.Namespace) -> int:
    from align.lot import analyse, lot_outputs, read_results, result_files
    from align.present import lot_lines
    from axisbase.units import ARCSEC

    files = result_files(args.results)
    outs = plan(args, files)
    paths = {"json": outs.add("--json", args.json, stdout_ok=True),
             "csv": outs.add("--csv", args.csv), "report": outs.add("--report", args.report)}
    read = read_results(files)
    lot = analyse([r.unit for r in read if r.unit is not None],
                  [r.rejected for r in read if r.rejected is not None],
                  None if args.tolerance_arcsec is None else args.tolerance_arcsec * ARCSEC)
    written, doc = lot_outputs(lot, read, paths, args.force, settings(args))
    say(lot_lines(lot, doc, args.tolerance_arcsec))
    warn(doc["warnings"])
    for k, v in written.items():
        if str(v) != "-":
            print(f"  wrote {k}: {v}")
    return 0 if lot.ok else 2


def add_lot(add: Callable[..., argparse.ArgumentParser]) -> None:
    lt = add("lot", "a production lot: control charts, outliers, capability, metadata",
             epilog=examples("align lot results/ --report lot.html --csv lot.csv "
                             "--tolerance-arcsec 20"))
    lt.add_argument("results", nargs="+",
                    help="session results ('align run --json') or folders of them (*.json)")
    lt.add_argument("--report", help="HTML report of the lot (a new file)")
    lt.add_argument("--csv", help="CSV with one row per unit (a new file)")
    lt.add_argument("--json", help="lot JSON ('-': stdout)")
    lt.add_argument("--tolerance-arcsec", type=POSITIVE, metavar="T",
                    help="tolerance ±T [″] on every angle: flags and process capability")
    lt.set_defaults(func=cmd_lot)
