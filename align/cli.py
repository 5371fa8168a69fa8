"""The ``align`` command. Exit status: 0 success, 2 bad input or usage, 1 internal error.

Degrees, arc-seconds and pixels appear only here and in files; the library works in radians.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import traceback
from collections.abc import Sequence
from pathlib import Path

import numpy as np

ARCSEC = np.pi / 180 / 3600


class UsageError(Exception):
    """Bad input the user can fix (exit status 2)."""


def _new_file(path: str | None, force: bool, inputs: Sequence[str] = ()) -> Path | None:
    """An output path that will not overwrite anything the user gave."""
    if path is None:
        return None
    p = Path(path)
    if any(p.resolve() == Path(i).resolve() for i in inputs):
        raise UsageError(f"{p}: is one of the inputs; refusing to write over it")
    if p.exists() and not force:
        raise UsageError(f"{p}: exists; choose a new name or pass --force")
    return p


def _write_json(path: Path | None, data: dict) -> None:
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(data, indent=2, default=float))
        print(f"wrote {path}")


# ----------------------------------------------------------------------------- marks

def cmd_marks(args: argparse.Namespace) -> int:
    from align.marks import measure_file
    from align.plots import plot_mark
    from imaging import CameraModel, ImageInputError

    camera = None
    if args.camera:
        try:
            camera = CameraModel.load(args.camera)
        except ImageInputError as exc:
            raise UsageError(str(exc)) from None
    out = _new_file(args.json, args.force, args.images)
    plot_dir = Path(args.plot) if args.plot else None
    results = []
    failed = 0
    for path in _progress(args.images, "marks"):
        res = measure_file(path, camera, alpha=args.alpha, max_marks=args.max_marks,
                           expect_one=args.one)
        for r in res:
            results.append(r)
            if not r.found:
                failed += 1
                print(f"{path}: FAILED: {r.error}", file=sys.stderr)
                continue
            print(f"{path} mark {r.index}: angle {np.rad2deg(r.angle_rad):+.6f}° "
                  f"± {r.angle_u_rad / ARCSEC:.2f}″, offset {r.offset_px:+.3f} px, "
                  f"length {r.length_px:.0f} px, {'dark' if r.dark else 'bright'}")
            for line in r.loop.summary_lines():
                print(f"    {line}")
            if plot_dir is not None:
                print(f"    plot: {plot_mark(r, plot_dir)}")
    _write_json(out, {"marks": [r.to_json() for r in results]})
    return 2 if failed else 0


# ----------------------------------------------------------------------------- camera

def cmd_camera(args: argparse.Namespace) -> int:
    from imaging import ImageInputError, calibrate_chessboard, read_image

    try:
        cols, rows = (int(v) for v in args.pattern.lower().split("x"))
    except ValueError:
        raise UsageError(f"--pattern {args.pattern!r}: expected COLSxROWS inner corners, "
                         "e.g. 9x6") from None
    out = _new_file(args.json, args.force, args.images)
    imgs = {}
    for p in args.images:
        try:
            img = read_image(p)
            imgs[p] = img.astype(np.uint8 if img.max() <= 255 else np.uint16)
        except ImageInputError as exc:
            print(f"{p}: skipped: {exc}", file=sys.stderr)
    try:
        model, failed = calibrate_chessboard(imgs, (cols, rows), args.square)
    except ImageInputError as exc:
        raise UsageError(str(exc)) from None
    for k, v in failed.items():
        print(f"{k}: skipped: {v}", file=sys.stderr)
    K, D = model.camera_matrix, model.dist_coeffs
    print(f"{model.views} views, RMS reprojection {model.rms_px:.3f} px")
    print(f"fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f} px")
    print("distortion k1 k2 p1 p2 k3: " + " ".join(f"{v:+.5f}" for v in D[:5]))
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(model.to_json())
        print(f"wrote {out}")
    return 0


# ----------------------------------------------------------------------------- calibrate

def _signs(text: str) -> tuple[float, float, float]:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) == 1:
        parts = parts * 3
    try:
        vals = tuple(float(p + "1") if p in "+-" else float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 3 or any(abs(v) != 1 for v in vals):
        raise UsageError(f"--scale-sign {text!r}: give +, - or three of them, e.g. -,-,-")
    return vals  # type: ignore[return-value]


def cmd_calibrate(args: argparse.Namespace) -> int:
    from align.calibration import (
        StaticSettings,
        calibrate,
        delta_g,
        model_to_dict,
        read_poses,
    )
    from align.errors import InputError

    out = _new_file(args.json, args.force, [args.static] + ([args.check] if args.check else []))
    signs = _signs(args.scale_sign)
    settings = StaticSettings(args.window, args.threshold, args.min_static, args.margin)
    try:
        poses, intervals = read_poses(args.static, settings)
        check = read_poses(args.check, settings, calibration=False)[0] if args.check else None
        cal = calibrate(poses, signs, alpha=args.alpha)
    except InputError as exc:
        raise UsageError(str(exc)) from None
    if intervals is not None:
        print(f"{len(intervals)} static intervals found:")
        for iv in intervals:
            print(f"  {iv.start_s:9.2f}-{iv.end_s:9.2f} s ({iv.duration_s:6.1f} s, "
                  f"{iv.samples} samples), noise {' '.join(f'{v:.3g}' for v in iv.std)}")
    m, a = cal.model, cal.algebraic
    sign_note = ("negative" if all(s < 0 for s in signs) else "positive"
                 if all(s > 0 for s in signs) else "mixed")
    print(f"{len(poses.u)} poses; scale-factor signs {signs} ({sign_note}: an ellipsoid cannot "
          "tell them, --scale-sign sets them)")
    print(f"{'':10s} {'algebraic (paper)':>22s} {'ML refined':>16s} {'u':>10s}")
    for i, ax in enumerate("xyz"):
        print(f"k_{ax} [V/g] {a.k[i]:22.7f} {m.k[i]:16.7f} {m.u_of(f'k_{ax}'):10.2g}")
    for i, ax in enumerate("xyz"):
        print(f"beta_{ax} [µrad] {a.beta[i] * 1e6:18.3f} {m.beta[i] * 1e6:16.3f} "
              f"{m.u_of(f'beta_{ax}') * 1e6:10.3g}")
    for i, ax in enumerate("xyz"):
        print(f"b_{ax} [µg] {a.bias[i] * 1e6:21.3f} {m.bias[i] * 1e6:16.3f} "
              f"{m.u_of(f'bias_{ax}') * 1e6:10.3g}")
    dof = cal.loop.after.dof
    if dof < 3:
        print(f"WARNING: {len(poses.u)} poses leave {dof} degrees of freedom: the fit is (nearly) "
              "exact, its residual proves nothing; add poses")
    if not cal.noise_known:
        print("noise unknown (per-pose means only): uncertainties from the residual scatter, "
              "no chi2 test")
    for line in cal.loop.summary_lines():
        print("  " + line)
    js = {
        "scale_factors_v_per_g": m.k.tolist(), "beta_rad": m.beta.tolist(),
        "bias_g": m.bias.tolist(),
        "scale_factors_u_v_per_g": [m.u_of(f"k_{ax}") for ax in "xyz"],
        "beta_u_rad": [m.u_of(f"beta_{ax}") for ax in "xyz"],
        "bias_u_g": [m.u_of(f"bias_{ax}") for ax in "xyz"],
        "scale_sign": list(signs), "residual_rms_g": cal.residual_rms_g, "dof": dof,
        "effects": [e.to_json() for e in cal.loop.effects],
        "unexplained_structure": cal.loop.unexplained_structure, "noise_known": cal.noise_known,
        "algebraic": {"scale_factors_v_per_g": a.k.tolist(), "beta_rad": a.beta.tolist(),
                      "bias_g": a.bias.tolist()},
        "poses": [{"pose": lab, "dg_g": float(d)} for lab, d in
                  zip(poses.labels, delta_g(m, poses), strict=True)],
        "model": model_to_dict(m),
    }
    if intervals is not None:
        js["static_intervals"] = [{"start_s": iv.start_s, "end_s": iv.end_s,
                                   "samples": iv.samples, "std": iv.std.tolist()}
                                  for iv in intervals]
    if check is not None:
        dg = delta_g(m, check)
        js["check"] = [{"pose": lab, "dg_g": float(d)} for lab, d in
                       zip(check.labels, dg, strict=True)]
        print("check poses |a| - 1 [µg]: " + " ".join(f"{d * 1e6:+.2f}" for d in dg))
    if args.plot:
        from align.plots import plot_calibration

        print(f"plot: {plot_calibration(cal, poses, check, Path(args.plot))}")
    _write_json(out, js)
    return 0


def _load_model(path: str):
    from align.calibration import model_from_dict

    try:
        d = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except json.JSONDecodeError as exc:
        raise UsageError(f"{path}: not JSON ({exc})") from None
    try:
        return model_from_dict(d.get("model", d), path)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def cmd_tilt(args: argparse.Namespace) -> int:
    from align.calibration.static import _read_table
    from align.errors import InputError
    from align.tilt import roll_pitch

    model = _load_model(args.calibration)
    out_json = _new_file(args.json, args.force, [args.readings])
    out_csv = _new_file(args.out, args.force, [args.readings])
    try:
        head, data, _, _ = _read_table(Path(args.readings))
    except InputError as exc:
        raise UsageError(str(exc)) from None
    col = {h: i for i, h in enumerate(head)}
    u = data[:, [col["ux"], col["uy"], col["uz"]]]
    t = data[:, col["t"]] if "t" in col else np.full(len(u), model.t_ref)
    temp = data[:, col["temp"]] if "temp" in col else None
    a = model.specific_force(u, t, temp)
    roll, pitch = roll_pitch(a, method=args.method, mu=args.mu)
    print(f"{len(a)} readings ({args.method} roll): roll {np.rad2deg(np.mean(roll)):+.6f}° "
          f"(sd {np.rad2deg(np.std(roll)) * 3600:.1f}″), pitch {np.rad2deg(np.mean(pitch)):+.6f}°"
          f" (sd {np.rad2deg(np.std(pitch)) * 3600:.1f}″), |a| - 1 mean "
          f"{(np.linalg.norm(a, axis=1) - 1).mean() * 1e6:+.2f} µg")
    if out_csv is not None:
        np.savetxt(out_csv, np.column_stack([t, np.rad2deg(roll), np.rad2deg(pitch)]),
                   delimiter=",", header="t,roll_deg,pitch_deg", comments="", fmt="%.9g")
        print(f"wrote {out_csv}")
    _write_json(out_json, {
        "method": args.method, "mu": args.mu if args.method == "paper" else None,
        "samples": len(a), "roll_deg_mean": float(np.rad2deg(np.mean(roll))),
        "pitch_deg_mean": float(np.rad2deg(np.mean(pitch))),
        "roll_deg_std": float(np.rad2deg(np.std(roll))),
        "pitch_deg_std": float(np.rad2deg(np.std(pitch)))})
    return 0


# ----------------------------------------------------------------------------- gonio

def cmd_gonio(args: argparse.Namespace) -> int:
    from align.gonio import latitude_from_earth_rate, loop_gonio, plausible_earth_rate
    from goniometry import (
        LogError,
        earth_rate_counts,
        face_angles,
        kept_table,
        read_revolutions,
        vertical_earth_rate,
    )

    faces = [f.strip() for f in args.faces.split(",") if f.strip()]
    if len(faces) < 2:
        raise UsageError("--faces needs at least two names, e.g. ref,z,y,x")
    nominal = None
    if args.nominal:
        try:
            nominal = np.deg2rad([float(v) for v in args.nominal.split(",")])
        except ValueError:
            raise UsageError(f"--nominal {args.nominal!r}: numbers in degrees") from None
        if len(nominal) != len(faces):
            raise UsageError(f"--nominal has {len(nominal)} values for {len(faces)} faces")
    out = _new_file(args.json, args.force, [args.log])
    d = 1 if args.direction == "ccw" else -1
    effects, loop = [], None
    try:
        summary = read_revolutions(args.log, len(faces))
        if args.latitude is not None and summary.has_time:
            rate = vertical_earth_rate(args.latitude, d)
            summary = read_revolutions(args.log, len(faces),
                                       correct=lambda c, dt: earth_rate_counts(c, dt, rate))
        elif summary.has_time:
            counts, dt, t_end = kept_table(summary)
            loop = loop_gonio(counts, dt, t_end, alpha=args.alpha)
            earth = [e for e in loop.effects if e.name == "earth_rate"]
            if earth and not plausible_earth_rate(earth[0].estimate, earth[0].u):
                print(f"  counts per revolution follow the period with a slope of "
                      f"{earth[0].estimate:.3g} rad/s: not the Earth's rotation; NOT applied")
                earth = []
            if earth:
                rate = earth[0].estimate
                summary = read_revolutions(
                    args.log, len(faces), correct=lambda c, dt: earth_rate_counts(c, dt, rate))
            effects = [e.to_json() for e in loop.effects]
        fa = face_angles(summary)
    except (LogError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    print(f"{summary.rows} rows, {fa.revolutions} revolutions used, {fa.counts_per_rev:.2f} "
          f"counts per revolution ({np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count)")
    for reason, n in summary.exclusions.counts.items():
        print(f"  {n} x {reason} (lines {', '.join(map(str, summary.exclusions.lines[reason]))}"
              f"{', ...' if n > 10 else ''})")
    if summary.incomplete_tail:
        print(f"  last {summary.incomplete_tail} rows after the final reference pulse: an "
              "incomplete revolution, not used")
    if args.latitude is not None and not summary.has_time:
        print("  no t column: the Earth-rate correction needs pulse times; not applied")
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
        for e in loop.effects:
            if e.name == "earth_rate":
                lat, ulat = latitude_from_earth_rate(e.estimate, e.u, d)
                print(f"  implied latitude {np.rad2deg(lat):.1f} ± {np.rad2deg(ulat):.1f}°")
    js = {"faces": faces, "angles_deg": np.rad2deg(fa.angles_rad).tolist(),
          "angles_u_arcsec": (np.rad2deg(fa.u_rad) * 3600).tolist(),
          "revolutions_used": fa.revolutions, "effects": effects,
          "unexplained_structure": bool(loop and loop.unexplained_structure),
          "covariance_arcsec2": (np.rad2deg(np.rad2deg(fa.cov)) * 3600**2).tolist(),
          "type_a_arcsec": (np.rad2deg(fa.u_type_a_rad) * 3600).tolist(),
          "type_b_arcsec": (np.rad2deg(fa.u_type_b_rad) * 3600).tolist(),
          "exclusions": {k: {"count": v, "lines": summary.exclusions.lines[k]}
                         for k, v in summary.exclusions.counts.items()},
          "allan": {"tau_revolutions": fa.allan_tau_rev.tolist(),
                    "adev_arcsec": (np.rad2deg(fa.allan_dev_rad) * 3600).tolist()}}
    if nominal is not None:
        js["deviation_arcsec"] = (np.rad2deg(fa.angles_rad - nominal) * 3600).tolist()
    if args.plot:
        from align.plots import plot_gonio

        print(f"plot: {plot_gonio(kept_table(summary)[0], fa, faces, Path(args.plot))}")
    _write_json(out, js)
    return 0


# ----------------------------------------------------------------------------- demo

def cmd_demo(args: argparse.Namespace) -> int:
    """Synthesise images with known truth, measure them, print the errors."""
    from align.marks import measure_file
    from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks
    from synth.marks import write_synth

    folder = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="align-demo-"))
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    # Two camera views of the platform, each with two housings' marks (1-5' off nominal),
    # cluttered, one view through a lens with radial distortion nobody declared.
    views = {
        "view_Y.png": ((0.0, 90.0), CameraGeometry()),
        "view_X.png": ((0.0, 90.0), CameraGeometry(focal_px=1200, k1=-0.12)),
    }
    print(f"demo: writing synthetic images to {folder}")
    rows = []
    for name, (nominals, cam) in views.items():
        marks = tuple(
            MarkSpec(np.deg2rad(nom + rng.uniform(1, 5) / 60 * rng.choice([-1, 1])),
                     offset_px=off, length_px=500, width_px=4.0, centre_t_px=tc)
            for nom, off, tc in zip(nominals, (-150.0, 250.0), (60.0, -40.0), strict=True))
        spec = ImageSpec(marks=marks, width=1024, height=768, seed=int(rng.integers(1 << 30)),
                         full_well_e=full_well_for_snr(40, -0.6), texture=0.01, dust=6,
                         dust_on_mark=2, scratches=3, gradient=(0.05, -0.03), camera=cam)
        s = render_marks(spec)
        path = folder / name
        if path.exists():
            raise UsageError(f"{path}: exists; demo never overwrites (use another --out)")
        write_synth(s, path)
        for r in measure_file(path):
            if not r.found:
                print(f"{name}: {r.error}")
                continue
            truth = min(s.truth.marks, key=lambda t: abs(np.sin(t.image_angle_rad - r.angle_rad)))
            err = (r.angle_rad - truth.image_angle_rad + np.pi / 2) % np.pi - np.pi / 2
            eff = ", ".join(e.name for e in r.loop.effects) or "none"
            rows.append((name, r, truth, err, eff))
    print(f"\n{'image':12s} {'angle [deg]':>14s} {'u [″]':>7s} {'error [″]':>10s} "
          f"{'CRLB [″]':>9s}  effects found")
    for name, r, truth, err, eff in rows:
        print(f"{name:12s} {np.rad2deg(r.angle_rad):+14.6f} {r.angle_u_rad / ARCSEC:7.2f} "
              f"{err / ARCSEC:+10.2f} {truth.crlb_angle_rad / ARCSEC:9.2f}  {eff}"
              + ("  (unexplained structure)" if r.unexplained_structure else ""))
    _demo_calibration(folder, rng)
    print("\nThe goniometer and the fusion into the misalignment matrix are not built yet; "
          "this demo covers the scribe-mark and calibration stages.")
    return 0


def _demo_calibration(folder: Path, rng: np.random.Generator) -> None:
    """The seed paper's tumble test (Table 1, 14 cube poses) with an undeclared K2."""
    from align.calibration import calibrate, delta_g, read_poses
    from synth.tumble import Triad, TumbleSpec, tumble, write_tumble_csv

    k2 = (35e-6, 0.0, -25e-6)
    d = tumble(TumbleSpec(triad=Triad(noise_v=4.8e-5, k2=k2), seed=int(rng.integers(1 << 30))))
    static = write_tumble_csv(d, folder / "tumble.csv")
    check = write_tumble_csv(d, folder / "tumble_check.csv", check=True)
    poses, _ = read_poses(static)
    cal = calibrate(poses, (-1, -1, -1))
    tr = d.spec.triad
    print(f"\ncalibration ({static.name}: Table 1 triad, 14 cube poses, K2 = "
          f"{k2[0] * 1e6:.0f}/{k2[1] * 1e6:.0f}/{k2[2] * 1e6:.0f} µg/g² not declared):")
    for label, m in (("paper's algebraic fit", cal.algebraic), ("after ML + loop", cal.model)):
        err = np.abs(m.bias - tr.bias) * 1e6
        dg = np.abs(delta_g(m, read_poses(check, calibration=False)[0])) * 1e6
        print(f"  {label:22s} bias error {' '.join(f'{v:6.2f}' for v in err)} µg, "
              f"check-pose |Δg| max {dg.max():6.2f} µg")
    for e in cal.loop.effects:
        print("  loop found " + e.name + ": " + ", ".join(
            f"{c}: {v * 1e6:+.1f} ± {u * 1e6:.1f} µg/g²" for c, v, u in e.components))


