"""Triad calibration by ellipsoid fitting (seed paper) with ML refinement and the loop."""

from align.calibration.ellipsoid import Ellipsoid, extract, li_griffiths, r_matrix
from align.calibration.model import (
    CANDIDATES,
    DRIFT,
    NONLIN,
    TEMP,
    WARMUP,
    CalibrationStage,
    admissible,
    algebraic,
)
from align.calibration.pipeline import Calibration, calibrate
from align.calibration.static import (
    READINGS,
    STATIC,
    StaticDetection,
    StaticInterval,
    StaticSettings,
    detect_static,
    find_static,
    read_poses,
    read_readings,
)
from align.calibration.triad import Poses, TriadModel, delta_g, poses_from_samples

__all__ = [
    "CANDIDATES", "DRIFT", "NONLIN", "TEMP", "WARMUP", "Calibration", "CalibrationStage",
    "Ellipsoid",
    "Poses", "TriadModel", "admissible", "algebraic", "calibrate", "delta_g", "extract",
    "li_griffiths", "r_matrix", "StaticInterval",
    "StaticSettings", "StaticDetection", "detect_static", "find_static", "read_poses",
    "read_readings", "READINGS", "STATIC", "poses_from_samples",
]
