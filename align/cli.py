"""The ``align`` command. Exit status: 0 success; 2 bad input or usage, or a result that cannot
be trusted (a failed stage: the result is still written, with ``ok: false``); 1 internal
error; 130 interrupted (Ctrl-C, SIGINT); 143 stopped (SIGTERM).

Degrees, arc-seconds and pixels appear only here and in files; the library works in radians.
This module parses arguments and prints; what it computes lives in the library. Heavy
libraries (numpy, scipy, OpenCV, matplotlib, pyarrow) are imported inside the command
functions, so ``align --help`` starts in a fraction of a second.
"""

from __future__ import annotations

import argparse
import codecs
import io
import logging
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from axisbase.errors import InputError
from axisbase.units import ARCSEC, DEG
from axisbase.version import __version__

log = logging.getLogger("align")

UNITS = ("g", "m/s2", "counts", "V")


class UsageError(InputError):
    """Bad input the user can fix (exit status 2)."""


# ----------------------------------------------------------------------------- value checks

def _number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
            hi_open: bool = False, integer: bool = False, what: str = "") -> Callable:
    """An argparse type: a finite number (or integer) in [lo, hi] (open ends as asked)."""

    def parse(text: str) -> float | int:
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {'a whole number' if integer else 'a number'}") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        low = lo is not None and (v <= lo if lo_open else v < lo)
        high = hi is not None and (v >= hi if hi_open else v > hi)
        if low or high:
            rng = (("(" if lo_open else "[") + ("-inf" if lo is None else f"{lo:g}") + ", "
                   + ("inf" if hi is None else f"{hi:g}") + (")" if hi_open else "]"))
            raise argparse.ArgumentTypeError(f"{text} outside {rng}{what}")
        return v

    return parse


ALPHA = _number(0, 1, lo_open=True, hi_open=True, what=": a significance level 0 < α < 1")
POSITIVE = _number(0, None, lo_open=True)


def _unique(items: Sequence[str], flag: str, what: str = "file") -> None:
    """Refuse the same file (after resolving) or name given twice."""
    seen: dict[str, str] = {}
    for it in items:
        key = str(Path(it).resolve()) if what == "file" else it
        if key in seen:
            raise UsageError(f"{flag}: {it} is given twice" + (
                f" (as {seen[key]})" if seen[key] != it else ""))
        seen[key] = it


def _signs(text: str) -> tuple[float, float, float]:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) == 1:
        parts = parts * 3
    if len(parts) != 3 or any(p not in ("+", "-") for p in parts):
        raise UsageError(f"--scale-sign {text!r}: give +, - or three of them, e.g. -,-,-")
    return tuple(-1.0 if p == "-" else 1.0 for p in parts)  # type: ignore[return-value]


_SIGNS = re.compile(r"^[+-](,[+-])+$")


# Options whose value may start with '-' (signs; lists of numbers: a southern latitude range,
# a region of interest or nominal angles written with a negative first number).
_DASH_VALUES = {"--scale-sign": _SIGNS,
                "--latitude-range": re.compile(r"^-\d"), "--roi": re.compile(r"^-\d"),
                "--nominal": re.compile(r"^-\d")}


def _attach_signs(argv: list[str]) -> list[str]:
    """``--scale-sign -,-,-`` (the documented form) as ``--scale-sign=-,-,-``, and
    ``--latitude-range -40,-30`` as ``--latitude-range=-40,-30``: argparse takes any value
    starting with '-' that is not a single negative number for an option, and has no setting
    to accept it as a value (only the ``=`` form)."""
    out, i = [], 0
    while i < len(argv):
        pattern = _DASH_VALUES.get(argv[i])
        if (pattern is not None and i + 1 < len(argv)
                and pattern.match(argv[i + 1].replace(" ", ""))):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def _table_options(args: argparse.Namespace, paths: Sequence[str], spec,
                   default: str | None = "V") -> tuple[dict, str | None]:
    """``--columns`` as a mapping and the data's output unit (``--units`` checked against
    the units written in the files' headers; ``default`` when neither says)."""
    from axisbase.table import parse_column_map, resolve_units

    cols = parse_column_map(getattr(args, "columns", None))
    units = resolve_units(getattr(args, "units", None), list(paths), spec, cols,
                          ("ux", "uy", "uz"), default=default)
    return cols, units


def _settings(args: argparse.Namespace) -> dict:
    """The command's settings for the provenance block (every flag, as given or defaulted)."""
    skip = {"func", "quiet", "verbose"}
    return {k: v for k, v in vars(args).items()
            if k not in skip and (v is None or isinstance(v, str | int | float | bool | list))}


def _plan(args: argparse.Namespace, inputs: Sequence[str | Path]):
    from axisbase.output import OutputPlan

    return OutputPlan(inputs, force=getattr(args, "force", False))


def _warn(lines: Sequence[str]) -> None:
    for w in lines:
        log.warning("WARNING: %s", w)


def _wrote(path: Path | None) -> None:
    if path is not None and str(path) != "-":
        print(f"wrote {path}")


# ----------------------------------------------------------------------------- marks

def cmd_marks(args: argparse.Namespace) -> int:
    import numpy as np

    from align.documents import marks_document
    from align.marks import measure_files
    from align.plots import plot_mark
    from axisbase.output import write_json
    from imaging import CameraModel, check_roi, read_image

    _unique(args.images, "images")
    roi = check_roi(args.roi.split(","), "--roi") if args.roi is not None else None
    from align.lens import LensRanges

    camera = CameraModel.load(args.camera) if args.camera else None
    ranges = LensRanges.parse(args.lens) if args.lens is not None else None
    plan = _plan(args, [*args.images] + ([args.camera] if args.camera else []))
    out = plan.add("--json", args.json, stdout_ok=True)
    plot_dir = plan.add("--plot", args.plot, folder=True)
    results = []
    failed = internal = 0
    batch = measure_files(_progress(args.images, "marks"), camera, alpha=args.alpha,
                          max_marks=args.max_marks, expect_one=args.one, roi=roi,
                          min_length_px=args.min_length, ranges=ranges)
    limited = 0
    for res in batch:
        for r in res:
            path = r.image
            results.append(r)
            if not r.found:
                failed += 1
                internal += r.internal_error
                log.error("%s: FAILED: %s", path, str(r.error).removeprefix(f"{path}: "))
                continue
            print(f"{path} mark {r.index}: angle {np.rad2deg(r.angle_rad):+.6f}° "
                  f"± {r.angle_u_rad / ARCSEC:.2f}″, offset {r.offset_px:+.3f} px, "
                  f"length {r.length_px:.0f} px, {'dark' if r.dark else 'bright'}")
            for line in r.loop.summary_lines():
                print(f"    {line}")
            limited += r.lens_limited
            if r.frame is not None:
                f = r.frame
                state = ("applied" if f.applied else "not significant" if f.consistent else
                         "LINES DISAGREE beyond one distortion: u inflated")
                print(f"    frame ({f.n_lines} marks, one lens): k1 {f.k1:+.4g} ± {f.k1_u:.2g}, "
                      f"{state}")
            if plot_dir is not None:
                img = read_image(path) if r.measurement is not None else None
                print(f"    plot: {plot_mark(r, plot_dir, img)}")
    doc = marks_document(results, _settings(args),
                         [*args.images] + ([args.camera] if args.camera else []))
    _warn(doc["warnings"])
    if out is not None:
        _wrote(write_json(out, doc, args.force))
    if internal:
        log.error("align marks: %d image(s) hit an internal error (please report); the "
                  "others were measured", internal)
    return 1 if internal else 2 if failed or limited else 0


