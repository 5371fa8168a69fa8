"""Camera model (OpenCV intrinsics + distortion): chessboard calibration, load/save, undistortion.

The JSON file holds ``camera_matrix`` (3x3), ``dist_coeffs`` (OpenCV order k1 k2 p1 p2 k3 ...),
``image_size`` [width, height], the calibration's RMS reprojection error [px], and (from
OpenCV's extended calibration) ``u``: standard uncertainty of each intrinsic parameter
(fx fy cx cy [px], k1 k2 p1 p2 k3) and ``per_view_rms_px``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from axisbase.errors import InputError
from axisbase.provenance import check_format
from imaging.errors import ImageInputError


@dataclass(frozen=True)
class CameraModel:
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float = float("nan")
    views: int = 0
    u: dict[str, float] | None = None
    per_view_rms_px: dict[str, float] | None = None

    @property
    def focal_px(self) -> float:
        return float(np.sqrt(self.camera_matrix[0, 0] * self.camera_matrix[1, 1]))

    def to_dict(self) -> dict:
        """The model as ``align camera --json`` saves it (OpenCV's order and units: [px])."""
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.ravel().tolist(),
            "image_size": list(self.image_size), "rms_px": self.rms_px, "views": self.views,
            "u": dict(self.u or {}), "per_view_rms_px": dict(self.per_view_rms_px or {}),
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> CameraModel:
        """From :meth:`to_dict`'s keys; raises KeyError, ValueError or TypeError on a dict
        that is not a camera model (:meth:`load` turns them into one line naming the file)."""
        def num(v: object) -> float:  # strict JSON saves NaN as null
            return float("nan") if v is None else float(v)  # type: ignore[arg-type]

        K = np.array(d["camera_matrix"], float).reshape(3, 3)
        D = np.array(d["dist_coeffs"], float).ravel()
        w, h = (int(v) for v in d["image_size"])
        return cls(K, D, (w, h), num(d.get("rms_px")), int(d.get("views", 0)),
                   {k: num(v) for k, v in (d.get("u") or {}).items()} or None,
                   {k: num(v) for k, v in (d.get("per_view_rms_px") or {}).items()} or None)

    @classmethod
    def load(cls, path: str | Path) -> CameraModel:
        p = Path(path)
        try:
            d = json.loads(p.read_text(encoding="utf-8-sig"))  # a BOM is not JSON's
            model = cls.from_dict(d)
        except FileNotFoundError:
            raise ImageInputError(f"{p}: camera file not found") from None
        except IsADirectoryError:
            raise ImageInputError(f"{p}: is a folder, not a camera file") from None
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ImageInputError(f"{p}: not a camera file ({exc!s}); expected camera_matrix, "
                                  "dist_coeffs, image_size as written by 'align camera'") from None
        try:  # version 1: files written before format versions existed
            check_format(d, "axis-align/camera", (1, 2, 3), str(p))
        except InputError as exc:
            raise ImageInputError(str(exc)) from None
        return model

    def undistort_centred(self, pts: np.ndarray, sigma: np.ndarray, shape: tuple[int, int]
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Undistort points given relative to the image centre; keep that convention.

        The output is in the pinhole image with the same camera matrix (pixels), so lengths
        stay in pixels; each sigma is scaled by the local magnification of the undistortion.
        """
        h, w = shape
        if (w, h) != tuple(self.image_size):
            raise ImageInputError(f"camera model is for {self.image_size[0]}x"
                                  f"{self.image_size[1]} images, this one is {w}x{h}")
        c = np.array([(w - 1) / 2, (h - 1) / 2])
        out = self.undistort_pixels(pts + c) - c
        probe = self.undistort_pixels(pts + c + np.array([0.5, 0.5]) / np.sqrt(2)) - c
        scale = np.linalg.norm(probe - out, axis=1) / 0.5
        return out, sigma * scale

    def undistort_pixels(self, pix: np.ndarray) -> np.ndarray:
        src = np.ascontiguousarray(pix, dtype=np.float64).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            und = cv2.undistortPointsIter(src, self.camera_matrix, self.dist_coeffs, None,
                                          self.camera_matrix, crit)
        else:  # OpenCV 5 takes the criteria in undistortPoints itself
            und = cv2.undistortPoints(src, self.camera_matrix, self.dist_coeffs, None, None,
                                      self.camera_matrix, crit)
        return und.reshape(-1, 2)


def find_chessboard(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of a chessboard (cols x rows inner corners), or None."""
    img8 = image if image.dtype == np.uint8 else cv2.normalize(
        image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    ok, corners = cv2.findChessboardCorners(img8, pattern)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    return cv2.cornerSubPix(img8, corners, (5, 5), (-1, -1), crit).reshape(-1, 2)


INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def calibrate_chessboard(images: dict[str, np.ndarray], pattern: tuple[int, int],
                         square: float = 1.0, fix_k3: bool = False, fix_aspect: bool = False
                         ) -> tuple[CameraModel, dict[str, str]]:
    """Calibrate intrinsics + 5-coefficient distortion from chessboard views.

    OpenCV's extended calibration: also the standard uncertainty of each intrinsic parameter
    (``u``; 0 for a fixed one) and each view's RMS reprojection error. ``fix_k3`` keeps k3 at
    0, ``fix_aspect`` keeps fx / fy at 1. Returns the model and, per file that could not be
    used, the reason.
    """
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2) * square
    objpts, imgpts, failed = [], [], {}
    size = None
    for name, img in images.items():
        s = (img.shape[1], img.shape[0])
        if size is not None and s != size:
            failed[name] = f"size {s[0]}x{s[1]} differs from the first image's {size[0]}x{size[1]}"
            continue
        c = find_chessboard(img, pattern)
        if c is None:
            failed[name] = f"no {pattern[0]}x{pattern[1]} chessboard found"
            continue
        size = s
        objpts.append(obj)
        imgpts.append(c.astype(np.float32).reshape(-1, 1, 2))
    if len(objpts) < 3:
        raise ImageInputError(f"only {len(objpts)} usable chessboard views; need at least 3 "
                              f"({'; '.join(f'{k}: {v}' for k, v in failed.items())})")
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect
                                                    else 0)
    K0 = np.eye(3) if fix_aspect else None
    rms, K, D, _, _, sd, _, per_view = cv2.calibrateCameraExtended(
        objpts, imgpts, size, K0, None, flags=flags)
    names = [n for n in images if n not in failed]
    u = {k: float(v) for k, v in zip(INTRINSICS, np.ravel(sd), strict=False)}
    return CameraModel(K, D.ravel(), size, float(rms), len(objpts), u,
                       {n: float(v) for n, v in zip(names, np.ravel(per_view), strict=True)}
                       ), failed
