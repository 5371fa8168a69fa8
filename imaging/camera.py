"""Camera model (OpenCV intrinsics + distortion): chessboard calibration, load/save, undistortion.

The JSON file holds ``camera_matrix`` (3x3), ``dist_coeffs`` (OpenCV order k1 k2 p1 p2 k3 ...),
``image_size`` [width, height], the calibration's RMS reprojection error [px], and (from
OpenCV's extended calibration) ``u``: standard uncertainty of each intrinsic parameter
(fx fy cx cy [px], k1 k2 p1 p2 k3) and ``per_view_rms_px``.

``u`` is the larger, per parameter, of OpenCV's formal uncertainty (``u_formal``: corner
noise taken as white and the model as exact) and the delete-one-view jackknife
(``u_jackknife``, from five views up): on the real chessboard photographs the views disagree
by 1.6-3.3x more than the formal u says (the corners' errors are correlated within a view and
the lens is not exactly OpenCV's five-coefficient model), and the marks measured through the
model inherit that error.

k3 is fitted only when the views determine it (:mod:`imaging.camera_k3`): else the model is
the k3-free fit with k3's range carried in ``cov`` (``lens_choice`` says which and why).
The board's x/y scale is fitted with the intrinsics (:mod:`imaging.camera_board`): corrected
when significant, else its range carried in ``cov`` (``board_scale``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from axisbase.errors import InputError
from axisbase.provenance import check_format
from imaging.camera_board import (
    BOARD_TOLERANCE,
    board_choice,
    board_fit,
    carried,
    scaled_board,
    significant,
)
from imaging.camera_cov import INTRINSICS, dominating, formal_cov, jackknife_cov
from imaging.camera_file import array_of, checked_intrinsics, what_text
from imaging.camera_k3 import choose_k3, left_out_term
from imaging.camera_views import MIN_VIEWS, not_one_camera_warning, one_camera_check, untested
from imaging.errors import ImageInputError


@dataclass(frozen=True)
class CameraModel:
    """A camera's intrinsics and lens distortion (OpenCV's model), from ``align camera``.

    Attributes
    ----------
    camera_matrix : numpy.ndarray
        K (3, 3): focal lengths and principal point [px].
    dist_coeffs : numpy.ndarray
        OpenCV's distortion coefficients (k1, k2, p1, p2[, k3 ...]) — dimensionless.
    image_size : tuple of int
        (width, height) [px].
    rms_px : float
        RMS reprojection error of the calibration [px].
    views : int
        Chessboard views used — dimensionless.
    u : dict or None
        Standard uncertainty per parameter (fx, fy, cx, cy [px]; k1, ... dimensionless): the
        larger of ``u_formal`` and ``u_jackknife``; from five views also ``aspect`` (of
        fy / fx, dimensionless: fx and fy are strongly correlated, so far below their u's).
    per_view_rms_px : dict or None
        RMS reprojection error of each view [px].
    u_formal : dict or None
        OpenCV's formal standard uncertainty per parameter (fx, fy, cx, cy [px]; k1, ...
        dimensionless).
    u_jackknife : dict or None
        Delete-one-view jackknife standard uncertainty per parameter (fx, fy, cx, cy [px];
        k1, ... dimensionless);
        None with fewer than :data:`JACKKNIFE_MIN_VIEWS` views.
    cov : numpy.ndarray or None
        (9, 9) joint covariance of fx fy cx cy k1 k2 p1 p2 k3 (:data:`INTRINSICS`; [px²],
        [px], 1): at least the formal and the jackknife covariance in every direction
        (:mod:`imaging.camera_cov`). None in models written before format version 4: the
        angles then carry the parameters' u as if independent (warned: not an upper bound).
    cov_formal, cov_jackknife : numpy.ndarray or None
        (9, 9) [px², px, 1 as ``cov``]: the two covariances ``cov`` dominates (the
        jackknife's None below :data:`JACKKNIFE_MIN_VIEWS` views).
    lens_choice : dict or None
        Whether k3 was fitted or left out and why (:func:`imaging.camera_k3.choose_k3`;
        k3, its u and range dimensionless, RMS [px]); a
        left-out k3's term (``k3_left_out``: ``carried_direction`` w per
        :data:`INTRINSICS`, ``carried_k3`` s) is already in ``cov`` (+ s² w wᵀ). None in
        files written before format version 5 (k3 then as the file has it).
    views_one_camera : dict or None
        Whether the views are of one camera (:func:`imaging.camera_views.one_camera_check`:
        the Wald W [1] of the best split's two calibrations, its p, the groups' names and
        their fx, cx, cy [px]); ``one_camera`` False makes the model not ok
        (:attr:`problems`). None in files written before format version 6.
    board_scale : dict or None
        The board's x/y scale s fitted with the intrinsics and what was done with it
        (:func:`imaging.camera_board.board_choice`: corrected, nominal or not separable; s,
        its u and the range carried, dimensionless): the carried term is already in ``cov``.
        None in files written before it.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float = float("nan")
    views: int = 0
    u: dict[str, float] | None = None
    per_view_rms_px: dict[str, float] | None = None
    u_formal: dict[str, float] | None = None
    u_jackknife: dict[str, float] | None = None
    cov: np.ndarray | None = None
    cov_formal: np.ndarray | None = None
    cov_jackknife: np.ndarray | None = None
    lens_choice: dict | None = None
    views_one_camera: dict | None = None
    board_scale: dict | None = None

    @property
    def problems(self) -> list[str]:
        """Why the model cannot be trusted: its views are not of one camera
        (:func:`imaging.camera_views.not_one_camera_warning`); empty when it can."""
        w = not_one_camera_warning(self.views_one_camera or {})
        return [w] if w else []

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
            "u_formal": dict(self.u_formal or {}), "u_jackknife": dict(self.u_jackknife or {}),
            "cov_params": list(INTRINSICS),
            **{k: (None if v is None else v.tolist()) for k, v in (
                ("cov", self.cov), ("cov_formal", self.cov_formal),
                ("cov_jackknife", self.cov_jackknife))},
            "lens_choice": None if self.lens_choice is None else dict(self.lens_choice),
            "views_one_camera": (None if self.views_one_camera is None
                                 else dict(self.views_one_camera)),
            "board_scale": None if self.board_scale is None else dict(self.board_scale),
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> CameraModel:
        """From :meth:`to_dict`'s keys; raises KeyError, ValueError or TypeError on a dict
        that is not a camera model (:meth:`load` turns them into one line naming the file)."""
        def num(v: object, key: str) -> float:  # strict JSON saves NaN as null
            if v is None:
                return float("nan")
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"'{key}' is {json.dumps(v)}, not a number")
            return float(v)

        def table(key: str) -> dict[str, float] | None:
            t = d.get(key) or {}
            if not isinstance(t, Mapping):
                raise ValueError(f"'{key}' is not a table of name: number")
            out = {k: num(v, f"{key}.{k}") for k, v in t.items()}
            bad = [k for k, v in out.items() if key != "per_view_rms_px" and v < 0]
            if bad:
                raise ValueError(f"'{key}.{bad[0]}' is {out[bad[0]]:g}: an uncertainty is "
                                 ">= 0")
            return out or None

        def cov(key: str) -> np.ndarray | None:
            if d.get(key) is None:
                return None
            if list(d.get("cov_params", INTRINSICS)) != list(INTRINSICS):
                raise ValueError(f"'cov_params' is not {list(INTRINSICS)}")
            c = array_of(d, key, (len(INTRINSICS), len(INTRINSICS)))
            s = np.sqrt(np.abs(np.outer(np.diag(c), np.diag(c))))
            if np.any(np.diag(c) < 0) or np.any(np.abs(c - c.T) > 1e-6 * s):
                raise ValueError(f"'{key}' is not a covariance (symmetric, diagonal >= 0)")
            return c

        def choice() -> dict | None:
            c = d.get("lens_choice")
            if c is None:
                return None
            if not isinstance(c, Mapping):
                raise ValueError("'lens_choice' is not a table")
            out = dict(c)
            if out.get("carried_k3") is not None:
                out["carried_k3"] = num(out["carried_k3"], "lens_choice.carried_k3")
                w = array_of(c, "carried_direction", (len(INTRINSICS),))
                out["carried_direction"] = w.tolist()
            return out

        def views() -> dict | None:
            v = d.get("views_one_camera")
            if v is not None and not isinstance(v, Mapping):
                raise ValueError("'views_one_camera' is not a table")
            if v is not None and not isinstance(v.get("one_camera"), (bool, type(None))):
                raise ValueError("'views_one_camera.one_camera' is not true, false or null")
            return None if v is None else dict(v)

        board = d.get("board_scale")
        if board is not None and not isinstance(board, Mapping):
            raise ValueError("'board_scale' is not a table")
        K, D, (w, h) = checked_intrinsics(d)
        return cls(K, D, (w, h), num(d.get("rms_px"), "rms_px"), int(d.get("views", 0)), table("u"),
                   table("per_view_rms_px"), table("u_formal"), table("u_jackknife"),
                   cov("cov"), cov("cov_formal"), cov("cov_jackknife"), choice(),
                   views(), None if board is None else dict(board))

    @classmethod
    def load(cls, path: str | Path) -> CameraModel:
        p = Path(path)
        try:
            text = p.read_text(encoding="utf-8-sig")  # a BOM is not JSON's
            d = json.loads(text)
            model = cls.from_dict(d)
        except UnicodeDecodeError:
            raise ImageInputError(f"{p}: not a camera file: binary data, not text (an image? "
                                  "a camera file is the JSON 'align camera' writes)") from None
        except json.JSONDecodeError as exc:
            raise ImageInputError(f"{p}: not a camera file: {what_text(text, exc)}") from None
        except FileNotFoundError:
            raise ImageInputError(f"{p}: camera file not found") from None
        except IsADirectoryError:
            raise ImageInputError(f"{p}: is a folder, not a camera file") from None
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            why = exc.args[0] if exc.args else type(exc).__name__
            raise ImageInputError(f"{p}: not a usable camera file: {why} (expected "
                                  "camera_matrix, dist_coeffs, image_size as written by "
                                  "'align camera')") from None
        try:  # version 1: files written before format versions existed
            check_format(d, "axis-align/camera", (1, 2, 3, 4, 5, 6), str(p))
        except InputError as exc:
            raise ImageInputError(str(exc)) from None
        return model

    def undistort_centred(self, pts: np.ndarray, sigma: np.ndarray, shape: tuple[int, int]
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Undistort points given relative to the image centre; keep that convention.

        The output is in the pinhole image with square pixels of the column pitch (the
        camera matrix with fy set to fx): an angle there is the angle in the object plane,
        the same convention as the lens route's y / (1 + aspect); keeping fy/fx in the
        coordinates would turn a 45 deg mark by (fy/fx - 1) / 2 rad (0.1 deg at 1.0035).
        Lengths stay in pixels; each sigma is scaled by the local magnification.
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
        """Undistorted pinhole pixels (square, of the column pitch) of distorted pixels [px]."""
        src = np.ascontiguousarray(pix, dtype=np.float64).reshape(-1, 1, 2)
        square = self.camera_matrix.copy()
        square[1, 1] = square[0, 0]
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            und = cv2.undistortPointsIter(src, self.camera_matrix, self.dist_coeffs, None,
                                          square, crit)
        else:  # OpenCV 5 takes the criteria in undistortPoints itself
            und = cv2.undistortPoints(src, self.camera_matrix, self.dist_coeffs, None, None,
                                      square, crit)
        return und.reshape(-1, 2)


def find_chessboard(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners of a chessboard (cols x rows inner corners), or None.

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN] (any depth: scaled to 8 bits for the search).
    pattern : tuple of int
        Inner corners per row and per column (cols, rows).

    Returns
    -------
    ndarray or None
        (cols x rows, 2) corners (x, y) [px] in OpenCV's order; None when the board is not
        found.
    """
    img8 = image if image.dtype == np.uint8 else cv2.normalize(
        image, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    ok, corners = cv2.findChessboardCorners(img8, pattern)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    return cv2.cornerSubPix(img8, corners, (5, 5), (-1, -1), crit).reshape(-1, 2)


JACKKNIFE_MIN_VIEWS = 5
"""Fewest views for the delete-one jackknife of the intrinsics' u (four dof at five)."""


def _intrinsics(K: np.ndarray, D: np.ndarray) -> np.ndarray:
    """fx fy cx cy k1 k2 p1 p2 k3 of a calibration, in :data:`INTRINSICS`' order."""
    return np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.ravel(D)[:5]]