# ----------------------------------------------------------------------------- camera

def _pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"--pattern {text!r}: expected COLSxROWS inner corners, "
                         "e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise UsageError(f"--pattern {text!r}: a chessboard has at least 2x2 inner corners")
    return cols, rows


def cmd_camera(args: argparse.Namespace) -> int:
    import numpy as np

    from align.documents import camera_document
    from axisbase.output import write_json
    from imaging import ImageInputError, calibrate_chessboard, read_image

    cols, rows = _pattern(args.pattern)
    _unique(args.images, "images")
    plan = _plan(args, args.images)
    out = plan.add("--json", args.json, stdout_ok=True)
    imgs = {}
    for p in args.images:
        try:
            img = read_image(p)
            imgs[p] = img.astype(np.uint8 if img.max() <= 255 else np.uint16)
        except ImageInputError as exc:
            log.warning("%s: skipped: %s", p, exc)
    model, failed = calibrate_chessboard(imgs, (cols, rows), args.square,
                                         fix_k3=args.fix_k3, fix_aspect=args.fix_aspect)
    for k, v in failed.items():
        log.warning("%s: skipped: %s", k, v)
    K, D, u = model.camera_matrix, model.dist_coeffs, model.u or {}
    print(f"{model.views} views, RMS reprojection {model.rms_px:.3f} px")
    for name, rms in (model.per_view_rms_px or {}).items():
        print(f"    {name}: RMS {rms:.3f} px")
    vals = dict(zip(("fx", "fy", "cx", "cy"), (K[0, 0], K[1, 1], K[0, 2], K[1, 2]),
                    strict=True))
    print(" ".join(f"{k} {v:.2f} ± {u.get(k, np.nan):.2f}" for k, v in vals.items()) + " px")
    print("distortion " + " ".join(f"{k} {v:+.5f} ± {u.get(k, np.nan):.5f}"
                                   for k, v in zip(("k1", "k2", "p1", "p2", "k3"), D[:5],
                                                   strict=False)))
    if out is not None:
        _wrote(write_json(out, camera_document(model, _settings(args), args.images),
                          args.force))
    return 0


# ----------------------------------------------------------------------------- calibrate

def cmd_calibrate(args: argparse.Namespace) -> int:
    from align.calibration import STATIC, StaticSettings, calibrate, read_poses
    from align.calibration.output import calibration_document
    from align.warnings import calibration_warnings
    from axisbase.output import write_json
    from axisbase.table import OUTPUT_UNITS

    inputs = [args.static] + ([args.check] if args.check else [])
    _unique(inputs, "static/--check")
    signs = _signs(args.scale_sign)
    # .mat/.npz arrays have no header to carry a unit: --units (else V) says it. The static
    # file sets the unit; a check file's header must agree with it (not set it).
    tables = [p for p in inputs if Path(p).suffix.lower() not in (".mat", ".npz")]
    cols, units = _table_options(args, [p for p in tables if p == args.static], STATIC)
    if args.check in tables:
        from axisbase.table import header_units, resolve_units

        said = f"--units {units}"
        if not args.units:
            known = args.static in tables and header_units(args.static, STATIC, cols,
                                                            ("ux", "uy", "uz"))
            said = f"{args.static} ({units}{'' if known else ', no unit in its header'})"
        resolve_units(units, [args.check], STATIC, cols, ("ux", "uy", "uz"), flag=said)
    plan = _plan(args, inputs)
    out = plan.add("--json", args.json, stdout_ok=True)
    plot = plan.add("--plot", args.plot, folder=True)
    settings = StaticSettings(args.window, args.threshold, args.min_static, args.margin,
                              args.split_sigma, args.split_deg)
    poses, intervals = read_poses(args.static, settings, columns=cols, rate_hz=args.rate)
    check = (read_poses(args.check, settings, calibration=False, columns=cols,
                        rate_hz=args.rate)[0] if args.check else None)
    if intervals is not None:
        print(f"{len(intervals)} static intervals found:")
        for iv in intervals:
            print(f"  {iv.start_s:9.2f}-{iv.end_s:9.2f} s ({iv.duration_s:6.1f} s, "
                  f"{iv.samples} samples), mean {' '.join(f'{v:.6g}' for v in iv.mean)}, "
                  f"noise {' '.join(f'{v:.3g}' for v in iv.std)}")
    cal = calibrate(poses, signs, alpha=args.alpha,
                    fixture_error_rad=args.fixture_error * DEG)
    from align.calibration.units import unit_scale_check

    unit_warnings = unit_scale_check(cal.model, units, f"--units {units}" if args.units else
                                     f"{args.static}: header unit [{units}]")
    m, a = cal.model, cal.algebraic
    ku = OUTPUT_UNITS[units]
    sign_note = ("negative" if all(s < 0 for s in signs) else "positive"
                 if all(s > 0 for s in signs) else "mixed")
    print(f"{len(poses.u)} poses in {units}; scale-factor signs {signs} ({sign_note}: an "
          "ellipsoid cannot tell them, --scale-sign sets them)")
    if cal.method == "known-pose":
        kf = cal.known
        from collections import Counter

        used = Counter(kf.faces)
        faces = ", ".join(f"{f} x{c}" if c > 1 else f for f, c in sorted(used.items()))
        print(f"known-pose (six-position) method on faces {faces}: fixture error "
              f"{args.fixture_error:g}° declared; chi2 {kf.chi2:.3g} on {kf.dof} dof")
    elif cal.known is not None:
        print("the six faces are among the poses: known-pose fit run too, cross-check below")
    heads = (("algebraic (paper)", "ML refined") if cal.method == "ellipsoid"
             else ("known-pose (GLS)", "(the same)"))
    print(f"{'':14s} {heads[0]:>22s} {heads[1]:>16s} {'u':>10s}")
    sa, sm, su = a.sensitivity(), m.sensitivity(), m.sensitivity_u()
    for i, ax in enumerate("xyz"):  # per g along each sensitive axis (k_i |r_i|)
        print(f"{f'k_{ax} [{ku}]':14s} {sa[i]:22.7f} {sm[i]:16.7f} {su[i]:10.2g}")
    for i, ax in enumerate("xyz"):
        print(f"{f'beta_{ax} [µrad]':14s} {a.beta[i] * 1e6:22.3f} {m.beta[i] * 1e6:16.3f} "
              f"{m.u_of(f'beta_{ax}') * 1e6:10.3g}")
    for i, ax in enumerate("xyz"):
        print(f"{f'b_{ax} [µg]':14s} {a.bias[i] * 1e6:22.3f} {m.bias[i] * 1e6:16.3f} "
              f"{m.u_of(f'bias_{ax}') * 1e6:10.3g}")
    for line in cal.effect_lines():
        print("  " + line)
    if cal.cross_check:
        print("cross-check ellipsoid vs known-pose (difference / combined u): "
              + ", ".join(f"{n} {v['z']:+.1f}" for n, v in cal.cross_check.items()))
    checked = None
    if check is not None:
        from align.calibration.check import check_poses

        checked = check_poses(cal, poses, check, args.alpha, f"{args.check}")
        print("check poses |a| - 1 [µg]: " + " ".join(f"{d * 1e6:+.2f}" for d in checked.dg))
        print("              z (/ u): " + " ".join(f"{z:+.2f}" for z in checked.z))
    warnings = (calibration_warnings(cal, poses) + unit_warnings
                + (list(checked.warnings) if checked is not None else []))
    _warn(warnings)
    if plot is not None:
        from align.plots import plot_calibration

        print(f"plot: {plot_calibration(cal, poses, check, plot)}")
        if intervals is not None:
            from align.calibration.plots import plot_static

            print(f"plot: {plot_static(args.static, settings, cols, args.rate, plot)}")
    if out is not None:
        doc = calibration_document(cal, poses, units, intervals, check, warnings,
                                   _settings(args), inputs, checked)
        _wrote(write_json(out, doc, args.force))
    return 0 if checked is None or checked.ok else 2


