"""The document each command writes: a result's own JSON, its warnings and whether it is ok,
in the envelope of :mod:`align.contract` (format, version, provenance). The command line
(:mod:`align.commands`) only chooses the file; what goes into it is decided here.

The calibration's document is :func:`align.calibration.output.calibration_document`; a
session's is :func:`align.session.output.session_document`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from align.camera_model_u import field_u
from align.contract import document
from align.family import family_gaps
from align.lens_design import DEFAULT_RANGES
from align.warnings import camera_warnings, gonio_warnings, mark_warnings

Inputs = Iterable[str | Path]


def marks_document(results: Sequence, settings: dict, inputs: Inputs,
                   camera_problems: Sequence[str] = ()) -> dict:
    """``align marks --json``: every mark (found or not), ok when every image was measured
    and no angle is lens-limited (``lens_limited``: calibrate the camera) or a bent mark
    running off the image (``bent_mark_off_frame``) or two grooves meeting at a kink
    (``kinked_mark``) or a family of lines with a step of its ruling empty
    (``missing_steps``), and the camera model (``camera_problems``: its views not of one
    camera) can be trusted."""
    return document("marks", {"ok": not camera_problems and all(
                                  r.found and not r.lens_limited and not r.bend_off_frame
                                  and not r.kinked and not family_gaps(r) for r in results),
                              "warnings": [*camera_problems, *mark_warnings(results)],
                              "marks": [r.to_dict() for r in results]}, settings, inputs)


def gonio_document(run, faces: Sequence[str], nominal_rad: np.ndarray | None, settings: dict,
                   inputs: Inputs) -> dict:
    """``align gonio --json``."""

    body = {"ok": not run.problems, "warnings": gonio_warnings(run, faces, nominal_rad),
            **run.to_dict(faces, nominal_rad)}
    return document("gonio", body, settings, inputs)


def tilt_document(res, settings: dict, inputs: Inputs) -> dict:
    """``align tilt --json`` (``res``: :class:`align.tilt.TiltOfReadings`)."""
    return document("tilt", res.to_dict(), settings, inputs)


def camera_document(model, settings: dict, inputs: Sequence[str | Path],
                    skipped: Mapping[str, str] | None = None) -> dict:
    """``align camera --json``: the camera model's own dict (``imaging.CameraModel``), ok,
    its warnings, and the photographs ``skipped`` (name -> why: unreadable, another size, no
    board found) apart from the ones used (the envelope's ``inputs``)."""
    skipped = dict(skipped or {})
    used = [p for p in inputs if str(p) not in skipped]
    field = field_u(model)
    body = {"ok": not model.problems,
            "warnings": model.problems + camera_warnings(skipped, field,
                                                         DEFAULT_RANGES.max_u_arcsec),
            "skipped": [{"file": str(k), "reason": v} for k, v in skipped.items()],
            **model.to_dict(), "field_u": field}
    return document("camera", body, settings, used)
