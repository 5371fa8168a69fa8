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
    from align.marks import measure_files
    from align.plots import plot_mark
    from imaging import CameraModel, ImageInputError, check_roi, read_image

    roi = None
    if args.roi is not None:
        try:
            roi = check_roi(args.roi.split(","), "--roi")
        except ImageInputError as exc:
            raise UsageError(str(exc)) from None
    if args.min_length is not None and args.min_length <= 0:
        raise UsageError(f"--min-length {args.min_length:g}: must be a positive length [px]")
    camera = None
    if args.camera:
        try:
            camera = CameraModel.load(args.camera)
        except ImageInputError as exc:
            raise UsageError(str(exc)) from None
    out = _new_file(args.json, args.force, args.images)
    plot_dir = Path(args.plot) if args.plot else None
    results = []
    failed = internal = 0
    batch = measure_files(_progress(args.images, "marks"), camera, alpha=args.alpha,
                          max_marks=args.max_marks, expect_one=args.one, roi=roi,
                          min_length_px=args.min_length)
    for res in batch:
        for r in res:
            path = r.image
            results.append(r)
            if not r.found:
                failed += 1
                internal += r.internal_error
                print(f"{path}: FAILED: {r.error}", file=sys.stderr)
                continue
            print(f"{path} mark {r.index}: angle {np.rad2deg(r.angle_rad):+.6f}° "
                  f"± {r.angle_u_rad / ARCSEC:.2f}″, offset {r.offset_px:+.3f} px, "
                  f"length {r.length_px:.0f} px, {'dark' if r.dark else 'bright'}")
            for line in r.loop.summary_lines():
                print(f"    {line}")
            if r.frame is not None:
                f = r.frame
                state = ("applied" if f.applied else "not significant" if f.consistent else
                         "LINES DISAGREE beyond one distortion: u inflated")
                print(f"    frame ({f.n_lines} marks, one lens): k1 {f.k1:+.4g} ± {f.k1_u:.2g}, "
                      f"{state}")
            if plot_dir is not None:
                img = read_image(path) if r.measurement is not None else None
                print(f"    plot: {plot_mark(r, plot_dir, img)}")
    _write_json(out, {"marks": [r.to_json() for r in results]})
    if internal:
        print(f"align marks: {internal} image(s) hit an internal error (please report); the "
              "others were measured", file=sys.stderr)
    return 1 if internal else 2 if failed else 0


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
        model, failed = calibrate_chessboard(imgs, (cols, rows), args.square,
                                             fix_k3=args.fix_k3, fix_aspect=args.fix_aspect)
    except ImageInputError as exc:
        raise UsageError(str(exc)) from None
    for k, v in failed.items():
        print(f"{k}: skipped: {v}", file=sys.stderr)
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
        calibration_json,
        delta_g,
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
    js = calibration_json(cal, poses)
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
    from align.calibration import read_table
    from align.errors import InputError
    from align.tilt import roll_pitch

    model = _load_model(args.calibration)
    out_json = _new_file(args.json, args.force, [args.readings])
    out_csv = _new_file(args.out, args.force, [args.readings])
    try:
        head, data, _, _ = read_table(Path(args.readings))
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
    from align.gonio import measure_log, run_json
    from goniometry import LogError, kept_table

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
    out = _new_file(args.json, args.force, [args.log] + ([args.reverse_log]
                                                         if args.reverse_log else []))
    d = 1 if args.direction == "ccw" else -1
    try:
        run = measure_log(args.log, len(faces), args.latitude, d, args.alpha,
                          reverse_log=args.reverse_log, steady_table=args.steady_table)
    except (LogError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    summary, fa, loop = run.summary, run.angles, run.loop
    print(f"{summary.rows} rows, {fa.revolutions} revolutions used, {fa.counts_per_rev:.2f} "
          f"counts per revolution ({np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count)")
    for reason, n in summary.exclusions.counts.items():
        print(f"  {n} x {reason} (lines {', '.join(map(str, summary.exclusions.lines[reason]))}"
              f"{', ...' if n > 10 else ''})")
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
    js = run_json(run, faces, nominal)
    if args.plot:
        from align.plots import plot_gonio

        print(f"plot: {plot_gonio(kept_table(summary)[0], fa, faces, Path(args.plot))}")
    _write_json(out, js)
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
    state = "consistent" if f.consistent else "NOT consistent (uncertainty inflated " \
        f"x{f.inflation:.2f})"
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
             cal_path: str | None, alpha: float, quiet: bool) -> dict:
    """One session end to end (also the worker of a batch); returns a short summary."""
    from align.errors import InputError
    from align.session import load_session, platform_calibration, result_json, run_session
    from align.session.report import write_report

    try:
        s = load_session(folder)
        inputs = [str(p) for p in s.inputs]
        outs = {k: _new_file(v, False, inputs) for k, v in
                (("json", json_path), ("report", report_path), ("cal", cal_path))}
    except (InputError, UsageError) as exc:
        return {"session": folder, "ok": False, "bad_input": True, "error": str(exc)}
    say = (lambda m: None) if quiet else (lambda m: print(f"  [{s.name}] {m}", file=sys.stderr))
    res = run_session(s, progress=say, alpha=alpha)
    js = result_json(res)
    if outs["json"] is not None:
        outs["json"].parent.mkdir(parents=True, exist_ok=True)
        outs["json"].write_text(json.dumps(js, indent=2, default=float))
    if outs["report"] is not None:
        write_report(res, outs["report"])
    pc = platform_calibration(res)
    if outs["cal"] is not None and pc is not None:
        outs["cal"].parent.mkdir(parents=True, exist_ok=True)
        outs["cal"].write_text(json.dumps(pc.to_dict(), indent=2))
    return {"session": s.name, "folder": folder, "ok": res.ok, "bad_input": not res.ok,
            "result": res if not quiet else None, "json": js,
            "outputs": {k: str(v) for k, v in outs.items() if v is not None}}


