"""Scribe marks in camera images: detection, sub-pixel centres, line fit with uncertainty.

Public API::

    read_image(path) -> ndarray
    detect_marks(image, min_length_px=None, roi=None) -> [MarkCandidate]
    measure_marks(image, camera=None) -> [MarkMeasurement | ImageInputError]
    fit_line(points, sigma, extra=None) -> LineFit      (accepts extra model terms)
    CameraModel, calibrate_chessboard, plumb_line
"""

from imaging.camera import CameraModel, calibrate_chessboard, find_chessboard
from imaging.detect import MarkCandidate, Roi, check_roi, detect_marks, line_frame, wrap_angle
from imaging.errors import ImageInputError
from imaging.io import read_image
from imaging.lens import PARAMS as LENS_PARAMS
from imaging.lens import distort_points, opencv_to_lens, undistort_points
from imaging.linefit import LineFit, fit_line
from imaging.measure import MarkMeasurement, measure_candidate, measure_marks
from imaging.plumbline import (
    PlumbLineFit,
    chessboard_lines,
    cross_magnification,
    plumb_line,
    undistort,
)
from imaging.profile import Centres, ProfileFit

__all__ = [
    "CameraModel", "Centres", "ImageInputError", "LENS_PARAMS", "LineFit", "MarkCandidate",
    "MarkMeasurement",
    "PlumbLineFit", "ProfileFit", "Roi", "calibrate_chessboard", "check_roi",
    "chessboard_lines", "cross_magnification", "detect_marks",
    "find_chessboard", "fit_line", "line_frame", "measure_candidate", "measure_marks",
    "plumb_line", "read_image", "undistort", "wrap_angle", "distort_points",
    "opencv_to_lens", "undistort_points",
]