def jackknife_estimates(objpts: list, imgpts: list, size: tuple[int, int],
                        K0: np.ndarray | None, flags: int) -> np.ndarray:
    """The intrinsics (:data:`INTRINSICS`, then the aspect fy / fx) of each of the n
    leave-one-view-out calibrations, (n, 10).

    By hand because OpenCV states only the formal u (white corner noise, exact model); the
    spread of the calibration over its views is what a mark measured through the model
    meets: u_J² = (n−1)/n · Σ (θ₋ᵢ − θ̄)² (:func:`imaging.camera_cov.jackknife_cov`)."""
    n = len(objpts)
    est = np.array([_intrinsics(*cv2.calibrateCamera(
        objpts[:i] + objpts[i + 1:], imgpts[:i] + imgpts[i + 1:], size,
        None if K0 is None else K0.copy(), None, flags=flags)[1:3]) for i in range(n)])
    return np.column_stack([est, est[:, 1] / est[:, 0]])  # and the aspect fy / fx


_GUESS_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-9)
"""The one-camera check's sub-fits start at the pooled fit and stop at a 1e-9 relative step
(4x faster than from scratch to machine precision; the intrinsics agree to 1e-6 px)."""


def views_one_camera(objpts: list, imgpts: list, size: tuple[int, int], names: list[str],
                     K0: np.ndarray | None, flags: int, est: np.ndarray) -> dict:
    """Whether the views are of one camera (:func:`imaging.camera_views.one_camera_check`),
    from the pooled fit's leave-one-view-out ``est`` (:func:`jackknife_estimates`)."""
    n = len(objpts)
    rms, Kp, Dp, _, _ = cv2.calibrateCamera(objpts, imgpts, size, None if K0 is None
                                            else K0.copy(), None, flags=flags)
    fits: dict[tuple, tuple] = {}

    def fit(idx: tuple) -> tuple:
        """K, D, rvecs, tvecs of the views ``idx`` (cached: the classification and the
        comparison fit the same groups)."""
        if idx not in fits:
            fits[idx] = cv2.calibrateCamera(
                [objpts[i] for i in idx], [imgpts[i] for i in idx], size, Kp.copy(),
                Dp.copy(), flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS,
                criteria=_GUESS_CRIT)[1:]
        return fits[idx]

    def halves(group: np.ndarray) -> tuple[tuple, tuple]:
        return tuple(np.flatnonzero(~group)), tuple(np.flatnonzero(group))

    def view_rms(group: np.ndarray) -> np.ndarray:
        out = np.zeros((n, 2))
        for j, idx in enumerate(halves(group)):
            K, D = fit(idx)[:2]
            for i, (oi, qi) in enumerate(zip(objpts, imgpts, strict=True)):
                _, r, t = cv2.solvePnP(oi, qi, K, D)
                proj = cv2.projectPoints(oi, r, t, K, D)[0]
                out[i, j] = np.sqrt(np.mean(np.sum((proj - qi).reshape(-1, 2)**2, axis=1)))
        return out

    def group_fit(group: np.ndarray) -> list:
        out = []
        for idx in halves(group):
            K, D, rv, tv = fit(idx)
            formal = formal_cov([objpts[i] for i in idx], [imgpts[i] for i in idx], K, D, rv,
                                tv, bool(flags & cv2.CALIB_FIX_K3), K0 is not None)
            jack = jackknife_cov(np.array([_intrinsics(*fit(idx[:k] + idx[k + 1:])[:2])
                                           for k in range(len(idx))]))
            out.append((_intrinsics(K, D), formal, jack))
        return out

    pseudo = n * _intrinsics(Kp, Dp) - (n - 1) * est[:, :len(INTRINSICS)]
    return one_camera_check(pseudo, names, view_rms, group_fit)