def cmd_run(args: argparse.Namespace) -> int:
    if len(args.sessions) == 1:
        out = _run_one(args.sessions[0], args.json, args.report, args.calibration,
                       args.alpha, quiet=False)
        if "error" in out:
            raise UsageError(out["error"])
        print(f"session {out['session']}:")
        _print_result(out["result"])
        for k, v in out["outputs"].items():
            print(f"  wrote {k}: {v}")
        return 0 if out["ok"] else 2
    return _run_batch(args)


def _run_batch(args: argparse.Namespace) -> int:
    """Several sessions in parallel; --json/--report/--calibration name folders."""
    import os
    from concurrent.futures import ProcessPoolExecutor, as_completed

    names = [Path(s).resolve().name for s in args.sessions]
    if len(set(names)) != len(names):
        raise UsageError("two sessions have the same folder name; outputs would collide")

    def path_in(folder: str | None, name: str, ext: str) -> str | None:
        return None if folder is None else str(Path(folder) / f"{name}{ext}")

    jobs = args.jobs or os.cpu_count() or 1
    results = []
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futs = {pool.submit(_run_one, s, path_in(args.json, n, ".json"),
                            path_in(args.report, n, ".html"),
                            path_in(args.calibration, n, ".cal.json"), args.alpha, True): s
                for s, n in zip(args.sessions, names, strict=True)}
        done = as_completed(futs)
        tty = sys.stderr.isatty()
        if tty:
            from tqdm import tqdm

            done = tqdm(done, total=len(futs), desc="sessions")
        for k, fut in enumerate(done, start=1):
            if not tty:  # a log file gets one line per finished session instead of a bar
                print(f"  [{k}/{len(futs)}] {Path(futs[fut]).name} finished", file=sys.stderr)
            try:
                results.append(fut.result())
            except Exception as exc:  # one session's crash must not stop the others
                results.append({"session": futs[fut], "ok": False, "bad_input": False,
                                "error": f"internal error: {exc!r}"})
    failed = [r for r in results if not r["ok"]]
    for r in sorted(results, key=lambda r: r["session"]):
        if r["ok"]:
            js = r["json"]
            E = np.array(js["misalignment_arcsec"])
            U = np.array(js["misalignment_u_arcsec"])
            worst = float(np.max(np.abs(E)))
            print(f"{r['session']}: OK, |E| max {worst:.1f}″, u max {U.max():.2f}″, chi2/dof "
                  f"{js['chi2']:.1f}/{js['dof']}"
                  + ("" if not js["unexplained_structure"] else ", NOT consistent")
                  + "".join(f", {k} {v}" for k, v in r["outputs"].items()))
        else:
            msg = r.get("error") or "; ".join(e["message"] for e in r["json"]["errors"])
            print(f"{r['session']}: FAILED: {msg}", file=sys.stderr)
    print(f"{len(results) - len(failed)} of {len(results)} sessions done"
          + (f", {len(failed)} failed" if failed else ""))
    if any(not r["ok"] and not r.get("bad_input", False) for r in results):
        return 1
    return 2 if failed else 0


