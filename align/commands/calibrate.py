"""``align calibrate`` (the triad from static poses), ``align tilt`` (roll and pitch through
a calibration) and ``align apply`` (readings to the platform frame)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.args import (
    ALPHA,
    adc_range,
    nonlinearity_bound,
    number,
    scale_stability,
    signs,
    unique,
)
from align.commands.common import (
    plan,
    same_units,
    say,
    settings,
    table_options,
    warn,
    wrote,
)
from align.commands.parents import examples, tables
from axisbase.units import DEG


def _outputs(args: argparse.Namespace, inputs: list[str]):
    """--json and --plot, checked against the inputs and each other before any work."""
    outs = plan(args, inputs)
    return (outs.add("--json", args.json, stdout_ok=True),
            outs.add("--plot", args.plot, folder=True))


def cmd_calibrate(args: argparse.Namespace) -> int:
    from align.calibration.files import calibrate_files, calibration_units
    from axisbase.header import parse_column_map

    if args.plan is not None or args.static is None:
        return _plan_poses(args)
    inputs = [args.static] + ([args.check] if args.check else [])
    unique(inputs, "static/--check")
    sign = signs(args.scale_sign) if args.scale_sign is not None else None
    cols = parse_column_map(args.columns)
    units = calibration_units(args.static, args.check, args.units, cols)
    out, plot = _outputs(args, inputs)
    run = calibrate_files(args.static, args.check, units, sign, _static_settings(args), cols,
                          args.rate, args.alpha, args.fixture_error * DEG,
                          f"--units {units}" if args.units else None, args.adc_range,
                          args.time_unit, args.scale_stability_ppm, args.nonlinearity_bound)
    _show_calibration(args, run, run.cal.signs, cols, plot)
    if out is not None:
        _write_calibration(args, run, out, inputs)
    return 0 if run.ok else 2


def _plan_poses(args: argparse.Namespace) -> int:
    from align.calibration.plan import plan_report
    from align.commands.args import UsageError

    if args.plan is None:
        raise UsageError("give the static-pose file (or --plan N for a pose "
                         "sequence to record)")
    say(plan_report(args.plan))
    return 0


def _static_settings(args: argparse.Namespace):
    from align.calibration.static import CLI_NAMES, StaticSettings

    return StaticSettings.given(CLI_NAMES, window_s=args.window, threshold=args.threshold,
                                min_duration_s=args.min_static, margin_s=args.margin,
                                split_sigma=args.split_sigma, split_deg=args.split_deg)


def _show_calibration(args: argparse.Namespace, run, sign, cols, plot) -> None:
    from align.present import calibration_lines, check_lines, interval_lines

    if run.intervals is not None:
        say(interval_lines(run.intervals))
    say(calibration_lines(run.cal, len(run.poses.u), run.units, sign, args.fixture_error))
    if run.checked is not None:
        say(check_lines(run.checked))
    warn(run.warnings)
    if plot is not None:
        from align.calibration.plots import plot_static
        from align.plots import plot_calibration

        print(f"plot: {plot_calibration(run.cal, run.poses, run.check, plot)}")
        if run.intervals is not None:
            fig = plot_static(args.static, _static_settings(args), cols, args.rate, plot,
                              args.time_unit)
            print(f"plot: {fig}")


def _write_calibration(args: argparse.Namespace, run, out, inputs: list[str]) -> None:
    from align.calibration.output import calibration_document
    from axisbase.output import write_json

    doc = calibration_document(run.cal, run.poses, run.units, run.intervals, run.check,
                               list(run.warnings), settings(args), inputs, run.checked)
    wrote(write_json(out, doc, args.force))


def cmd_tilt(args: argparse.Namespace) -> int:
    from align.apply import load_tilt_calibration
    from align.calibration import READINGS
    from align.present import tilt_lines
    from align.tilt import read_readings_noted, tilt_of_readings

    inputs = [args.readings, args.calibration]
    unique(inputs, "readings/--calibration")
    cols, units = table_options(args, [args.readings], READINGS, default=None)
    model, cal_units = load_tilt_calibration(args.calibration)
    same_units(units, cal_units, args.calibration)
    outs = plan(args, inputs)
    out_json, out_csv = outs.add("--json", args.json, stdout_ok=True), outs.add("--out", args.out)
    tab, read = read_readings_noted(args.readings, cols, args.rate, args.time_unit)
    res = tilt_of_readings(model, tab, args.method, args.mu, read)
    say(tilt_lines(res, args.method))
    warn(res.warnings)
    _write_tilt(args, res, out_json, out_csv, inputs)
    return 2 if model.not_ok else 0


def _write_tilt(args: argparse.Namespace, res, out_json, out_csv, inputs: list[str]) -> None:
    from align.documents import tilt_document
    from axisbase.output import write_atomic, write_json

    if out_csv is not None:
        wrote(write_atomic(out_csv, res.csv_text(), args.force))
    if out_json is not None:
        wrote(write_json(out_json, tilt_document(res, settings(args), inputs), args.force))


def cmd_apply(args: argparse.Namespace) -> int:
    from align.apply import PlatformCalibration, apply_to_readings
    from align.calibration import READINGS, read_readings
    from align.present import apply_lines
    from axisbase.output import write_atomic

    inputs = [args.calibration_file, args.readings]
    unique(inputs, "calibration_file/readings")
    cols, units = table_options(args, [args.readings], READINGS, default=None)
    pc, cal_units = PlatformCalibration.load_with_units(args.calibration_file)
    same_units(units, cal_units, args.calibration_file)
    out = plan(args, inputs).add("--out", args.out)
    tab = read_readings(args.readings, cols, args.rate, args.time_unit)
    res = apply_to_readings(pc, tab, tilt=args.tilt, method=args.method)
    say(apply_lines(res))
    warn(res.warnings)
    wrote(write_atomic(out, res.csv_text(), args.force))
    return 2 if pc.not_ok else 0


def add_calibrate(add: Callable[..., argparse.ArgumentParser]) -> None:
    k = add("calibrate", "ellipsoid calibration of the triad from static poses", tables(),
            epilog=examples("align calibrate static.csv --json cal.json",
                            "align calibrate recording.csv --check check.csv --scale-sign -,-,- "
                            "--plot figs/",
                            "align calibrate --plan 28"))
    k.add_argument("static", nargs="?", help="pose,ux,uy,uz[,t][,temp] or a recording "
                   "t,ux,uy,uz (CSV), or a .mat/.npz with named arrays (--columns u=NAME,t=NAME)")
    k.add_argument("--plan", type=int, metavar="N", help="print an N-pose order (N >= 28) "
                   "that makes the effects identifiable, with its check by simulation, and "
                   "exit")
    k.add_argument("--check", help="check poses (same format): |a| - 1 per pose")
    k.add_argument("--json", help="write results (and the model for tilt/apply) to a new file "
                   "('-': stdout)")
    k.add_argument("--plot", help="folder for the dg-per-pose / residual figure")
    k.add_argument("--scale-sign", default=None,
                   help="signs of k: +, - or e.g. -,-,- (default: from the face labels "
                   "+x,-x,... when the poses carry them, else +)")
    k.add_argument("--adc-range", type=adc_range, metavar="LO,HI",
                   help="the ADC's rails in the readings' unit: a pose reaching one is left "
                   "out (warned) or refused (default: a pile-up at a pose's extreme value)")
    k.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    k.add_argument("--scale-stability-ppm", type=scale_stability, metavar="PPM",
                   help="how stable the scale factors are over the run, ± [ppm]: u covers a "
                   "wander of that size (not given: a wander the poses' own slopes show is "
                   "corrected and its u carried, else the scale is assumed stable, stated)")
    k.add_argument("--nonlinearity-bound", type=nonlinearity_bound, metavar="K2,K3",
                   help="the datasheet's bounds on the second- and third-order non-linearity, "
                   "± [µg/g², µg/g³]: the loop refuses K2/K3 beyond them, and a term it does "
                   "not fit is carried in u (not given: the physical priors, nothing carried)")
    # The detection settings' rules are StaticSettings.given's (session.toml's keys pass them
    # too): here only "a number".
    k.add_argument("--window", type=float, default=0.25,
                   help="static detection window [s] (at least 5 samples)")
    k.add_argument("--threshold", type=float, default=3.0,
                   help="static if the moving std < this x the recording's own noise "
                   "(estimated from its quietest windows)")
    k.add_argument("--min-static", type=float, default=0.5,
                   help="shortest static interval kept [s]")
    k.add_argument("--margin", type=float, default=0.1, help="cut from each end [s]")
    k.add_argument("--split-sigma", type=float, default=8.0,
                   help="split an interval whose mean moves by more than this many standard "
                   "errors ...")
    k.add_argument("--split-deg", type=float, default=1.0,
                   help="... and by more than this tilt [deg] (a slow turn, not settling)")
    k.add_argument("--fixture-error", type=number(0, 90), default=0.5, metavar="DEG",
                   help="placement error of the faces +x,-x,... (known-pose method) [deg]")
    k.set_defaults(func=cmd_calibrate)


def add_tilt(add: Callable[..., argparse.ArgumentParser]) -> None:
    tl = add("tilt", "roll and pitch from readings through a calibration", tables(),
             epilog=examples("align tilt readings.csv --calibration cal.json --out tilt.csv",
                             "align tilt readings.csv --calibration pc.json --method paper "
                             "--json tilt.json"))
    tl.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    tl.add_argument("--calibration", required=True,
                    help="JSON written by 'align calibrate' (roll/pitch of the triad's own "
                    "frame) or a platform calibration / session result from 'align run' "
                    "(roll/pitch of the platform, as 'align apply --tilt')")
    tl.add_argument("--method", choices=["exact", "paper"], default="exact",
                    help="exact atan2 roll, or the tilt paper's regularised one")
    tl.add_argument("--mu", type=number(0, 1, lo_open=True), default=0.001,
                    help="the paper's regulariser (--method paper)")
    tl.add_argument("--json", help="summary JSON ('-': stdout)")
    tl.add_argument("--out", help="per-reading CSV t,roll_deg,pitch_deg (a new file)")
    tl.set_defaults(func=cmd_tilt)


def add_apply(add: Callable[..., argparse.ArgumentParser]) -> None:
    ap = add("apply", "readings -> specific force in the platform frame", tables(),
             epilog=examples("align apply pc.json readings.csv --out platform.csv --tilt"))
    ap.add_argument("calibration_file", help="JSON from 'align run --calibration' or --json")
    ap.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    ap.add_argument("--out", required=True, help="new CSV t,ax_g,ay_g,az_g[,roll_deg,pitch_deg]")
    ap.add_argument("--tilt", action="store_true", help="add roll and pitch columns")
    ap.add_argument("--method", choices=["exact", "paper"], default="exact",
                    help="roll formula for --tilt")
    ap.set_defaults(func=cmd_apply)
