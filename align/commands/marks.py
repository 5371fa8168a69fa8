"""``align marks`` (scribe marks in images) and ``align camera`` (a camera from chessboard
photographs)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.args import (
    ALPHA,
    NON_NEGATIVE,
    POSITIVE,
    add_max_pixels,
    number,
    pattern,
    unique,
)
from align.commands.common import log, plan, progress, say, settings, warn, wrote
from align.commands.parents import examples


def cmd_marks(args: argparse.Namespace) -> int:
    from align.grid_phase import with_grid_phase
    from align.marks import measure_files
    from imaging import check_roi

    unique(args.images, "images")
    roi = check_roi(args.roi.split(","), "--roi") if args.roi is not None else None
    camera, ranges = _lens_inputs(args)
    inputs = [*args.images] + ([args.camera] if args.camera else [])
    outs = plan(args, inputs)
    out, plot_dir = (outs.add("--json", args.json, stdout_ok=True),
                     outs.add("--plot", args.plot, folder=True))
    batch = measure_files(progress(args.images, "marks"), camera, alpha=args.alpha,
                          max_marks=args.max_marks, expect_one=args.one, roi=roi,
                          min_length_px=args.min_length, ranges=ranges)
    batch = map(with_grid_phase, batch) if args.blur_after_pixels else batch  # declared
    results, failed, internal = _show_marks(batch, plot_dir)
    bad_model = _write_marks(args, results, inputs, out, camera)  # two cameras' views in it
    # A lens-limited angle is not ok (docs/camera.md): exit 2 like a failed image.
    return _marks_status(failed + _not_ok(results) + bad_model, internal)


def _lens_inputs(args: argparse.Namespace):
    """The camera model (--camera) and the plausible lens ranges (--lens); ranges beside a
    model are refused by :meth:`LensRanges.parse` naming both flags."""
    from align.lens import LensRanges
    from imaging import CameraModel

    camera = CameraModel.load(args.camera) if args.camera else None
    ranges = (LensRanges.parse(args.lens, beside="--camera" if args.camera else "")
              if args.lens is not None else None)
    return camera, ranges


def _not_ok(results) -> int:
    """Marks measured but not ok: lens-limited, a bent mark running off the image, two
    grooves meeting at a kink, or a member of a family with lines missing."""
    from align.family import family_gaps

    return sum(r.lens_limited or r.bend_off_frame or r.kinked or bool(family_gaps(r))
               for r in results)


def _write_marks(args: argparse.Namespace, results: list, inputs: list[str], out,
                 camera) -> int:
    """Warn and write the marks' JSON; the number of the camera model's own problems (its
    views not of one camera: each makes the run not ok)."""
    from align.documents import marks_document
    from align.warnings import not_measured
    from axisbase.output import write_json

    problems = [f"{args.camera}: {w}" for w in (camera.problems if camera else [])]
    doc = marks_document(results, settings(args), inputs, problems)
    # A failed image was said once, as its error (_show_marks): not again as a warning.
    said = {not_measured(r) for r in results if not r.found}
    warn([w for w in doc["warnings"] if w not in said])
    if out is not None:
        wrote(write_json(out, doc, args.force))
    return len(problems)


def _show_marks(batch, plot_dir) -> tuple[list, int, int]:
    """Print each image's marks as they are measured (and plot them); the results, the
    count of images that failed and of those that hit an internal error."""
    from align.plots import plot_mark
    from align.present import mark_lines
    from imaging import read_image

    results, failed, internal = [], 0, 0
    for res in batch:
        for r in res:
            results.append(r)
            if not r.found:
                failed += 1
                internal += r.internal_error
                log.error("%s: FAILED: %s", r.image, str(r.error).removeprefix(f"{r.image}: "))
                continue
            say(mark_lines(r))
            if plot_dir is not None:
                img = read_image(r.image) if r.measurement is not None else None
                print(f"    plot: {plot_mark(r, plot_dir, img)}")
    return results, failed, internal


def _marks_status(failed: int, internal: int) -> int:
    if internal:
        log.error("align marks: %d image(s) hit an internal error (please report); the "
                  "others were measured", internal)
    return 1 if internal else 2 if failed else 0


def cmd_camera(args: argparse.Namespace) -> int:
    from align.documents import camera_document
    from align.present import camera_lines
    from axisbase.output import write_json
    from imaging import calibrate_chessboard

    cols, rows = pattern(args.pattern)
    unique(args.images, "images")
    out = plan(args, args.images).add("--json", args.json, stdout_ok=True)
    imgs, unread = _read_boards(args.images)
    model, failed = calibrate_chessboard(imgs, (cols, rows), args.square,
                                         fix_aspect=args.fix_aspect, k3="fixed" if args.fix_k3
                                         else "free" if args.free_k3 else "auto",
                                         board_tolerance=args.board_tolerance)
    doc = camera_document(model, settings(args), args.images, {**unread, **failed})
    warn(doc["warnings"])
    say(camera_lines(model, doc["field_u"]))
    if out is not None:
        wrote(write_json(out, doc, args.force))
    return 2 if model.problems else 0  # the views are not of one camera


def _read_boards(paths: list[str]) -> tuple[dict, dict[str, str]]:
    """The photographs that can be read, as 8- or 16-bit arrays, and why each other one
    cannot (skipped: a warning in the JSON and on the terminal)."""
    import numpy as np

    from imaging import ImageInputError, read_image

    imgs, unread = {}, {}
    for p in paths:
        try:
            img = read_image(p)
            imgs[p] = img.astype(np.uint8 if img.max() <= 255 else np.uint16)
        except ImageInputError as exc:
            unread[p] = str(exc).removeprefix(f"{p}: ")
    return imgs, unread


def add_marks(add: Callable[..., argparse.ArgumentParser]) -> None:
    m = add("marks", "measure scribe marks in images", epilog=examples(
        "align marks mark1.png mark2.tif --json marks.json",
        "align marks photo.tif --camera camera.json --roi 100,200,800,600 --one --plot figs/"))
    m.add_argument("images", nargs="+", help="image files (PNG, TIFF, JPEG; 8 or 16 bit)")
    m.add_argument("--camera", help="camera model JSON written by 'align camera' (trusted: "
                   "applied, its u propagated, no distortion fitted on top)")
    m.add_argument("--lens", metavar="KEY=V,...",
                   help="plausible lens without --camera (Type B ranges; keys k1, k2, p at the "
                   "image half-diagonal, aspect, pp_px [px], max_u_arcsec; defaults k1=0.3,"
                   "k2=0.05,p=0.001,aspect=0.005,pp_px=40,max_u_arcsec=60; all 0: declared "
                   "distortion-free; beside --camera only max_u_arcsec and pp_stability_px: "
                   "how far the model's principal point may have moved since calibration [px], "
                   "default 0.5; docs/camera.md)")
    m.add_argument("--json", help="write results to this new JSON file ('-': stdout)")
    m.add_argument("--plot", help="folder for one PNG per mark (line + residuals)")
    m.add_argument("--alpha", type=ALPHA, default=1e-3, help="significance of the loop's tests")
    m.add_argument("--max-marks", type=number(1, 1000, integer=True), default=8,
                   help="most marks reported per image")
    m.add_argument("--roi", metavar="X,Y,W,H",
                   help="search only this rectangle [px]: top-left column, row, width, height")
    m.add_argument("--min-length", type=POSITIVE, metavar="PX",
                   help="shortest mark to report [px] (default 100, at most 80 %% of the "
                   "image's smaller side)")
    m.add_argument("--one", action="store_true",
                   help="each image holds one mark: two competing marks are an error")
    m.add_argument("--blur-after-pixels", action="store_true",
                   help="the images were filtered on the pixel grid after capture (demosaiced, "
                   "sharpened, resampled): near-axis marks carry the grid_phase term "
                   "(docs/camera.md)")
    add_max_pixels(m)
    m.set_defaults(func=cmd_marks)


def add_camera(add: Callable[..., argparse.ArgumentParser]) -> None:
    c = add("camera", "calibrate a camera from chessboard photographs", epilog=examples(
        "align camera board*.jpg --pattern 9x6 --square 25 --json camera.json"))
    c.add_argument("images", nargs="+", help="chessboard photographs")
    c.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS")
    c.add_argument("--square", type=POSITIVE, default=1.0, help="square size (any unit)")
    c.add_argument("--json", help="write the camera model to this new JSON file ('-': stdout)")
    k3 = c.add_mutually_exclusive_group()
    k3.add_argument("--fix-k3", action="store_true", help="keep k3 at 0 as known (default: "
                    "fit k3 only when the views determine it, else leave it out and carry its "
                    "range in the covariance; docs/camera.md)")
    k3.add_argument("--free-k3", action="store_true", help="always fit k3 (OpenCV's default)")
    c.add_argument("--fix-aspect", action="store_true", help="keep fx/fy at 1")
    c.add_argument("--board-tolerance", type=lambda v: NON_NEGATIVE(v) / 100.0,
                   metavar="PCT", help="the board's print tolerance of its x/y scale "
                   "ratio [%%] (default 0.1; 0: a board known exact): carried in "
                   "fy/fx's u when the views cannot separate the board's x/y scale from the "
                   "pixels' aspect (docs/camera.md)")
    add_max_pixels(c)
    c.set_defaults(func=cmd_camera)