# ----------------------------------------------------------------------------- apply

def cmd_apply(args: argparse.Namespace) -> int:
    from align.apply import PlatformCalibration
    from align.calibration import read_table
    from align.errors import InputError
    from align.tilt import roll_pitch

    out = _new_file(args.out, args.force, [args.calibration_file, args.readings])
    try:
        pc = PlatformCalibration.load(args.calibration_file)
        head, data, _, _ = read_table(Path(args.readings))
    except InputError as exc:
        raise UsageError(str(exc)) from None
    col = {h: i for i, h in enumerate(head)}
    u = data[:, [col["ux"], col["uy"], col["uz"]]]
    t = data[:, col["t"]] if "t" in col else np.full(len(u), pc.model.t_ref)
    temp = data[:, col["temp"]] if "temp" in col else None
    a = pc.specific_force(u, t, temp)
    cols, names = [t, *a.T], ["t", "ax_g", "ay_g", "az_g"]
    if args.tilt:
        roll, pitch = roll_pitch(a, method=args.method)
        cols += [np.rad2deg(roll), np.rad2deg(pitch)]
        names += ["roll_deg", "pitch_deg"]
    np.savetxt(out, np.column_stack(cols), delimiter=",", header=",".join(names),
               comments="", fmt="%.10g")
    print(f"{len(a)} readings -> platform frame; mean a = "
          + " ".join(f"{v:+.7f}" for v in a.mean(0)) + " g")
    print(f"wrote {out}")
    return 0


# ----------------------------------------------------------------------------- synth

