"""Fusion of goniometer, camera, calibration and platform readings into the misalignment E.

Public API::

    Block, MarkObs, PlatformPose                      (observations of each instrument)
    mark_block, gonio_block, ellipsoid_block, static_block
    fuse(blocks) -> FusionResult                      (weighted LS + the residual loop)
    NOT_EXCLUDED_TAG                                  (names a carried candidate's Type B share)
"""

from align.fusion.observations import (
    E_INDEX,
    E_NAMES,
    REF,
    ROLL,
    TILT,
    Block,
    MarkObs,
    PlatformPose,
    axes_from,
    e_matrix,
    ellipsoid_block,
    gonio_block,
    mark_block,
    static_block,
)
from align.fusion.plausible import NOT_EXCLUDED_TAG
from align.fusion.solve import FusionResult, FusionStage, ObservationRow, fuse

__all__ = [
    "E_INDEX", "E_NAMES", "NOT_EXCLUDED_TAG", "REF", "ROLL", "TILT", "Block", "FusionResult",
    "FusionStage", "MarkObs", "ObservationRow", "PlatformPose", "axes_from", "e_matrix",
    "ellipsoid_block", "fuse", "gonio_block", "mark_block", "static_block",
]