def cmd_tilt(args: argparse.Namespace) -> int:
    from align.apply import load_tilt_calibration
    from align.calibration import READINGS, read_readings
    from align.documents import tilt_document
    from align.tilt import tilt_of_readings
    from axisbase.output import write_atomic, write_json

    inputs = [args.readings, args.calibration]
    _unique(inputs, "readings/--calibration")
    cols, units = _table_options(args, [args.readings], READINGS, default=None)
    model, cal_units = load_tilt_calibration(args.calibration)
    _same_units(units, cal_units, args.calibration)
    plan = _plan(args, inputs)
    out_json = plan.add("--json", args.json, stdout_ok=True)
    out_csv = plan.add("--out", args.out)
    tab = read_readings(args.readings, cols, args.rate)
    res = tilt_of_readings(model, tab, args.method, args.mu)
    s = res.to_dict()
    print(f"{s['samples']} readings ({args.method} roll, {s['frame']} frame): "
          f"roll {s['roll_deg_mean']:+.6f}° "
          f"(sd {s['roll_deg_std'] * 3600:.1f}″), pitch {s['pitch_deg_mean']:+.6f}° "
          f"(sd {s['pitch_deg_std'] * 3600:.1f}″), |a| - 1 mean {s['norm_minus_1_ug']:+.2f} µg")
    _warn(res.warnings)
    if out_csv is not None:
        _wrote(write_atomic(out_csv, res.csv_text(), args.force))
    if out_json is not None:
        _wrote(write_json(out_json, tilt_document(res, _settings(args), inputs), args.force))
    return 0


def _same_units(units: str | None, cal_units: str | None, where: str) -> None:
    """Readings whose unit is stated (flag or header) must be in the calibration's unit; if
    unstated they are taken to be."""
    if units is not None and cal_units is not None and units != cal_units:
        raise UsageError(f"the readings are in {units} but {where} was calibrated from "
                         f"{cal_units} (--units, or the header's unit)")


# ----------------------------------------------------------------------------- gonio

def _faces(text: str) -> list[str]:
    faces = [f.strip() for f in text.split(",")]
    if any(not f for f in faces):
        raise UsageError(f"--faces {text!r}: an empty face name")
    if len(faces) < 2:
        raise UsageError("--faces needs at least two names, e.g. ref,z,y,x")
    _unique(faces, "--faces", what="name")
    return faces


def _nominal(text: str | None, n: int) -> list[float] | None:
    import math

    if not text:
        return None
    try:
        deg = [float(v) for v in text.split(",")]
    except ValueError:
        raise UsageError(f"--nominal {text!r}: numbers in degrees") from None
    if len(deg) != n:
        raise UsageError(f"--nominal has {len(deg)} values for {n} faces")
    if not all(math.isfinite(v) and 0 < v < 360 for v in deg):
        raise UsageError(f"--nominal {text!r}: each angle must be in (0, 360) degrees")
    if abs(sum(deg) - 360) > 1e-6:
        raise UsageError(f"--nominal {text!r}: the angles of a full turn must sum to 360, "
                         f"not {sum(deg):g}")
    return deg


def _distinct_files(a: str, b: str, flag_a: str, flag_b: str) -> None:
    """Two inputs that must be different recordings: not the same file, not a copy."""
    from axisbase.provenance import sha256_file

    pa, pb = Path(a), Path(b)
    if pa.resolve() == pb.resolve():
        raise UsageError(f"{flag_b} {b}: is the same file as {flag_a}")
    try:
        same = (pa.stat().st_size == pb.stat().st_size and sha256_file(pa) == sha256_file(pb))
    except OSError:
        return  # the reader names the problem
    if same:
        raise UsageError(f"{flag_b} {b}: has the same contents as {flag_a} {a}; the other "
                         "direction is a different recording")


def _latitude_range(text: str) -> list[float]:
    """argparse type of ``--latitude-range LO,HI`` [deg]."""
    import math

    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: two latitudes LO,HI in degrees") from None
    if not all(math.isfinite(v) and -90 <= v <= 90 for v in (lo, hi)) or lo > hi:
        raise argparse.ArgumentTypeError(f"{text}: need -90 <= LO <= HI <= 90")
    return [lo, hi]


