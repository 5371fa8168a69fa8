"""Scribe marks through the residual loop, and the per-image result.

Each image's marks are measured (:mod:`imaging`), the camera's lens is met
(:mod:`align.camera_lens`: one lens for all marks of a frame, or of a camera's images in a
session, identifiability first, what the lines do not determine carried in u as named terms),
then each mark goes through the residual loop over its line fit (:mod:`align.mark_stage`).
A bow the loop finds is a bent mark only beyond what the camera's lens can still make on that
mark; its direction is then the chord between the groove's ends, u widened to cover the other
readings (:func:`loop_mark`, docs/camera.md).
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from align.camera_lens import (
    CAMERA_MODEL,
    LENS_TERMS,
    CameraLens,
    camera_lens,
    claimed_lens,
    undistorted_mark,
)
from align.family_stage import family_note, grating_notes, offset_lens_u, with_families
from align.lens import LensRanges
from align.lens_advice import lens_advice
from align.loop import Candidate, run_loop
from align.mark_choice import MIN_DELTA_BIC, alternatives, blend
from align.mark_kink import KINK_MIN_RAD, kink_test, kink_testable, split_kinked
from align.mark_reading import read_mark, structure_inflation, wrap_line_angle
from align.mark_result import FrameDistortion, MarkResult
from align.mark_shadow import shadow_edge_note, unshadowed
from align.mark_stage import (
    BEND,
    CANDIDATES,
    RADIAL,
    WIGGLE,
    MarkStage,
    half_diagonal,
    radial_admissible,
)
from axisbase.errors import internal_error
from imaging import (
    MAX_LENGTH_FRACTION,
    CameraModel,
    ImageInputError,
    JpegTables,
    MarkMeasurement,
    Roi,
    measure_frame,
    read_image_notes,
)

log = logging.getLogger("align.marks")

__all__ = ["BEND", "CANDIDATES", "RADIAL", "WIGGLE", "LENS_TERMS", "CameraLens", "MarkStage",
           "FrameDistortion", "MarkResult", "camera_lens", "half_diagonal", "loop_mark",
           "finish_mark", "measure_image", "measure_camera", "measure_file", "measure_files",
           "structure_inflation", "with_families"]


CARRY_EDGE_DECISIONS = False
"""Whether the marks' loop carries its decisions on the edge of their tests
(:mod:`align.mark_choice`: the other side's reading by its chance, ``model_choice`` in u).
Built and unit-tested, but **off**: merged with the rest of 28 Nov it widened u beyond what
the errors need on JPEG crops at quality 50 (RMS z 0.35, bound 0.5), a ruled scale's family
(χ²/dof 0.64 for 0.7–1.4), and `align plan` does not
predict the terms it adds (docs/loop.md, "Decisions on the edge")."""

CHOICE_NOTE = 0.01
"""Least change of a mark's u (relative) or angle (in its u) for which a decision of the
loop on the edge of its test (:mod:`align.mark_choice`) is said in a note."""


def loop_mark(m: MarkMeasurement, image: str = "", index: int = 0, alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES, lens_bow_px: float = 0.0
              ) -> MarkResult:
    """Run the residual loop over one measured mark.

    ``lens_bow_px``: the largest sagitta the camera's lens can still leave on this mark
    (:attr:`CameraLens.bow_px`; 0: none, the lens is known or declared absent). A bow the
    loop finds beyond it (by more than its u at ``alpha``) has no lens's shape here: a bent
    mark, named; within it, lens or bend, said so. Either way the direction is read end to
    end and u covers the other readings.

    Parameters
    ----------
    m : imaging.MarkMeasurement
        The mark's measured centres [px] and their sigma across the line [px].
    image : str
        The image's name, in the result and its notes.
    index : int
        The mark's index in its image.
    alpha : float
        Significance of the loop's tests (probability of a false alarm per test).
    candidates : sequence of Candidate
        The effects the loop may add (radial distortion, bend, ...).
    lens_bow_px : float
        Largest sagitta the camera's undetermined lens can leave on this mark [px].

    Returns
    -------
    MarkResult
        The mark's angle and its u [rad], offset and its u [px], the loop's report, the
        named u terms [rad] and notes.
    """
    stage = MarkStage(m)
    admissible = functools.partial(radial_admissible, alpha=alpha)
    rep = run_loop(stage, candidates, alpha=alpha, min_delta_bic=MIN_DELTA_BIC,
                   admissible=admissible)
    a, au, du, infl, terms, notes, bend, off_frame = read_mark(stage, rep, m, image, index, alpha,
                                                           lens_bow_px)
    # The loop's decisions within their statistics' sampling spread of the threshold: the
    # other side's reading carried by its chance (align.mark_choice), so that the angle does
    # not jump where an imperceptibly different input tips a decision.
    alts = alternatives(stage, rep, candidates, alpha, admissible) if CARRY_EDGE_DECISIONS else []
    readings = [(x.weight, *read_mark(stage, x.report, m, image, index, alpha, lens_bow_px,
                                  x.structured)[:2]) for x in alts]
    if readings:
        a_one, u_one = a, au
        a, choice = blend(a, au, readings)
        if choice > 0:
            terms["model_choice"] = choice
            au = float(np.hypot(au, choice))
        # Said only where it changes the reading (a decision near the band's edge has a
        # weight of ~0: its term stays in the u terms, a line for it would be noise).
        if au > (1 + CHOICE_NOTE) * u_one or abs(a - a_one) > CHOICE_NOTE * u_one:
            notes.append(f"{image} mark {index}: the loop's decision on the edge of its test ("
                         + "; ".join(f"{x.what}: weight {x.weight:.2f}, margin "
                                     f"{x.margin:+.2f}" for x in alts)
                         + "): the angle is the readings' average by weight, u carries the "
                         f"other reading (model_choice {np.rad2deg(choice) * 3600:.3g}″)")
    # Two straight grooves meeting at an angle, found as one: no bow, chord or fit is either
    # groove's direction (mark_kink). Tested only where the loop left structure or named a
    # bow (a clean straight mark has nothing to break).
    kink = (kink_test(m, stage.sigma) if kink_testable(m) and (
        rep.unexplained_structure or bend is not None) else None)
    kinked = kink is not None and kink.p < alpha and abs(kink.turn_rad) >= KINK_MIN_RAD
    if kinked:
        notes.append(f"{image} mark {index}: NOT OK: a kink at t = {kink.t_px:+.0f} px from "
                     f"the mark's middle (broken line against line and bow: sup-F "
                     f"{kink.sup_f:.3g}, p = {kink.p:.2g}): two straight grooves meeting at an "
                     "angle, measured as one line they have no one direction; measure each "
                     "part on its own (an ROI on each)")
    d = rep.after.quantities["offset_px"][0]
    return MarkResult(
        image=image, found=True, index=index, angle_rad=a, angle_u_rad=au, offset_px=d,
        offset_u_px=du, length_px=m.length_px, width_px=m.profile.width_px,
        blur_px=m.profile.blur_px, dark=m.candidate.dark, n_points=len(m.points),
        n_rejected=m.n_rejected, angle_before_rad=rep.before.quantities["angle_rad"][0],
        loop=rep, measurement=m, uncertainty_inflation=infl, u_terms=terms,
        notes=tuple(notes), bend_off_frame=bend is not None and off_frame,
        kinked=kinked)


def finish_mark(m: MarkMeasurement, lens: CameraLens, k: int, name: str, index: int,
                alpha: float = 1e-3, group: str = "") -> MarkResult:
    """One mark of a camera whose lens is known (:func:`camera_lens`, ``k`` the mark's place
    in it): undistorted by it, through the loop, the lens's u terms added to the angle.
    ``group`` names the lens solve the mark shares with others (default: the image)."""
    before = m.line.angle_rad
    mu = undistorted_mark(m, lens.lam) if lens.lam is not None else m
    r = loop_mark(mu, name, index, alpha,
                  lens_bow_px=lens.bow_px[k] if k < len(lens.bow_px) else 0.0)
    terms = dict(r.u_terms)
    terms.update(lens.terms[k] if k < len(lens.terms) else {})
    au = float(np.sqrt(r.angle_u_rad**2 + sum(v**2 for k_, v in terms.items()
                                              if k_ not in r.u_terms)))
    lens_u = float(np.sqrt(sum(v**2 for k_, v in terms.items() if k_.startswith(LENS_TERMS))))
    limited = bool(lens_u > lens.max_u_rad) or lens.unresolved
    notes = list(lens.notes) + list(r.notes) + [
        f"{name} mark {index}: crossing with "
        f"{f'mark {j}' if j >= 0 else 'a groove not found as a mark'}: {n} px excluded "
        "(the other groove lies in its profile window there)" for j, n in m.crossings]
    if lens.unresolved:
        notes.append(f"{name} mark {index}: NOT OK: the camera's marks fit neither its "
                     "calibrated lens nor one changed lens (see the camera's note): recalibrate "
                     f"the camera (`align camera`) and give it with {lens.model_as}")
    elif limited:
        worst = max((k_ for k_ in terms if k_.startswith(LENS_TERMS)), key=terms.get)
        notes.append(f"{name} mark {index}: NOT OK: the angle is lens-limited (± "
                     f"{np.rad2deg(lens_u) * 3600:.0f}″ from the lens, mostly {worst}; bound "
                     f"{np.rad2deg(lens.max_u_rad) * 3600:.0f}″): "
                     + lens_advice(lens, m, worst))
    claimed = claimed_lens(lens.lam, lens.record)
    if claimed is not None and not np.array_equal(claimed, lens.lam):
        # The offset through the claimed lens: a parameter fitted free moves the line by its
        # sagitta, which the offset's u does not carry.
        # (Fits either side of the +-90 deg wrap negate the offset: scene 94, 439 px off.)
        c = undistorted_mark(m, claimed).line
        sgn = 1.0 if abs(c.angle_rad - mu.line.angle_rad) <= np.pi / 2 else -1.0
        r = replace(r, offset_px=r.offset_px + sgn * c.offset_px - mu.line.offset_px)
    coupling = lens.coupling[k] if k < len(lens.coupling) else {}
    # The lens moves the offset as it turns the angle: what it leaves undetermined (or its
    # calibration's u) is in the offset's u too (an undeclared k1 -0.27 lens, three marks
    # 150-250 px out: offsets 10 u off at a stated 0.007 px).
    du_lens = offset_lens_u(mu.points, r.angle_rad, lens.record, m.image_shape)
    r = replace(r, offset_u_px=float(np.hypot(r.offset_u_px, du_lens)),
                offset_lens_u_px=du_lens)
    return replace(r, angle_before_rad=before, angle_u_rad=au, u_terms=terms,
                   lens=lens.record, notes=tuple(notes), lens_limited=limited,
                   lens_coupling=dict(coupling), lens_group=(group or name) if coupling else "")


def measure_image(image: np.ndarray, name: str = "image", camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None,
                  ranges: LensRanges | None = None, jpeg_tables: JpegTables | None = None
                  ) -> list[MarkResult]:
    """Every mark of an in-memory image, each through the loop; failures become entries.

    Parameters
    ----------
    image : numpy.ndarray
        The image, 2-D grey levels [DN].
    name : str
        Its name in the results and notes (a file's path).
    camera : imaging.CameraModel or None
        A calibrated camera (its lens removed from the marks); None: the lens from the
        marks' bows within ``ranges``.
    alpha : float
        Significance of the residual loops' tests.
    max_marks : int
        Most marks reported (the strongest; the rest counted as unreported).
    expect_one : bool
        One mark expected: competing lines are an error, not more marks.
    roi : tuple of int or None
        Region searched, (x, y, w, h) [px].
    min_length_px : float or None
        Shortest line taken as a mark [px].
    ranges : LensRanges or None
        The plausible lens (Type B) when no camera model is given (None: the default).
    jpeg_tables : imaging.JpegTables or None
        A JPEG file's quantisation table from its header (None: read from the pixels).

    Returns
    -------
    list of MarkResult
        One per mark found, in the image's order (angles [rad], offsets [px]); an image
        that cannot be measured is one entry with ``found`` False and its ``error``.

    Examples
    --------
    A synthetic 400 px mark at 0.1° (``synth`` renders it, with its truth), no lens:

    >>> import numpy as np
    >>> from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
    >>> from align import LensRanges, measure_image
    >>> spec = ImageSpec(marks=(MarkSpec(np.deg2rad(0.1), 5.0, 400.0, 4.0, contrast=-0.6),),
    ...                  width=640, height=480, full_well_e=full_well_for_snr(50, -0.6), seed=1)
    >>> (m,) = measure_image(render_marks(spec, with_crlb=False).image,
    ...                      ranges=LensRanges.none())
    >>> bool(abs(m.angle_rad - np.deg2rad(0.1)) < 3 * m.angle_u_rad), m.lens_limited
    (True, False)
    """
    too_long = min_length_note(min_length_px, image.shape)
    if too_long:  # refused before measuring: the flag is wrong, not the image
        return [MarkResult(image=name, found=False, error=f"{name}: {too_long}")]
    try:
        measured = measure_frame(image, camera, where=name, max_marks=max_marks,
                                 expect_one=expect_one, roi=roi, min_length_px=min_length_px,
                                 jpeg_tables=jpeg_tables)
    except ImageInputError as exc:
        return [MarkResult(image=name, found=False, error=str(exc))]
    found, split = _frame_marks(measured.items, name, alpha, image, camera)
    ms = [m for m in found if isinstance(m, MarkMeasurement)]
    # One lens for the frame, all its marks together (identifiability first).
    lens = camera_lens(ms, camera, ranges, alpha)
    out = []
    k = 0
    for i, m in enumerate(found):
        if isinstance(m, ImageInputError):
            out.append(MarkResult(image=name, found=False, error=str(m), index=i))
            continue
        r = finish_mark(m, lens, k, name, i, alpha)
        out.append(replace(r, notes=r.notes + split[i]) if i in split else r)
        k += 1
    if measured.notes:  # the frame's background (stripes): on each of its marks
        out = [replace(r, notes=measured.notes + r.notes) for r in out]
    out = with_families(out, measured.families, measured.unreported,
                        CAMERA_MODEL if camera is not None else
                        "frame lens" if lens.lam is not None else "none", alpha, image)
    # A grating beside the marks: named with its region, never passed over unsaid.
    said = grating_notes(image, name, out)
    return [replace(r, notes=said + r.notes) for r in out] if said else out



def measure_camera(images: Sequence[tuple[str | Path, Roi | None]],
                   camera: CameraModel | None = None, alpha: float = 1e-3,
                   expect_one: bool = False, ranges: LensRanges | None = None,
                   label: str = "", on_image: Callable[[int], None] | None = None
                   ) -> list[list[MarkResult]]:
    """All images of one camera with one lens (issue 18): every mark of every image enters
    one plumb-line fit (:func:`camera_lens`), then each goes through its loop. ``images``:
    (path, roi) pairs; one list of results per image, in order; an unreadable image or one
    without a mark is its failed entry, as in :func:`measure_file`.

    Parameters
    ----------
    images : sequence of (str or Path, tuple of int or None)
        Each image file and its region searched, (x, y, w, h) [px] or None.
    camera : imaging.CameraModel or None
        A calibrated camera; None: one lens from all the images' marks within ``ranges``.
    alpha : float
        Significance of the residual loops' tests.
    expect_one : bool
        One mark expected per image.
    ranges : LensRanges or None
        The plausible lens (Type B) when no camera model is given.
    label : str
        The camera's name, in the notes and the marks' lens group.
    on_image : callable or None
        Called with each image's index before it is read (progress).

    Returns
    -------
    list of list of MarkResult
        One list per image, in the order of ``images`` (angles [rad], offsets [px]).
    """
    found_all: list[list[MarkMeasurement | ImageInputError]] = []
    said: dict[str, tuple[str, ...]] = {}  # what the reader did to each stored image
    split_all: dict[str, dict[int, tuple[str, ...]]] = {}  # shadowed, kinked marks' notes
    for j, (path, roi) in enumerate(images):
        if on_image is not None:
            on_image(j)
        try:
            got = read_image_notes(path)
        except ImageInputError as exc:
            found_all.append([exc])
            continue
        try:
            fr = measure_frame(got.pixels, camera, where=str(path), expect_one=expect_one,
                               roi=roi, jpeg_tables=got.jpeg_tables)
            said[str(path)] = tuple(f"{path}: {n}" for n in got.notes) + fr.notes
            items, split = _frame_marks(fr.items, str(path), alpha, got.pixels, camera)
            found_all.append(items)
            split_all[str(path)] = split
        except ImageInputError as exc:
            # One mark expected and a family of lines there: named, not just "competing".
            note = family_note(got.pixels, roi) if expect_one else None
            found_all.append([ImageInputError(f"{exc}; {note}") if note else exc])
    ms = [m for f in found_all for m in f if isinstance(m, MarkMeasurement)]
    shapes = {m.image_shape for m in ms}
    lens = camera_lens(ms, camera, ranges, alpha, label) if len(shapes) <= 1 else None
    out, k = [], 0
    for (path, _), found in zip(images, found_all, strict=True):
        res = []
        for i, m in enumerate(found):
            if isinstance(m, ImageInputError):
                res.append(MarkResult(image=str(path), found=False, error=str(m), index=i))
                continue
            if lens is None:  # images of different sizes: one lens each
                one = camera_lens([m], camera, ranges, alpha, label)
                res.append(finish_mark(m, one, 0, str(path), i, alpha,
                                       group=f"{path} mark {i}"))
            else:
                res.append(finish_mark(m, lens, k, str(path), i, alpha,
                                       group=f"camera {label}" if label else "camera"))
            if i in split_all.get(str(path), {}):
                res[-1] = replace(res[-1], notes=res[-1].notes + split_all[str(path)][i])
            k += 1
        notes = said.get(str(path), ())
        out.append([replace(r, notes=notes + tuple(r.notes)) for r in res] if notes else res)
    return out


def _frame_marks(items: Sequence[MarkMeasurement | ImageInputError], name: str, alpha: float,
                 image: np.ndarray, camera: CameraModel | None
                 ) -> tuple[list[MarkMeasurement | ImageInputError], dict[int, tuple[str, ...]]]:
    """The frame's marks measured again where a shadow's edge runs along one
    (:func:`align.mark_shadow.unshadowed`) and split where one is kinked
    (:func:`_split_kinked`), and the notes saying so, by each mark's final index."""
    items, shaded = unshadowed(items, image, camera, name)
    found, split = _split_kinked(items, name, alpha, image, camera)
    notes: dict[int, tuple[str, ...]] = {}
    for i, m in enumerate(found):
        said = ((shadow_edge_note(f"{name} mark {i}", shaded[id(m)]),) if id(m) in shaded
                else ()) + ((split[i],) if i in split else ())
        if said:
            notes[i] = said
    return found, notes


def _split_kinked(items: Sequence[MarkMeasurement | ImageInputError], name: str, alpha: float,
                  image: np.ndarray, camera: CameraModel | None
                  ) -> tuple[list[MarkMeasurement | ImageInputError], dict[int, str]]:
    """The frame's marks with each kinked one (:func:`align.mark_kink.split_kinked`) as its
    two straight parts, each measured again from ``image`` as its own groove, and the note
    of each part (by its new index)."""
    out: list[MarkMeasurement | ImageInputError] = []
    said: dict[int, str] = {}
    for item in items:
        parts, kink = ((item,), None) if isinstance(item, ImageInputError) else split_kinked(
            item, alpha, image, camera, name)
        if len(parts) == 2 and kink is not None:
            i = len(out)
            turn = float(np.rad2deg(wrap_line_angle(parts[1].line.angle_rad
                                                    - parts[0].line.angle_rad)))
            for j in (0, 1):
                said[i + j] = (f"{name} mark {i + j}: a kink of {turn:+.2f}° at t = "
                               f"{kink.t_px:+.0f} px from the middle of a groove found as one "
                               f"line (broken line against line and bow: p = {kink.p:.2g}): "
                               f"measured as two lines, marks {i} and {i + 1}")
        out.extend(parts)
    return out, said


def min_length_note(min_length_px: float | None, shape: tuple[int, ...]) -> str | None:
    """Why ``min_length_px`` [px] cannot be asked of an image of ``shape`` (rows, columns),
    or None: a mark is at most 80 % of the image's smaller side (the detector's bound,
    :func:`imaging.detect.default_min_length`), so a longer minimum finds nothing and would
    blame the image."""
    if min_length_px is None:
        return None
    side = min(shape[:2])
    bound = MAX_LENGTH_FRACTION * side
    if min_length_px <= bound:
        return None
    return (f"--min-length {min_length_px:g} px is beyond this image's bound of {bound:g} px "
            f"(at most {MAX_LENGTH_FRACTION * 100:g} % of its smaller side, {side} px): not "
            "measured; give a shorter --min-length")


def measure_file(path: str | Path, camera: CameraModel | None = None, alpha: float = 1e-3,
                 max_marks: int = 8, expect_one: bool = False, roi: Roi | None = None,
                 min_length_px: float | None = None, ranges: LensRanges | None = None
                 ) -> list[MarkResult]:
    """Every mark in an image file; an unreadable file is one failed entry.

    Parameters
    ----------
    path : str or Path
        The image file (PNG, TIFF, JPEG, ...).
    camera, alpha, max_marks, expect_one, roi, min_length_px, ranges
        As in :func:`measure_image` (``roi`` [px], ``min_length_px`` [px]).

    Returns
    -------
    list of MarkResult
        As :func:`measure_image`, with what the reader did to the stored image
        (orientation, data offset) in each mark's notes.
    """
    try:
        got = read_image_notes(path)
    except ImageInputError as exc:
        return [MarkResult(image=str(path), found=False, error=str(exc))]
    results = measure_image(got.pixels, str(path), camera, alpha, max_marks, expect_one, roi,
                            min_length_px, ranges, got.jpeg_tables)
    if not got.notes:
        return results
    # What the reader did to the stored image (orientation applied, signed data offset):
    # in each mark's notes, hence in the JSON and the warnings.
    said = tuple(f"{path}: {n}" for n in got.notes)
    return [replace(r, notes=said + tuple(r.notes)) for r in results]


def measure_files(paths: Sequence[str | Path], camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None,
                  ranges: LensRanges | None = None) -> Iterator[list[MarkResult]]:
    """:func:`measure_file` over a batch, one list per file; nothing escapes one image.

    Bad input is already a failed entry; anything else raised inside one image is a bug, but
    it must not cost the user the other images: it becomes that image's failed entry, marked
    ``internal_error`` ("internal error — please report (<type>: <message>)", the traceback
    in the log), and the batch goes on.
    """
    for path in paths:
        try:
            yield measure_file(path, camera, alpha, max_marks, expect_one, roi, min_length_px,
                               ranges)
        except Exception as exc:  # noqa: BLE001 - deliberate: isolate one image's bug
            bug = internal_error(exc)
            log.error("%s: %s", path, bug, exc_info=exc)
            yield [MarkResult(image=str(path), found=False, internal_error=True,
                              error=str(bug))]
