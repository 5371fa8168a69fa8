"""A camera file's checks: its arrays, the intrinsics' shapes and ranges, and what a file that
is not JSON holds (:meth:`imaging.camera.CameraModel.load` reports them naming the file)."""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

DIST_LENGTHS = (4, 5, 8, 12, 14)
"""The lengths of an OpenCV distortion vector (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [tx ty]]]])."""


def array_of(d: Mapping, key: str, shape: tuple[int, ...] | None) -> np.ndarray:
    """``d[key]`` as a finite float array of ``shape`` (None: any 1-D length), or
    ValueError naming the key."""
    try:
        a = np.array(d[key], dtype=float)
    except KeyError:
        raise KeyError(f"no '{key}'") from None
    except (TypeError, ValueError):
        raise ValueError(f"'{key}' is not an array of numbers") from None
    if shape is not None and a.shape != shape:
        raise ValueError(f"'{key}' has shape {list(a.shape)}, expected {list(shape)}")
    if shape is None and a.ndim != 1:
        raise ValueError(f"'{key}' has shape {list(a.shape)}, expected a flat list")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"'{key}' holds a non-finite value (NaN, inf or null)")
    return a


def checked_intrinsics(d: Mapping) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """The camera matrix, distortion and image size of a camera file, each checked as any
    other input is: shapes, finite values, focal lengths > 0, the principal point inside the
    image, the matrix's fixed entries. ValueError/KeyError naming the key (:meth:`CameraModel.load`
    adds the file)."""
    K = array_of(d, "camera_matrix", (3, 3))
    D = array_of(d, "dist_coeffs", None)
    size = array_of(d, "image_size", (2,))
    if np.any(size != np.round(size)) or np.any(size < 16):
        raise ValueError(f"'image_size' {size.tolist()} is not two whole numbers of pixels "
                         "(width, height) of at least 16")
    w, h = (int(v) for v in size)
    if len(D) not in DIST_LENGTHS:
        raise ValueError(f"'dist_coeffs' has {len(D)} values; OpenCV's have "
                         f"{', '.join(map(str, DIST_LENGTHS))}")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fx <= 0 or fy <= 0:
        raise ValueError(f"'camera_matrix' focal lengths fx {fx:g}, fy {fy:g} px: both must "
                         "be > 0")
    if not (0 <= cx <= w and 0 <= cy <= h):
        raise ValueError(f"'camera_matrix' principal point ({cx:g}, {cy:g}) px lies outside "
                         f"the {w}x{h} px image")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise ValueError("'camera_matrix' is not [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    return K, D, (w, h)



def what_text(text: str, exc: json.JSONDecodeError) -> str:
    """What a camera file that is not JSON holds, in the user's words: OpenCV's own
    FileStorage files (YAML, XML: calibration samples write them) are the common case."""
    head = text.lstrip()[:400].lower()
    if head.startswith("%yaml") or "<opencv_storage>" in head:
        kind = "YAML" if head.startswith("%yaml") else "XML"
        return (f"an OpenCV FileStorage {kind} file, not the JSON 'align camera' writes: "
                "calibrate with 'align camera' (which also gives the model's u), or write its "
                "camera_matrix, dist_coeffs and image_size as JSON (docs/formats.md, camera "
                "file)")
    return (f"not JSON ({exc.msg} at line {exc.lineno}, column {exc.colno}); a camera file is "
            "the JSON 'align camera' writes")