def cmd_gonio(args: argparse.Namespace) -> int:
    import numpy as np

    # (align.documents and align.warnings import the loop, i.e. scipy: after the pass, which
    # imports it on a thread while it waits on the parser)
    from align.gonio import measure_log
    from axisbase.table import parse_column_map
    from goniometry import FaceCountError, kept_table

    faces = _faces(args.faces)
    nominal_deg = _nominal(args.nominal, len(faces))
    nominal = None if nominal_deg is None else np.deg2rad(nominal_deg)
    inputs = [args.log] + ([args.reverse_log] if args.reverse_log else [])
    if args.reverse_log:
        _distinct_files(args.log, args.reverse_log, "log", "--reverse-log")
    cols = parse_column_map(args.columns)
    plan = _plan(args, inputs)
    out = plan.add("--json", args.json, stdout_ok=True)
    plot = plan.add("--plot", args.plot, folder=True)
    d = 1 if args.direction == "ccw" else -1
    if args.latitude is not None and args.latitude_range is not None:
        raise UsageError("--latitude-range: give it or --latitude, not both")
    try:
        run = measure_log(args.log, len(faces), args.latitude, d, args.alpha,
                          reverse_log=args.reverse_log, steady_table=args.steady_table,
                          columns=cols, latitude_range_deg=args.latitude_range)
    except FaceCountError as exc:
        raise UsageError(f"--faces {args.faces}: names {exc.named} faces, but {exc.path} has "
                         f"{exc.found} pulses per revolution") from None
    from align.documents import gonio_document
    from align.warnings import gonio_warnings
    from axisbase.output import write_json

    summary, fa, loop = run.summary, run.angles, run.loop
    print(f"{summary.rows} rows, {fa.revolutions} revolutions used, {fa.counts_per_rev:.2f} "
         f"counts per revolution ({np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count)")
    for reason, n in summary.exclusions.counts.items():
        lines = ", ".join(map(str, summary.exclusions.lines[reason][:10]))
        print(f"  {n} x {reason} (lines {lines}{', ...' if n > 10 else ''})")
    if summary.incomplete_tail:
        print(f"  last {summary.incomplete_tail} rows after the final reference pulse: an "
             "incomplete revolution, not used")
    for i, name in enumerate(faces):
        nxt = faces[(i + 1) % len(faces)]
        dev = "" if nominal is None else (
            f"  deviation {np.rad2deg(fa.angles_rad[i] - nominal[i]) * 3600:+9.3f}″")
        lock = "  (quantisation locked: not averaged)" if fa.quantisation_locked[i] else ""
        print(f"  {name:>6s} -> {nxt:<6s} {np.rad2deg(fa.angles_rad[i]):12.7f}° "
             f"± {np.rad2deg(fa.u_rad[i]) * 3600:.3f}″{dev}{lock}")
    if loop is not None:
        for line in loop.summary_lines():
            print("  " + line)
    for note in run.notes:
        print("  " + note)
    # (the document hashes the logs: only when written)
    _warn(gonio_warnings(run, faces, nominal))
    if plot is not None:
        from align.plots import plot_gonio

        print(f"plot: {plot_gonio(kept_table(summary)[0], fa, faces, plot)}")
    if out is not None:
        _wrote(write_json(out, gonio_document(run, faces, nominal, _settings(args), inputs),
                          args.force))
    return 0


# ----------------------------------------------------------------------------- run

def _print_result(res, out=None) -> None:
    out = out or sys.stdout
    f = res.fusion
    for e in res.errors:
        print(f"  stage {e.stage}: FAILED: {e.message}", file=out)
    if f is None:
        print("  no misalignment (the fusion did not run)", file=out)
        return
    print(f"  misalignment E [″] (row: accelerometer, column: platform X Y Z), sources: "
          f"{', '.join(f.sources)}", file=out)
    for i in range(3):
        cells = ["0".rjust(17) if i == j else
                 f"{f.E[i, j] / ARCSEC:+9.2f} ± {f.E_u[i, j] / ARCSEC:5.2f}" for j in range(3)]
        print(f"    {'xyz'[i]}: " + "  ".join(cells), file=out)
    state = ("consistent" if f.consistent else
             f"NOT consistent (uncertainty inflated x{f.inflation:.2f})" if f.inflation > 1 else
             "NOT consistent (structure left in the residual: see the fusion loop)")
    print(f"  chi2 {f.chi2:.2f} / {f.dof} dof (p {f.p_value:.3g}): instruments {state}",
          file=out)
    for e in f.loop.effects:
        parts = (", ".join(f"{c} {v / ARCSEC:+.2f} ± {u / ARCSEC:.2f}″" for c, v, u in
                           e.components) if e.components
                 else f"{e.estimate / ARCSEC:+.2f} ± {e.u / ARCSEC:.2f}″")
        print(f"  fusion loop added {e.name}: {parts} (p {e.p_value:.2g}, dBIC "
              f"{e.delta_bic:.1f})", file=out)
    if f.loop.unexplained_structure:
        print("  " + f.loop.summary_lines()[-1], file=out)


def _run_one(folder: str, json_path: str | None, report_path: str | None,
             cal_path: str | None, alpha: float, quiet: bool, force: bool = False,
             allow_outside: bool = False, settings: dict | None = None) -> dict:
    """One session end to end, in this process (``align.session.batch.run_job``)."""
    from align.session.batch import SessionJob, run_job

    job = SessionJob(folder, json_path, report_path, cal_path, alpha, force, allow_outside,
                     settings or {"alpha": alpha}, keep_result=True)
    return run_job(job, progress=None if quiet else (
        lambda m: log.info("  [%s] %s", Path(folder).resolve().name, m)))


# Flags that say how a batch runs, not what it computes: left out of the results' settings,
# so a batch gives the same JSON however it is run.
_EXECUTION = ("jobs", "scheduler", "resume")


def _run_settings(args: argparse.Namespace) -> dict:
    return {k: v for k, v in _settings(args).items() if k not in _EXECUTION}


