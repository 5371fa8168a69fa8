"""Laser goniometry: ring-laser counter logs -> angles between housing faces.

Public API::

    iter_log(path or rows) -> chunks             (streaming, validated; rows in memory too)
    read_revolutions(path or rows, n_faces) -> LogSummary (repairs / exclusions recorded)
    face_angles(summary) -> FaceAngles            (means, uncertainty, covariance, Allan)
"""

from goniometry.angles import (
    FaceAngles,
    earth_rate_counts,
    face_angles,
    kept_table,
    vertical_earth_rate,
)
from goniometry.errors import FaceCountError, LogError
from goniometry.exclusions import Exclusions
from goniometry.reader import Chunk, iter_log
from goniometry.revolutions import LogSummary, read_revolutions

__all__ = [
    "Chunk", "Exclusions", "FaceAngles", "FaceCountError", "LogError", "LogSummary",
    "earth_rate_counts", "face_angles", "iter_log", "kept_table", "read_revolutions",
    "vertical_earth_rate",
]