def jackknife_u(objpts: list, imgpts: list, size: tuple[int, int], K0: np.ndarray | None,
                flags: int) -> np.ndarray:
    """Delete-one-view jackknife standard uncertainty of each intrinsic and the aspect."""
    est = jackknife_estimates(objpts, imgpts, size, K0, flags)
    return np.sqrt(np.diag(jackknife_cov(est)))



def calibrate_chessboard(images: dict[str, np.ndarray], pattern: tuple[int, int],
                         square: float = 1.0, fix_k3: bool = False, fix_aspect: bool = False,
                         k3: str = "auto", board_tolerance: float | None = None
                         ) -> tuple[CameraModel, dict[str, str]]:
    """Calibrate intrinsics + 5-coefficient distortion from chessboard views.

    OpenCV's extended calibration: also the standard uncertainty of each intrinsic parameter
    (``u``; 0 for a fixed one: the larger of OpenCV's formal u and, from
    :data:`JACKKNIFE_MIN_VIEWS` views, the delete-one-view jackknife) and each view's RMS
    reprojection error. ``k3``: ``auto`` fits k3 only when the views determine it, else
    leaves it out and carries its range in ``cov`` (:mod:`imaging.camera_k3`); ``free``
    always fits it (OpenCV's default), ``fixed`` (or ``fix_k3``) keeps it at 0 as known.
    ``fix_aspect`` keeps fx / fy at 1. The board's x/y scale is fitted with the intrinsics
    and corrected, or its range carried (:mod:`imaging.camera_board`; ``board_tolerance``
    the print's, 0.001 = 0.1 %).

    Parameters
    ----------
    images : dict of str to numpy.ndarray
        Chessboard photographs by name (8- or 16-bit grey).
    pattern : tuple of int
        Inner corners (columns, rows).
    square : float
        Side of a square (any unit; the intrinsics do not depend on it).
    fix_k3, fix_aspect : bool
        Keep k3 at 0 (as ``k3="fixed"``); keep fx / fy at 1.
    k3 : str
        ``auto``, ``free`` or ``fixed`` (:data:`K3_MODES`).
    board_tolerance : float or None
        The board's print tolerance of its x/y scale ratio (dimensionless; None:
        :data:`imaging.camera_board.BOARD_TOLERANCE`).

    Returns
    -------
    CameraModel
        The model, with ``u``, ``u_formal``, ``u_jackknife`` and per-view RMS [px].
    dict of str to str
        Per file that could not be used, the reason.
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
    names = [n for n in images if n not in failed]
    return calibrate_corners(objpts, imgpts, size, names, fix_k3, fix_aspect, k3,
                             board_tolerance), failed


K3_MODES = ("auto", "free", "fixed")
"""How ``align camera`` treats k3 (:func:`calibrate_chessboard`)."""


def calibrate_corners(objpts: list, imgpts: list, size: tuple[int, int], names: list[str],
                      fix_k3: bool = False, fix_aspect: bool = False, k3: str = "auto",
                      board_tolerance: float | None = None) -> CameraModel:
    """:func:`calibrate_chessboard` from the boards' corners found: ``objpts`` per view the
    board's corners (N, 3) [board units] (float32), ``imgpts`` their image (N, 1, 2) [px]
    (float32), ``size`` (width, height) [px], ``names`` one per view.

    The board's x/y scale s is fitted at the calibration (:mod:`imaging.camera_board`):
    significant, the calibration is redone on the board scaled by it; else its range is
    carried in the covariance (``board_scale``)."""
    m = _calibrate_lens(objpts, imgpts, size, names, fix_k3, fix_aspect, k3)

    def fit(obj: list, model: CameraModel) -> dict:
        return board_fit(obj, imgpts, model.camera_matrix, model.dist_coeffs,
                         (model.lens_choice or {}).get("k3") != "fitted", fix_aspect)

    first = fit(objpts, m)
    s, applied, last = first["s"], significant(first), first
    if applied:  # the print error named and taken out; the refit's step refines s
        objpts = scaled_board(objpts, s)
        m = _calibrate_lens(objpts, imgpts, size, names, fix_k3, fix_aspect, k3)
        last = fit(objpts, m)
        s += last["s"]
    choice = board_choice(last, s, applied, BOARD_TOLERANCE if board_tolerance is None
                          else board_tolerance)
    cov, u = carried(m.cov, m.u or {}, m.camera_matrix, choice)
    return replace(m, cov=cov, u=u, board_scale=choice)


def _calibrate_lens(objpts: list, imgpts: list, size: tuple[int, int], names: list[str],
                    fix_k3: bool, fix_aspect: bool, k3: str) -> CameraModel:
    """:func:`calibrate_corners` on the board as given: the lens model chosen (k3) and the
    views' one-camera check."""
    mode = "fixed" if fix_k3 else k3
    if mode not in K3_MODES:
        raise ValueError(f"k3 mode {mode!r} is not one of {K3_MODES}")
    if mode != "auto":
        m = _calibrate(objpts, imgpts, size, names, mode == "fixed", fix_aspect)
        return replace(m, lens_choice={"k3": "fitted" if mode == "free" else "left out",
                                       "why": f"k3 {mode} as asked"})
    jack: dict[bool, np.ndarray] = {}  # each fit's jackknife, reused by the views' check
    free = _calibrate(objpts, imgpts, size, names, False, fix_aspect, check=False, keep=jack)
    fixed = _calibrate(objpts, imgpts, size, names, True, fix_aspect, check=False, keep=jack)
    k3_hat = float(np.ravel(free.dist_coeffs)[4])
    u_k3 = float((free.u or {}).get("k3", 0.0))
    points = sum(len(p) for p in imgpts)
    params = 9 - int(fix_aspect) + 6 * len(objpts)
    choice = choose_k3(free.rms_px, fixed.rms_px, points, params, k3_hat, u_k3)
    fitted = choice["k3"] == "fitted"
    views = _views_check(objpts, imgpts, size, names, not fitted, fix_aspect,
                         jack.get(not fitted))
    if fitted:
        return replace(free, lens_choice=choice, views_one_camera=views)
    w, s_k3 = left_out_term(free.cov, k3_hat, u_k3)
    choice.update(carried_k3=s_k3, carried_direction=w.tolist())
    cov = fixed.cov + s_k3**2 * np.outer(w, w)
    # Each parameter's u with the carried term in it (k3's is the range carried, not the 0
    # of a parameter held fixed): the file's u and its covariance say the same.
    u = {k: float(max(v, np.sqrt(cov[INTRINSICS.index(k), INTRINSICS.index(k)])))
         if k in INTRINSICS else v for k, v in (fixed.u or {}).items()}
    return replace(fixed, cov=cov, u=u, lens_choice=choice, views_one_camera=views)


