"""``align gonio``: face angles from a ring-laser counter log."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.args import (
    ALPHA,
    UsageError,
    distinct_files,
    face_plan,
    latitude_range,
    number,
)
from align.commands.common import byte_progress, plan, say, settings, warn, wrote
from align.commands.parents import examples, tables
from axisbase.units import DEG


def cmd_gonio(args: argparse.Namespace) -> int:
    # (align.documents, align.warnings and align.present import the loop, i.e. scipy: after
    # the pass, which imports it on a thread while it waits on the parser)
    from align.gonio import measure_log
    from axisbase.header import parse_column_map

    names, nominal_deg = face_plan(args.faces, args.nominal, str(args.log))
    inputs = [args.log] + ([args.reverse_log] if args.reverse_log else [])
    if args.reverse_log:
        distinct_files(args.log, args.reverse_log, "log", "--reverse-log")
    cols = parse_column_map(args.columns)
    outs = plan(args, inputs)
    out, plot = (outs.add("--json", args.json, stdout_ok=True),
                 outs.add("--plot", args.plot, folder=True))
    run = _measure(measure_log, args, names, cols)
    _show_gonio(run, names, nominal_deg, plot)
    if out is not None:
        _write_gonio(args, run, names, nominal_deg, out, inputs)
    return 2 if run.problems else 0  # angles u does not cover: not ok (docs/cli.md)


def _measure(measure_log: Callable, args: argparse.Namespace, names: list[str], cols: dict):
    from goniometry import FaceCountError

    if args.latitude is not None and args.latitude_range is not None:
        raise UsageError("--latitude-range: give it or --latitude, not both")
    logs = [args.log] + ([args.reverse_log] if args.reverse_log else [])
    with byte_progress(logs, "reading") as on_bytes:
        try:
            lat = None if args.latitude is None else args.latitude * DEG
            lat_range = (None if args.latitude_range is None else
                         tuple(v * DEG for v in args.latitude_range))
            return measure_log(args.log, len(names), lat,
                               1 if args.direction == "ccw" else -1, args.alpha,
                               reverse_log=args.reverse_log, steady_table=args.steady_table,
                               columns=cols, latitude_range_rad=lat_range,
                               on_bytes=on_bytes, time_unit=args.time_unit,
                               latency_max_s=(None if args.latency_max_us is None else
                                              args.latency_max_us * 1e-6),
                               counters_sound=args.counters_sound)
        except FaceCountError as exc:
            raise UsageError(f"--faces {args.faces}: names {exc.named} faces, but {exc.path} "
                             f"has {exc.found} pulses per revolution") from None


def _nominal_rad(nominal_deg: list[float] | None):
    import numpy as np

    return None if nominal_deg is None else np.deg2rad(nominal_deg)


def _show_gonio(run, names: list[str], nominal_deg: list[float] | None, plot) -> None:
    from align.present import gonio_lines
    from align.warnings import gonio_warnings

    say(gonio_lines(run, names, _nominal_rad(nominal_deg)))
    warn(gonio_warnings(run, names, _nominal_rad(nominal_deg)))
    if plot is not None:
        from align.plots import plot_gonio
        from goniometry import kept_table

        print(f"plot: {plot_gonio(kept_table(run.summary)[0], run.angles, names, plot)}")


def _write_gonio(args, run, names, nominal_deg, out, inputs) -> None:
    # (the document hashes the logs: only when written)
    from align.documents import gonio_document
    from axisbase.output import write_json

    doc = gonio_document(run, names, _nominal_rad(nominal_deg), settings(args), inputs)
    wrote(write_json(out, doc, args.force))


def add_gonio(add: Callable[..., argparse.ArgumentParser]) -> None:
    g = add("gonio", "face angles from a ring-laser counter log",
            tables(rate=False, units=False, example="count=periods,counter=channel,ref=index",
                   time_unit=True),
            epilog=examples("align gonio log.csv --faces ref,z,y,x --nominal 90,90,90,90 "
                            "--latitude 48.1 --json gonio.json",
                            "align gonio ccw.csv --faces ref,z,y,x --reverse-log cw.csv "
                            "--latitude-range 40,55 --plot figs/"))
    g.add_argument("log", help="CSV count,counter,ref[,t]")
    g.add_argument("--faces", required=True, help="face names in passing order, e.g. ref,z,y,x")
    g.add_argument("--nominal", help="nominal angles [deg] summing to 360, e.g. 90,90,90,90")
    g.add_argument("--latitude", type=number(-90, 90), metavar="DEG",
                   help="site latitude [deg] (Earth-rate correction)")
    g.add_argument("--latitude-range", type=latitude_range, metavar="LO,HI",
                   help="without --latitude: the latitudes the site may have [deg]; bounds "
                   "the Earth-rate term carried in u (default: all latitudes)")
    g.add_argument("--direction", choices=["ccw", "cw"], default="ccw",
                   help="table rotation seen from above")
    g.add_argument("--reverse-log", help="a log of the same faces with the table turning the "
                   "other way: the angles are then the mean of both directions")
    g.add_argument("--steady-table", action="store_true",
                   help="the table turns at constant speed: angles from the pulse times "
                   "(below the count quantisation) when the counts confirm it")
    g.add_argument("--latency-max-us", type=number(0, None), metavar="US",
                   help="the autocollimator's latency bound [µs] from its specification "
                   "(0: none): one direction on a table whose speed follows its angle then "
                   "carries that latency's bias in u (without it: up to 1 ms where its bias "
                   "stays within u, else not ok)")
    g.add_argument("--counters-sound", action="store_true",
                   help="the counters are verified (their dead time measured: no counts lost "
                   "at their switches): one direction whose counts and pulse times disagree "
                   "then carries no counters' part in u, and is not ok where the table's "
                   "speed does not explain the disagreement")
    g.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    g.add_argument("--plot", help="folder for angle-per-revolution / Allan / spectrum figure")
    g.add_argument("--json", help="results JSON ('-': stdout)")
    g.set_defaults(func=cmd_gonio)