def cmd_run(args: argparse.Namespace) -> int:
    if len(args.sessions) == 1:  # in this process (--scheduler is for batches)
        if args.scheduler:
            log.info("one session: it runs here (--scheduler is for batches)")
        from align.session.batch import SessionJob, is_complete

        if args.resume and is_complete(SessionJob(args.sessions[0], args.json, args.report,
                                                  args.calibration)):
            print(f"session {args.sessions[0]}: outputs complete, skipped (--resume)")
            return 0
        out = _run_one(args.sessions[0], args.json, args.report, args.calibration,
                       args.alpha, quiet=False, force=args.force,
                       allow_outside=args.allow_outside, settings=_run_settings(args))
        if "error" in out:
            raise UsageError(out["error"])
        print(f"session {out['session']}:")
        _print_result(out["result"])
        _warn(out["warnings"])
        for k, v in out["outputs"].items():
            if v != "-":
                print(f"  wrote {k}: {v}")
        return 0 if out["ok"] else 2
    _unique(args.sessions, "sessions")
    return _run_batch(args)


def _run_batch(args: argparse.Namespace) -> int:
    """Several sessions in parallel (local processes, or a Dask cluster with --scheduler);
    --json/--report/--calibration name folders."""
    import os

    import numpy as np

    from align.session.batch import (
        batch_jobs,
        executor_for,
        is_complete,
        run_batch,
        skipped,
    )
    from axisbase.provenance import command_line
    from axisbase.stop import Stopped

    jobs = batch_jobs(args.sessions, args.json, args.report, args.calibration,
                      alpha=args.alpha, force=args.force, allow_outside=args.allow_outside,
                      settings=_run_settings(args), command=tuple(command_line()))
    results = []
    if args.resume:
        results = [skipped(j) for j in jobs if is_complete(j)]
        jobs = [j for j in jobs if not is_complete(j)]
        if results:
            log.info("--resume: %d of %d sessions already complete, skipped", len(results),
                     len(results) + len(jobs))
    scheduler = args.scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS") or None
    executor = executor_for(scheduler, args.jobs)
    if scheduler:
        log.info("running %d sessions on the Dask cluster at %s", len(jobs), scheduler)
    bar = None
    if sys.stderr.isatty() and log.getEffectiveLevel() <= logging.INFO and jobs:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc="sessions")

    done: list = []

    def on_done(r: dict) -> None:
        done.append(r)
        if bar is not None:
            bar.update()
        else:  # a log file gets one line per finished session instead of a bar
            log.info("  [%d/%d] %s finished", len(done), len(jobs), r["session"])

    try:
        run_batch(jobs, executor, on_done)
    except Stopped:
        if bar is not None:
            bar.close()
        print(f"stopped: {len(done)} of {len(jobs)} sessions finished (their outputs are "
              "complete; no other session left any); 'align run ... --resume' does the rest",
              file=sys.stderr)
        raise
    finally:
        if bar is not None:
            bar.close()
    results += done
    failed = [r for r in results if not r["ok"]]
    for r in sorted(results, key=lambda r: r["session"]):
        js = r.get("json")
        if js is not None and js.get("misalignment_arcsec") is not None:
            E = np.array(js["misalignment_arcsec"])
            U = np.array(js["misalignment_u_arcsec"])
            worst = float(np.max(np.abs(E)))
            print(f"{r['session']}: {'OK' if r['ok'] else 'FAILED stages'}, |E| max "
                  f"{worst:.1f}″, u max {U.max():.2f}″, chi2/dof {js['chi2']:.1f}/{js['dof']}"
                  + ("" if not js["unexplained_structure"] else ", NOT consistent")
                  + (" (complete before, skipped)" if r.get("skipped") else "")
                  + "".join(f", {k} {v}" for k, v in r["outputs"].items()))
        elif r.get("skipped"):
            print(f"{r['session']}: complete before, skipped"
                  + "".join(f", {k} {v}" for k, v in r["outputs"].items()))
        if not r["ok"]:
            msg = r.get("error") or "; ".join(f"{e['stage']}: {e['message']}"
                                              for e in (js or {}).get("errors", []))
            log.error("%s: FAILED: %s", r["session"], msg)
    print(f"{len(results) - len(failed)} of {len(results)} sessions done"
          + (f", {len(failed)} failed" if failed else ""))
    if any(not r["ok"] and not r.get("bad_input", False) for r in results):
        return 1
    return 2 if failed else 0


# ----------------------------------------------------------------------------- apply

def cmd_apply(args: argparse.Namespace) -> int:
    from align.apply import PlatformCalibration, apply_to_readings
    from align.calibration import READINGS, read_readings
    from axisbase.output import write_atomic

    inputs = [args.calibration_file, args.readings]
    _unique(inputs, "calibration_file/readings")
    cols, units = _table_options(args, [args.readings], READINGS, default=None)
    pc, cal_units = PlatformCalibration.load_with_units(args.calibration_file)
    _same_units(units, cal_units, args.calibration_file)
    plan = _plan(args, inputs)
    out = plan.add("--out", args.out)
    tab = read_readings(args.readings, cols, args.rate)
    res = apply_to_readings(pc, tab, tilt=args.tilt, method=args.method)
    print(f"{res.samples} readings -> platform frame; mean a = "
          + " ".join(f"{v:+.7f}" for v in res.mean_g) + " g")
    _warn(res.warnings)
    _wrote(write_atomic(out, res.csv_text(), args.force))
    return 0


# ----------------------------------------------------------------------------- lot

def cmd_lot(args: argparse.Namespace) -> int:
    from align.lot import analyse, lot_outputs, read_results, result_files

    files = result_files(args.results)
    plan = _plan(args, files)
    outs = {"json": plan.add("--json", args.json, stdout_ok=True),
            "csv": plan.add("--csv", args.csv), "report": plan.add("--report", args.report)}
    read = read_results(files)
    lot = analyse([r.unit for r in read if r.unit is not None],
                  [r.rejected for r in read if r.rejected is not None],
                  None if args.tolerance_arcsec is None else args.tolerance_arcsec * ARCSEC)
    written, doc = lot_outputs(lot, read, outs, args.force, _settings(args))
    print(f"lot: {len(lot.units)} session results ({len(lot.in_stats)} ok, in the "
          f"statistics), {len(lot.rejected)} files not read; run order {lot.run_order_note}")
    for a in doc["angles"]:
        c, cap = a["control_chart"], a["capability"]
        line = f"  {a['name']}: n {a['n']}"
        if c is not None:
            line += (f", mean {a['mean_arcsec']:+.2f}″, σ_w {c['sigma_within_arcsec']:.2f}″, "
                     f"limits {c['lcl_arcsec']:+.2f} … {c['ucl_arcsec']:+.2f}″, "
                     f"{len(a['outside_limits'])} outside")
        if cap is not None:
            line += (f"; Cpk {cap['cpk']:.2f} ± {cap['cpk_u']:.2f}, "
                     f"{len(a['outside_tolerance'])} outside ±{args.tolerance_arcsec:g}″")
        print(line)
    _warn(doc["warnings"])
    for k, v in written.items():
        if str(v) != "-":
            print(f"  wrote {k}: {v}")
    return 0 if lot.ok else 2


