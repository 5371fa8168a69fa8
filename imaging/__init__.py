"""Scribe marks in camera images: detection, sub-pixel centres, line fit with uncertainty.

Public API::

    read_image(path) -> ndarray
    detect_marks(image, min_length_px=None, roi=None) -> [MarkCandidate]
    detect_lines(image, ...) -> Detection               (with families of lines, dials)
    grating_note(image) -> str | None                   (a grating's pitch, when it is one)
    groove_ends(image, profile, extent) -> GrooveEnds   (ends under dust or ink, bounded)
    measure_marks(image, camera=None) -> [MarkMeasurement | ImageInputError]
    fit_line(points, sigma, extra=None) -> LineFit      (accepts extra model terms)
    CameraModel, calibrate_chessboard, plumb_line
"""

from imaging.camera import CameraModel, calibrate_chessboard, find_chessboard
from imaging.centres import Centres
from imaging.confirm import shadow_free
from imaging.defocus import BlurTrend, defocus_note
from imaging.detect import (
    MAX_LENGTH_FRACTION,
    MarkCandidate,
    Roi,
    check_roi,
    detect_marks,
    line_frame,
    wrap_angle,
)
from imaging.ends import GrooveEnds, groove_ends
from imaging.errors import ImageInputError
from imaging.families import Detection, detect_lines
from imaging.grating import grating_note
from imaging.groove import ProfileFit
from imaging.io import ImageRead, JpegTables, read_image, read_image_notes, set_max_pixels
from imaging.jpeg import JpegBlocks, block_labels, jpeg_note
from imaging.jpeg_scatter import (
    BlockScatter,
    block_phase_columns,
    block_scatter,
    jpeg_centre_scale,
    jpeg_noise_dof,
    posterior_factor,
)
from imaging.lens import PARAMS as LENS_PARAMS
from imaging.lens import distort_points, opencv_to_lens, undistort_points
from imaging.linefit import LineFit, fit_line, fit_line_only
from imaging.measure import (
    MarkMeasurement,
    MeasuredFrame,
    measure_candidate,
    measure_frame,
    measure_marks,
    on_line,
)
from imaging.oriented import OrientedStripes, Wave
from imaging.plumbline import (
    PlumbLineFit,
    chessboard_lines,
    cross_magnification,
    plumb_line,
    undistort,
)
from imaging.stripes import Stripes

__all__ = [
    "MAX_LENGTH_FRACTION",
    "BlurTrend", "JpegBlocks", "OrientedStripes", "Stripes", "Wave", "defocus_note", "jpeg_note",
    "block_phase_columns", "jpeg_centre_scale", "jpeg_noise_dof", "BlockScatter", "block_scatter",
    "posterior_factor",
    "block_labels",
    "CameraModel", "Centres", "Detection", "ImageInputError", "LENS_PARAMS", "LineFit",
    "MarkCandidate", "MarkMeasurement", "MeasuredFrame", "PlumbLineFit", "ProfileFit", "Roi",
    "calibrate_chessboard", "check_roi", "chessboard_lines", "cross_magnification",
    "detect_lines", "detect_marks", "distort_points", "find_chessboard", "fit_line",
    "fit_line_only",
    "line_frame", "measure_candidate", "measure_frame", "measure_marks", "opencv_to_lens",
    "on_line", "plumb_line", "read_image", "undistort", "undistort_points", "wrap_angle",
    "ImageRead", "JpegTables", "read_image_notes", "set_max_pixels",
    "GrooveEnds", "grating_note", "groove_ends", "shadow_free",
]
