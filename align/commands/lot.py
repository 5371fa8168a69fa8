"""``align lot``: a production lot of session results."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.args import add_decision_flags, decision_keywords
from align.commands.common import log, plan, say, settings, warn
from align.commands.parents import examples
from axisbase.units import ARCSEC


def _analyse(read, half: float | None):
    """The lot's statistics over the units read (``half``: the capability's half-width [″])."""
    from align.lot import analyse

    return analyse([r.unit for r in read if r.unit is not None],
                   [r.rejected for r in read if r.rejected is not None],
                   None if half is None else half * ARCSEC)


def cmd_lot(args: argparse.Namespace) -> int:
    from align.decision import resolve
    from align.lot import lot_outputs, read_results, result_files
    from align.present import lot_lines, verdict_lines

    files = result_files(args.results)
    outs = plan(args, files)
    paths = {"json": outs.add("--json", args.json, stdout_ok=True),
             "csv": outs.add("--csv", args.csv), "report": outs.add("--report", args.report)}
    read = read_results(files)
    half = _capability_half(args.tolerance_arcsec)
    lot = _analyse(read, half)
    flags = decision_keywords(args)
    spec = resolve(None, **flags)
    written, doc = lot_outputs(lot, read, paths, args.force, settings(args), spec, flags)
    say([*lot_lines(lot, doc, half),
         *verdict_lines(doc["dispositions"], spec.rule if spec else None)])
    warn(doc["warnings"])
    say(f"  wrote {k}: {v}" for k, v in written.items() if str(v) != "-")
    return _lot_status(lot, doc, args.fail_on_reject)


def _capability_half(tol: tuple[float, float] | None) -> float | None:
    """T of a symmetric ±T [″] (capability, Cp and Cpk, is against a symmetric ±T about a
    zero nominal); None for an asymmetric tolerance (said) or none."""
    half = tol[1] if tol is not None and tol[0] == -tol[1] else None
    if tol is not None and half is None:
        log.warning("--tolerance-arcsec %g,%g: asymmetric: per-unit verdicts only, no "
                    "capability (Cpk is computed against a symmetric ±T)", *tol)
    return half


def _lot_status(lot, doc: dict, fail_on_reject: bool) -> int:
    from align.session.batch import rejected
    from axisbase.errors import EXIT_INPUT, EXIT_OK, EXIT_REJECTED

    if not lot.ok:
        return EXIT_INPUT
    return EXIT_REJECTED if fail_on_reject and rejected(
        d["verdict"] for d in doc["dispositions"]) else EXIT_OK


def add_lot(add: Callable[..., argparse.ArgumentParser]) -> None:
    lt = add("lot", "a production lot: control charts, outliers, capability, metadata",
             epilog=examples("align lot results/ --report lot.html --csv lot.csv "
                             "--tolerance-arcsec 20"))
    lt.add_argument("results", nargs="+",
                    help="session results ('align run --json') or folders of them (*.json)")
    lt.add_argument("--report", help="HTML report of the lot (a new file)")
    lt.add_argument("--csv", help="CSV with one row per unit (a new file)")
    lt.add_argument("--json", help="lot JSON ('-': stdout)")
    add_decision_flags(lt)
    lt.set_defaults(func=cmd_lot)