# ----------------------------------------------------------------------------- synth

def cmd_synth(args: argparse.Namespace) -> int:
    from synth.session import EFFECTS, SessionSpec, write_session

    def parse(items: Sequence[str], flag: str) -> dict[str, float]:
        import math

        out = {}
        for it in items:
            name, _, val = it.partition("=")
            if name not in EFFECTS:
                raise UsageError(f"{flag} {name!r}: unknown effect; known: " + ", ".join(
                    f"{k} [{u or '-'}] ({d})" for k, (u, d) in EFFECTS.items()))
            if name in out:
                raise UsageError(f"{flag} {name}: given twice")
            try:
                out[name] = float(val)
            except ValueError:
                raise UsageError(f"{flag} {it!r}: expected NAME=NUMBER") from None
            if not math.isfinite(out[name]):
                raise UsageError(f"{flag} {it!r}: not a finite number")
        return out

    declared = parse(args.effect, "--effect")
    undeclared = parse(args.undeclared, "--undeclared")
    both = set(declared) & set(undeclared)
    if both:
        raise UsageError(f"--effect and --undeclared both name {', '.join(sorted(both))}")
    spec = SessionSpec(seed=args.seed, effects={**declared, **undeclared},
                       undeclared=frozenset(undeclared))
    out = Path(args.out)
    if args.force and out.exists() and any(out.iterdir()):
        import shutil

        _replaceable_synth(out, "out")
        shutil.rmtree(out)
    try:
        write_session(out, spec)
    except FileExistsError as exc:
        raise UsageError(f"{exc} (--force replaces a folder 'align synth' wrote)") from None
    except ValueError as exc:  # synth's refusal of an effect it cannot render
        raise UsageError(str(exc)) from None
    print(f"wrote session {args.out} (seed {args.seed}; truth in {Path(args.out) / 'truth.json'})")
    for k, v in {**declared, **undeclared}.items():
        print(f"  effect {k} = {v} {EFFECTS[k][0]} "
              f"({'undeclared' if k in undeclared else 'declared in session.toml'})")
    return 0


def _replaceable_synth(folder: Path, flag: str) -> None:
    """--force replaces a synthetic session folder only if synth wrote it (it holds the
    truth.json synth writes): a folder of the user's own is never deleted."""
    if not (folder / "truth.json").is_file():
        raise UsageError(f"{flag} {folder}: not a session written by 'align synth' (no "
                         "truth.json); --force replaces only those — choose a new folder")


# ----------------------------------------------------------------------------- demo

def cmd_demo(args: argparse.Namespace) -> int:
    """Synthesise a session with known truth, run it, print the matrix and its error."""
    import shutil
    import tempfile

    from align.session import truth_errors
    from synth.session import SessionSpec, write_session

    folder = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="align-demo-"))
    session = folder / "session"
    if args.out and folder.exists() and any(folder.iterdir()):
        if not args.force:
            raise UsageError(f"--out {folder}: exists and is not empty; choose a new folder "
                             "or pass --force (a previous demo's session/ and outputs are "
                             "replaced)")
        if session.exists():
            _replaceable_synth(session, "--out")
            shutil.rmtree(session)
    roll = 30.0
    print(f"demo: writing a synthetic session to {session} (seed {args.seed}): 8 mark images "
          "from two cameras (each with a reversal), a ring-laser counter log, a 14-pose "
          f"tumble and 8 platform poses; camera A rolled by {roll:.0f}″, NOT declared")
    truth = write_session(session, SessionSpec(seed=args.seed,
                                               effects={"camera_roll_A": roll},
                                               undeclared=frozenset({"camera_roll_A"})))
    report = folder / "report.html"
    out = _run_one(str(session), str(folder / "result.json"), str(report),
                   str(folder / "platform_calibration.json"), 1e-3, quiet=False,
                   force=args.force, settings=_settings(args))
    if "error" in out:
        raise UsageError(out["error"])
    res = out["result"]
    print(f"\nsession {out['session']}:")
    _print_result(res)
    _warn(out["warnings"])
    if res.fusion is not None:
        err, z_rms = truth_errors(res.fusion, truth)
        print("  error against truth [″]:")
        for i in range(3):
            print("    " + "xyz"[i] + ": " + "  ".join(
                "0".rjust(8) if i == j else f"{err[i, j] / ARCSEC:+8.3f}" for j in range(3)))
        print(f"  normalised errors (error / u): RMS {z_rms:.2f}")
    print()
    for k, v in out["outputs"].items():
        print(f"{k}: {v}")
    return 0 if out["ok"] else 2


# ----------------------------------------------------------------------------- main

def _progress(items: Sequence[str], desc: str):
    if len(items) < 4 or not sys.stderr.isatty() or log.getEffectiveLevel() > logging.INFO:
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc)


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line naming the flag (not the whole usage block)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


_FMT = argparse.ArgumentDefaultsHelpFormatter


def _common() -> argparse.ArgumentParser:
    c = argparse.ArgumentParser(add_help=False)
    g = c.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true",
                   help="only warnings and errors on stderr (no progress)")
    g.add_argument("-v", "--verbose", action="store_true", help="debugging messages on stderr")
    return c


def _writes() -> argparse.ArgumentParser:
    w = argparse.ArgumentParser(add_help=False)
    w.add_argument("--force", action="store_true",
                   help="replace output files that exist (inputs are never replaced)")
    return w