def cmd_synth(args: argparse.Namespace) -> int:
    from synth.session import EFFECTS, SessionSpec, write_session

    def parse(items: Sequence[str]) -> dict[str, float]:
        out = {}
        for it in items:
            name, _, val = it.partition("=")
            if name not in EFFECTS:
                raise UsageError(f"effect {name!r}: unknown; known: " + ", ".join(
                    f"{k} [{u or '-'}] ({d})" for k, (u, d) in EFFECTS.items()))
            try:
                out[name] = float(val)
            except ValueError:
                raise UsageError(f"effect {it!r}: expected NAME=NUMBER") from None
        return out

    declared = parse(args.effect)
    undeclared = parse(args.undeclared)
    spec = SessionSpec(seed=args.seed, effects={**declared, **undeclared},
                       undeclared=frozenset(undeclared))
    try:
        write_session(args.out, spec)
    except (FileExistsError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    print(f"wrote session {args.out} (seed {args.seed}; truth in {Path(args.out) / 'truth.json'})")
    for k, v in {**declared, **undeclared}.items():
        print(f"  effect {k} = {v} {EFFECTS[k][0]} "
              f"({'undeclared' if k in undeclared else 'declared in session.toml'})")
    return 0


# ----------------------------------------------------------------------------- demo

def cmd_demo(args: argparse.Namespace) -> int:
    """Synthesise a session with known truth, run it, print the matrix and its error."""
    from synth.session import SessionSpec, write_session

    folder = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="align-demo-"))
    session = folder / "session"
    roll = 30.0
    print(f"demo: writing a synthetic session to {session} (seed {args.seed}): 8 mark images "
          "from two cameras (each with a reversal), a ring-laser counter log, a 14-pose "
          f"tumble and 8 platform poses; camera A rolled by {roll:.0f}″, NOT declared")
    try:
        truth = write_session(session, SessionSpec(seed=args.seed,
                                                   effects={"camera_roll_A": roll},
                                                   undeclared=frozenset({"camera_roll_A"})))
    except FileExistsError as exc:
        raise UsageError(str(exc)) from None
    report = folder / "report.html"
    out = _run_one(str(session), str(folder / "result.json"), str(report),
                   str(folder / "platform_calibration.json"), 1e-3, quiet=False)
    if "error" in out:
        raise UsageError(out["error"])
    res = out["result"]
    print(f"\nsession {out['session']}:")
    _print_result(res)
    if res.fusion is not None:
        err = (res.fusion.E - np.array(truth["misalignment_rad"])) / ARCSEC
        z = err / np.where(res.fusion.E_u > 0, res.fusion.E_u / ARCSEC, 1)
        print("  error against truth [″]:")
        for i in range(3):
            print("    " + "xyz"[i] + ": " + "  ".join(
                "0".rjust(8) if i == j else f"{err[i, j]:+8.3f}" for j in range(3)))
        off = [z[i, j] for i in range(3) for j in range(3) if i != j]
        print(f"  normalised errors (error / u): RMS {np.sqrt(np.mean(np.square(off))):.2f}")
    print(f"\nreport: {report}")
    for k, v in out["outputs"].items():
        print(f"{k}: {v}")
    return 0 if out["ok"] else 2


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
    m.add_argument("--roi", metavar="X,Y,W,H",
                   help="search only this rectangle [px]: top-left column, row, width, height")
    m.add_argument("--min-length", type=float, metavar="PX",
                   help="shortest mark to report [px] (default 100)")
    m.add_argument("--one", action="store_true",
                   help="each image holds one mark: two competing marks are an error")
    m.add_argument("--force", action="store_true", help="allow overwriting the --json file")
    m.set_defaults(func=cmd_marks)

    c = sub.add_parser("camera", help="calibrate a camera from chessboard photographs")
    c.add_argument("images", nargs="+")
    c.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    c.add_argument("--square", type=float, default=1.0, help="square size (any unit)")
    c.add_argument("--json", help="write the camera model to this new JSON file")
    c.add_argument("--fix-k3", action="store_true", help="keep k3 at 0")
    c.add_argument("--fix-aspect", action="store_true", help="keep fx/fy at 1")
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
    g.add_argument("--reverse-log", help="a log of the same faces with the table turning the "
                   "other way: the angles are then the mean of both directions")
    g.add_argument("--steady-table", action="store_true",
                   help="the table turns at constant speed: angles from the pulse times "
                   "(below the count quantisation) when the counts confirm it")
    g.add_argument("--alpha", type=float, default=1e-3)
    g.add_argument("--plot", help="folder for angle-per-revolution / Allan / spectrum figure")
    g.add_argument("--json")
    g.add_argument("--force", action="store_true")
    g.set_defaults(func=cmd_gonio)

    r = sub.add_parser("run", help="run whole sessions: every stage, the loops, the fusion")
    r.add_argument("sessions", nargs="+", help="session folder(s) holding session.toml")
    r.add_argument("--json", help="result JSON (a folder when several sessions)")
    r.add_argument("--report", help="HTML report (a folder when several sessions)")
    r.add_argument("--calibration", help="platform calibration JSON for 'align apply' "
                   "(a folder when several sessions)")
    r.add_argument("--jobs", type=int, help="parallel sessions (default: all cores)")
    r.add_argument("--alpha", type=float, default=1e-3,
                   help="significance of the residual loops' tests (default 1e-3)")
    r.set_defaults(func=cmd_run)

    ap = sub.add_parser("apply", help="readings -> specific force in the platform frame")
    ap.add_argument("calibration_file", help="JSON from 'align run --calibration' or --json")
    ap.add_argument("readings", help="CSV with ux,uy,uz[,t][,temp]")
    ap.add_argument("--out", required=True, help="new CSV t,ax_g,ay_g,az_g[,roll_deg,pitch_deg]")
    ap.add_argument("--tilt", action="store_true", help="add roll and pitch columns")
    ap.add_argument("--method", choices=["exact", "paper"], default="exact")
    ap.add_argument("--force", action="store_true")
    ap.set_defaults(func=cmd_apply)

    sy = sub.add_parser("synth", help="write synthetic data with known truth")
    sy_sub = sy.add_subparsers(dest="what", required=True)
    ss = sy_sub.add_parser("session", help="a complete synthetic session folder")
    ss.add_argument("out", help="new folder")
    ss.add_argument("--seed", type=int, default=0)
    ss.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data and declared in session.toml (e.g. "
                    "camera_roll_A=30 [arcsec]; an unknown name lists them all)")
    ss.add_argument("--undeclared", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data but not declared")
    ss.set_defaults(func=cmd_synth)

    d = sub.add_parser("demo", help="synthesise a session with known truth and run it")
    d.add_argument("--out", help="folder for the session and outputs (default: a new temp folder)")
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