def _views_check(objpts: list, imgpts: list, size: tuple[int, int], names: list[str],
                 fix_k3: bool, fix_aspect: bool, est: np.ndarray | None = None) -> dict:
    """:func:`views_one_camera` with the calibration's flags (``est``: its jackknife
    estimates when already computed); not tested below :data:`MIN_VIEWS` views."""
    if len(objpts) < MIN_VIEWS:
        return untested(len(objpts))
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect
                                                    else 0)
    K0 = np.eye(3) if fix_aspect else None
    if est is None:
        est = jackknife_estimates(objpts, imgpts, size, K0, flags)
    return views_one_camera(objpts, imgpts, size, names, K0, flags, est)


def _calibrate(objpts: list, imgpts: list, size: tuple[int, int], names: list[str],
               fix_k3: bool, fix_aspect: bool, check: bool = True,
               keep: dict | None = None) -> CameraModel:
    """One OpenCV calibration with its u's and joint covariances (k3 free or at 0), and
    (``check``) whether its views are of one camera (:func:`views_one_camera`); ``keep``
    receives its jackknife estimates under ``fix_k3`` (a views' check of the same fit
    reuses them: each is one calibration per view)."""
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (cv2.CALIB_FIX_ASPECT_RATIO if fix_aspect
                                                    else 0)
    K0 = np.eye(3) if fix_aspect else None
    rms, K, D, rvecs, tvecs, sd, _, per_view = cv2.calibrateCameraExtended(
        objpts, imgpts, size, None if K0 is None else K0.copy(), None, flags=flags)
    formal = np.ravel(sd)[:len(INTRINSICS)]
    u_formal = {k: float(v) for k, v in zip(INTRINSICS, formal, strict=True)}
    u_jack = None
    u = dict(u_formal)
    cov_f = formal_cov(objpts, imgpts, K, D, rvecs, tvecs, fix_k3, fix_aspect)
    cov_j = None
    if len(objpts) >= JACKKNIFE_MIN_VIEWS:
        est = jackknife_estimates(objpts, imgpts, size, K0, flags)
        if keep is not None:
            keep[fix_k3] = est
        cov_j = jackknife_cov(est[:, :-1])
        jack = np.sqrt(np.diag(jackknife_cov(est)))
        jack[:-1][formal == 0] = 0.0  # a fixed parameter stays exact
        u_jack = {k: float(v) for k, v in zip((*INTRINSICS, "aspect"), jack, strict=True)}
        u = {k: float(max(v, u_jack[k])) for k, v in u_formal.items()}
        # fx and fy move together (one board scale): the aspect fy / fx is known far better
        # than their u's together say. OpenCV gives no covariance, so its u is the jackknife's,
        # at least what fully correlated fx, fy would leave; 0 when fixed.
        a = K[1, 1] / K[0, 0]
        floor = a * abs(u["fy"] / K[1, 1] - u["fx"] / K[0, 0])
        u["aspect"] = 0.0 if fix_aspect else float(max(u_jack["aspect"], floor))
    return CameraModel(K, D.ravel(), size, float(rms), len(objpts), u,
                       {n: float(v) for n, v in zip(names, np.ravel(per_view), strict=True)},
                       u_formal, u_jack, cov_f if cov_j is None else dominating(cov_f, cov_j),
                       cov_f, cov_j, views_one_camera=None if not check else _views_check(
                           objpts, imgpts, size, names, fix_k3, fix_aspect,
                           None if cov_j is None else est))