# ----------------------------------------------------------------------------- main

def _progress(items: Sequence[str], desc: str):
    if len(items) < 4 or not sys.stderr.isatty():
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="align", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)

    m = sub.add_parser("marks", help="measure scribe marks in images")
    m.add_argument("images", nargs="+")
    m.add_argument("--camera", help="camera model JSON written by 'align camera'")
    m.add_argument("--json", help="write results to this new JSON file")
    m.add_argument("--plot", help="folder for one PNG per mark (line + residuals)")
    m.add_argument("--alpha", type=float, default=1e-3, help="significance of the loop's tests")
    m.add_argument("--max-marks", type=int, default=8)
    m.add_argument("--one", action="store_true",
                   help="each image holds one mark: two competing marks are an error")
    m.add_argument("--force", action="store_true", help="allow overwriting the --json file")
    m.set_defaults(func=cmd_marks)

    c = sub.add_parser("camera", help="calibrate a camera from chessboard photographs")
    c.add_argument("images", nargs="+")
    c.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    c.add_argument("--square", type=float, default=1.0, help="square size (any unit)")
    c.add_argument("--json", help="write the camera model to this new JSON file")
    c.add_argument("--force", action="store_true")
    c.set_defaults(func=cmd_camera)

    k = sub.add_parser("calibrate", help="ellipsoid calibration of the triad from static poses")
    k.add_argument("static", help="pose,ux,uy,uz[,t][,temp] or a recording t,ux,uy,uz")
    k.add_argument("--check", help="check poses (same format): |a| - 1 per pose")
    k.add_argument("--json", help="write results (and the model for tilt/apply) to a new file")
    k.add_argument("--plot", help="folder for the dg-per-pose / residual figure")
    k.add_argument("--scale-sign", default="+", help="signs of k: + (default), - or e.g. -,-,-")
    k.add_argument("--alpha", type=float, default=1e-3)
    k.add_argument("--window", type=float, default=1.0, help="static detection window [s]")
    k.add_argument("--threshold", type=float, default=3.0,
                   help="static if moving std < this x noise floor")
    k.add_argument("--min-static", type=float, default=2.0, help="shortest static interval [s]")
    k.add_argument("--margin", type=float, default=0.5, help="cut from each end [s]")
    k.add_argument("--force", action="store_true")
    k.set_defaults(func=cmd_calibrate)

    tl = sub.add_parser("tilt", help="roll and pitch from readings through a calibration")
    tl.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    tl.add_argument("--calibration", required=True, help="JSON written by 'align calibrate'")
    tl.add_argument("--method", choices=["exact", "paper"], default="exact")
    tl.add_argument("--mu", type=float, default=0.001, help="the paper's regulariser")
    tl.add_argument("--json")
    tl.add_argument("--out", help="per-reading CSV t,roll_deg,pitch_deg (a new file)")
    tl.add_argument("--force", action="store_true")
    tl.set_defaults(func=cmd_tilt)

    g = sub.add_parser("gonio", help="face angles from a ring-laser counter log")
    g.add_argument("log", help="CSV count,counter,ref[,t]")
    g.add_argument("--faces", required=True, help="face names in passing order, e.g. ref,z,y,x")
    g.add_argument("--nominal", help="nominal angles [deg], e.g. 90,90,90,90")
    g.add_argument("--latitude", type=float, help="site latitude [deg] (Earth-rate correction)")
    g.add_argument("--direction", choices=["ccw", "cw"], default="ccw")
    g.add_argument("--alpha", type=float, default=1e-3)
    g.add_argument("--plot", help="folder for angle-per-revolution / Allan / spectrum figure")
    g.add_argument("--json")
    g.add_argument("--force", action="store_true")
    g.set_defaults(func=cmd_gonio)

    d = sub.add_parser("demo", help="synthesise data with known truth and measure it")
    d.add_argument("--out", help="folder for the synthetic files (default: a new temp folder)")
    d.add_argument("--seed", type=int, default=1)
    d.set_defaults(func=cmd_demo)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0) and 2
    try:
        return int(args.func(args))
    except UsageError as exc:
        print(f"align {args.cmd}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 1
    except Exception:
        print(f"align {args.cmd}: internal error (please report):", file=sys.stderr)
        traceback.print_exc()
        return 1


if __name__ == "__main__":
    sys.exit(main())