def _tables(rate: bool = True, units: bool = True,
            example: str = "ux=ax,uy=ay,uz=az") -> argparse.ArgumentParser:
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
    return t


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="align", description=__doc__.splitlines()[0], formatter_class=_FMT)
    p.add_argument("--version", action="version", version=f"axis-align {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND", parser_class=_Parser)
    common, writes = _common(), _writes()

    def add(name: str, help: str, *parents: argparse.ArgumentParser) -> argparse.ArgumentParser:
        return sub.add_parser(name, help=help, description=help, formatter_class=_FMT,
                              parents=[common, *parents])

    m = add("marks", "measure scribe marks in images", writes)
    m.add_argument("images", nargs="+", help="image files (PNG, TIFF, JPEG; 8 or 16 bit)")
    m.add_argument("--camera", help="camera model JSON written by 'align camera' (trusted: "
                   "applied, its u propagated, no distortion fitted on top)")
    m.add_argument("--lens", metavar="KEY=V,...",
                   help="plausible lens without --camera (Type B ranges; keys k1, k2, p at the "
                   "image half-diagonal, aspect, pp_px [px], max_u_arcsec; defaults k1=0.3,"
                   "k2=0.05,p=0.001,aspect=0.005,pp_px=20,max_u_arcsec=60; all 0: declared "
                   "distortion-free)")
    m.add_argument("--json", help="write results to this new JSON file ('-': stdout)")
    m.add_argument("--plot", help="folder for one PNG per mark (line + residuals)")
    m.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    m.add_argument("--max-marks", type=_number(1, 1000, integer=True), default=8,
                   help="most marks reported per image")
    m.add_argument("--roi", metavar="X,Y,W,H",
                   help="search only this rectangle [px]: top-left column, row, width, height")
    m.add_argument("--min-length", type=POSITIVE, metavar="PX",
                   help="shortest mark to report [px] (default 100, at most 80 %% of the "
                   "image's smaller side)")
    m.add_argument("--one", action="store_true",
                   help="each image holds one mark: two competing marks are an error")
    m.set_defaults(func=cmd_marks)

    c = add("camera", "calibrate a camera from chessboard photographs", writes)
    c.add_argument("images", nargs="+", help="chessboard photographs")
    c.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS")
    c.add_argument("--square", type=POSITIVE, default=1.0, help="square size (any unit)")
    c.add_argument("--json", help="write the camera model to this new JSON file ('-': stdout)")
    c.add_argument("--fix-k3", action="store_true", help="keep k3 at 0")
    c.add_argument("--fix-aspect", action="store_true", help="keep fx/fy at 1")
    c.set_defaults(func=cmd_camera)

    k = add("calibrate", "ellipsoid calibration of the triad from static poses", writes,
            _tables())
    k.add_argument("static", help="pose,ux,uy,uz[,t][,temp] or a recording t,ux,uy,uz (CSV), "
                   "or a .mat/.npz with named arrays (--columns u=NAME,t=NAME)")
    k.add_argument("--check", help="check poses (same format): |a| - 1 per pose")
    k.add_argument("--json", help="write results (and the model for tilt/apply) to a new file "
                   "('-': stdout)")
    k.add_argument("--plot", help="folder for the dg-per-pose / residual figure")
    k.add_argument("--scale-sign", default="+", help="signs of k: +, - or e.g. -,-,-")
    k.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    k.add_argument("--window", type=POSITIVE, default=0.25,
                   help="static detection window [s] (at least 5 samples)")
    k.add_argument("--threshold", type=_number(1, None, lo_open=True), default=3.0,
                   help="static if the moving std < this x the recording's own noise "
                   "(estimated from its quietest windows)")
    k.add_argument("--min-static", type=POSITIVE, default=0.5,
                   help="shortest static interval kept [s]")
    k.add_argument("--margin", type=_number(0), default=0.1, help="cut from each end [s]")
    k.add_argument("--split-sigma", type=POSITIVE, default=8.0,
                   help="split an interval whose mean moves by more than this many standard "
                   "errors ...")
    k.add_argument("--split-deg", type=_number(0), default=1.0,
                   help="... and by more than this tilt [deg] (a slow turn, not settling)")
    k.add_argument("--fixture-error", type=_number(0, 90), default=0.5, metavar="DEG",
                   help="placement error of the faces +x,-x,... (known-pose method) [deg]")
    k.set_defaults(func=cmd_calibrate)

    tl = add("tilt", "roll and pitch from readings through a calibration", writes, _tables())
    tl.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    tl.add_argument("--calibration", required=True,
                    help="JSON written by 'align calibrate' (roll/pitch of the triad's own "
                    "frame) or a platform calibration / session result from 'align run' "
                    "(roll/pitch of the platform, as 'align apply --tilt')")
    tl.add_argument("--method", choices=["exact", "paper"], default="exact",
                    help="exact atan2 roll, or the tilt paper's regularised one")
    tl.add_argument("--mu", type=_number(0, 1, lo_open=True), default=0.001,
                    help="the paper's regulariser (--method paper)")
    tl.add_argument("--json", help="summary JSON ('-': stdout)")
    tl.add_argument("--out", help="per-reading CSV t,roll_deg,pitch_deg (a new file)")
    tl.set_defaults(func=cmd_tilt)

    g = add("gonio", "face angles from a ring-laser counter log", writes,
            _tables(rate=False, units=False, example="count=periods,counter=channel,ref=index"))
    g.add_argument("log", help="CSV count,counter,ref[,t]")
    g.add_argument("--faces", required=True, help="face names in passing order, e.g. ref,z,y,x")
    g.add_argument("--nominal", help="nominal angles [deg] summing to 360, e.g. 90,90,90,90")
    g.add_argument("--latitude", type=_number(-90, 90), metavar="DEG",
                   help="site latitude [deg] (Earth-rate correction)")
    g.add_argument("--latitude-range", type=_latitude_range, metavar="LO,HI",
                   help="without --latitude: the latitudes the site may have [deg]; bounds "
                   "the Earth-rate term carried in u (default: all latitudes)")
    g.add_argument("--direction", choices=["ccw", "cw"], default="ccw",
                   help="table rotation seen from above")
    g.add_argument("--reverse-log", help="a log of the same faces with the table turning the "
                   "other way: the angles are then the mean of both directions")
    g.add_argument("--steady-table", action="store_true",
                   help="the table turns at constant speed: angles from the pulse times "
                   "(below the count quantisation) when the counts confirm it")
    g.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    g.add_argument("--plot", help="folder for angle-per-revolution / Allan / spectrum figure")
    g.add_argument("--json", help="results JSON ('-': stdout)")
    g.set_defaults(func=cmd_gonio)

    r = add("run", "run whole sessions: every stage, the loops, the fusion", writes)
    r.add_argument("sessions", nargs="+", help="session folder(s) holding session.toml")
    r.add_argument("--json", help="result JSON (a folder when several sessions; '-': stdout)")
    r.add_argument("--report", help="HTML report (a folder when several sessions)")
    r.add_argument("--calibration", help="platform calibration JSON for 'align apply' "
                   "(a folder when several sessions)")
    r.add_argument("--jobs", type=_number(1, 1024, integer=True),
                   help="parallel sessions (default: all cores)")
    r.add_argument("--alpha", type=ALPHA, default=1e-3,
                   help="significance of the residual loops' tests")
    r.add_argument("--allow-outside", action="store_true",
                   help="let session.toml name files outside the session folder")
    r.add_argument("--resume", action="store_true",
                   help="skip sessions whose outputs are all in place (an interrupted batch) "
                   "and run the rest")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the sessions of a batch on this Dask scheduler, e.g. "
                   "tcp://host:8786 (default: $DASK_SCHEDULER_ADDRESS, else local processes)")
    r.set_defaults(func=cmd_run)

    ap = add("apply", "readings -> specific force in the platform frame", writes, _tables())
    ap.add_argument("calibration_file", help="JSON from 'align run --calibration' or --json")
    ap.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    ap.add_argument("--out", required=True, help="new CSV t,ax_g,ay_g,az_g[,roll_deg,pitch_deg]")
    ap.add_argument("--tilt", action="store_true", help="add roll and pitch columns")
    ap.add_argument("--method", choices=["exact", "paper"], default="exact",
                    help="roll formula for --tilt")
    ap.set_defaults(func=cmd_apply)

    lt = add("lot", "a production lot: control charts, outliers, capability, metadata",
             writes)
    lt.add_argument("results", nargs="+",
                    help="session results ('align run --json') or folders of them (*.json)")
    lt.add_argument("--report", help="HTML report of the lot (a new file)")
    lt.add_argument("--csv", help="CSV with one row per unit (a new file)")
    lt.add_argument("--json", help="lot JSON ('-': stdout)")
    lt.add_argument("--tolerance-arcsec", type=POSITIVE, metavar="T",
                    help="tolerance ±T [″] on every angle: flags and process capability")
    lt.set_defaults(func=cmd_lot)

    sy = sub.add_parser("synth", help="write synthetic data with known truth",
                        formatter_class=_FMT)
    sy_sub = sy.add_subparsers(dest="what", required=True, parser_class=_Parser)
    ss = sy_sub.add_parser("session", help="a complete synthetic session folder",
                           formatter_class=_FMT, parents=[common, writes])
    ss.add_argument("out", help="new folder (must not exist or be empty)")
    ss.add_argument("--seed", type=_number(0, 2**63 - 1, integer=True), default=0,
                    help="random seed (the same seed gives the same session)")
    ss.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data and declared in session.toml (e.g. "
                    "camera_roll_A=30 [arcsec]; an unknown name lists them all)")
    ss.add_argument("--undeclared", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data but not declared")
    ss.set_defaults(func=cmd_synth)

    d = add("demo", "synthesise a session with known truth and run it", writes)
    d.add_argument("--out", help="folder for the session and outputs (default: a new temp folder)")
    d.add_argument("--seed", type=_number(0, 2**63 - 1, integer=True), default=1,
                   help="random seed")
    d.set_defaults(func=cmd_demo)
    return p


# ----------------------------------------------------------------------------- console

_ASCII = {"″": '"', "′": "'", "±": "+/-", "µ": "u", "°": " deg", "²": "^2", "³": "^3",
          "χ": "chi", "α": "alpha", "β": "beta", "σ": "sigma", "Δ": "d", "×": "x", "→": "->",
          "≤": "<=", "≥": ">=", "≈": "~", "−": "-", "—": "-", "–": "-", "√": "sqrt", "·": "*"}


def _ascii_fallback(exc: UnicodeError) -> tuple[str, int]:
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    bad = exc.object[exc.start:exc.end]
    return "".join(_ASCII.get(ch, "?") for ch in bad), exc.end


codecs.register_error("align-ascii", _ascii_fallback)


class _ClosedPipeSafe:
    """A text stream that stops writing, quietly, once its reader has gone (``| head -1``):
    the run goes on and its files are still written."""

    def __init__(self, stream):
        self._s = stream
        self.closed_pipe = False

    def write(self, text: str) -> int:
        if not self.closed_pipe:
            try:
                return self._s.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.closed_pipe:
            try:
                self._s.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        import os

        self.closed_pipe = True
        try:  # no further flush at exit may raise either
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._s.fileno())
        except (OSError, ValueError):
            pass

    def __getattr__(self, name: str):
        return getattr(self._s, name)


def _console(stream):
    """``stream`` with an ASCII fallback for ″ ± µ ° when its encoding cannot show them
    (LANG=C, PYTHONIOENCODING=ascii, a Windows code page) and a quiet end on a closed pipe."""
    if isinstance(stream, _ClosedPipeSafe):
        return stream
    try:
        "″±µ°".encode(stream.encoding or "ascii")
    except (UnicodeEncodeError, LookupError):
        try:
            stream.reconfigure(errors="align-ascii")
        except (AttributeError, ValueError):
            pass
    except AttributeError:
        pass
    return _ClosedPipeSafe(stream)


def _logging(args: argparse.Namespace) -> None:
    level = (logging.WARNING if getattr(args, "quiet", False) else
             logging.DEBUG if getattr(args, "verbose", False) else logging.INFO)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    given_out, given_err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _console(sys.stdout), _console(sys.stderr)
    try:
        return _main(argv)
    finally:
        for s in (sys.stdout, sys.stderr):
            try:
                s.flush()
            except (OSError, ValueError):
                pass
        sys.stdout, sys.stderr = given_out, given_err


def _main(argv: list[str]) -> int:
    from axisbase.output import set_real_stdout
    from axisbase.provenance import set_command
    from axisbase.stop import Stopped, raise_on_signals, restore

    parser = build_parser()
    try:
        args = parser.parse_args(_attach_signs(argv))
    except SystemExit as exc:
        return int(exc.code or 0) and 2
    _logging(args)
    set_command(["align", *argv])
    real_stdout = sys.stdout
    set_real_stdout(real_stdout)
    handlers = raise_on_signals()  # SIGTERM unwinds like Ctrl-C: no half-written outputs
    if getattr(args, "json", None) == "-":
        # The JSON owns standard output: messages go to stderr, or nowhere with -q (which
        # leaves stderr to warnings and errors).
        sys.stdout = io.StringIO() if getattr(args, "quiet", False) else sys.stderr
    try:
        return int(args.func(args))
    except InputError as exc:
        print(f"align {args.cmd}: {exc}", file=sys.stderr)
        return 2
    except Stopped as stop:
        print(f"align {args.cmd}: stopped ({stop})", file=sys.stderr)
        return stop.exit_status
    except KeyboardInterrupt:
        print(f"align {args.cmd}: interrupted", file=sys.stderr)
        return 130
    except Exception:
        import traceback

        print(f"align {args.cmd}: internal error (please report):", file=sys.stderr)
        traceback.print_exc()
        return 1
    finally:
        sys.stdout = real_stdout
        restore(handlers)


if __name__ == "__main__":
    sys.exit(main())
