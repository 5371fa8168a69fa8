"""A camera whose marks show that its lens is not its model (issue 18, user 12): the lens taken
as undetermined, as without a model.

When the marks bow beyond what the calibrated lens leaves them, the calibration is not the lens
— and the one change of it their bows call for is not the lens either: a stereo rig's other
camera's model (principal points 14 px apart, k's differing) left a single mark's bow explained
by a k1 change whose reading was still 700-1100″ off at a stated ± 70-310″ (z up to 10). What
is known then is what the marks determine of the lens on top of the model, and the plausible
ranges for the rest (Type B, :class:`align.lens_design.LensRanges`), exactly as for a camera
without a model (:func:`align.lens.solve_lens`): that u replaces the one alternative reading,
and where it is beyond the lens bound the angle is lens-limited ("recalibrate the camera").

The solve on top of the model sees what is left of the distortion, not the model's own: a
principal point moved under a strong model's distortion turns a line where no distortion is
left to turn it (the no-model solve's principal-point terms are 0 at no distortion), and the
rig's other camera's model is 13-15 px off there. So the model's own principal point is
carried too, anywhere within the plausible range of the image centre (:func:`pp_coupling`).
For the same reason the check of the marks against the model gets the model's principal
point as its lever (:func:`model_lever`): without it a straight mark that a moved principal
point bowed was read as a bent mark beside a kept calibration — 11 of 108 marks under the
other camera's model silently 3.6-11.6 u off (user 12's rig, tests/align/test_lens_fallback.py).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import solve_triangular

from align.camera_model_u import raw_pixels
from align.lens import LensRanges, LensSolution, LineGeometry, solve_lens
from align.lens_bump import PP, pp_angle_coupling
from align.lens_design import _Design
from align.lens_terms import angle_coupling, camera_departure
from align.mark_stage import half_diagonal
from imaging import CameraModel, line_frame
from imaging.lens import PARAMS

WIDENING = ("camera_or_bent", "camera_disagreement")
"""The u terms a camera model's check adds when its marks depart from it (docs/camera.md);
their name stays, their size becomes the undetermined lens's (:func:`carried`)."""


@dataclass(frozen=True)
class LensBeyondModel:
    """The lens on top of a camera model its marks depart from, as without a model.

    Attributes
    ----------
    sol : LensSolution
        What the marks determine of it (applied) and what they leave to the ranges.
    coupling : tuple of dict
        Per mark, its angle's lens terms as signed components [rad], shared by the marks of
        the camera (:func:`align.lens_terms.angle_coupling`).
    """

    sol: LensSolution
    coupling: tuple[dict[str, float], ...]


COEFFS = tuple(PARAMS.index(k) for k in ("k1", "k2", "p1", "p2"))
"""The lens vector's entries that are also a camera model's own distortion coefficients (its
``dist_coeffs`` 0-3)."""

COEFF_STEP = 1e-3
"""The central difference's step of each of the model's coefficients, in the lens vector's
units (at the half-diagonal): a bow of ~0.2 px at the frame's corner."""


def _across(camera: CameraModel, raw: np.ndarray, sigma: np.ndarray, shape: tuple[int, int],
            n: np.ndarray, moved) -> np.ndarray:
    """How each centre, undistorted by ``camera``, moves across its line (normal ``n``) per
    unit of a change of the model (``moved(camera, step)``: the model moved by ``step`` of
    the unit; central difference at +- 1 step) [px per unit]."""
    q = [moved(camera, step).undistort_centred(raw, sigma, shape)[0] for step in (1.0, -1.0)]
    return (q[0] - q[1]) @ n / 2.0


def _moved_pp(axis: int):
    def moved(camera: CameraModel, step: float) -> CameraModel:
        K = camera.camera_matrix.copy()
        K[axis, 2] += step
        return replace(camera, camera_matrix=K)
    return moved


def _moved_coeff(j: int, per_unit: float):
    def moved(camera: CameraModel, step: float) -> CameraModel:
        D = np.zeros(max(5, np.size(camera.dist_coeffs)))
        D[:np.size(camera.dist_coeffs)] = np.ravel(camera.dist_coeffs)
        D[j] += step * per_unit
        return replace(camera, dist_coeffs=D)
    return moved


def model_lever(designs: Sequence[_Design], lines: Sequence[LineGeometry],
                camera: CameraModel, shape: tuple[int, int]) -> list[_Design]:
    """The marks' designs against a camera model (taken at no lens on top of it:
    :func:`align.lens_terms.check_camera`) with the model's own levers: how each undistorted
    centre moves across its line when the model's principal point moves (``cx``, ``cy``, per
    px) and when its distortion coefficients change (``k1``, ``k2``, ``p1``, ``p2``, per unit
    of the lens vector at the half-diagonal: OpenCV's k1 (R/f)^2, k2 (R/f)^4, p R/f), each a
    central difference of the model, its straight-line part projected out as
    :func:`align.lens_design._design` does.

    At no lens the principal point's columns are 0, and a principal point's bow could only
    be read as a bent mark. The coefficients' columns of a change *on top of* the model (the
    undistorted centres distorted again) are not a change of the model's coefficients: a
    real change of k1 (the model's -0.20 for a lens of -0.27) seen through the model is a
    radial bow no k1, k2 on top describes exactly, and two straight marks far from the
    centre read it as different (k1, k2) even noise-free: two 240/220 px corner marks, their
    centres out to the grooves' ends, disagreed at chi2 8.1 on 2 dof (k1 -0.0390 / -0.0374,
    k2 -0.0205 / -0.0175), and with noise at 14.5 (p 7e-4: a changed lens read 'neither');
    with these columns 0.02 (k1 -0.0390 / -0.0387 for a true -0.0399), 0.8 with noise."""
    h, w = shape
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    a = half_diagonal(shape) / float(camera.camera_matrix[0, 0])
    per_unit = {0: a**-2, 1: a**-4, 2: a**-1, 3: a**-1}  # the model's units per vector unit
    levers = [(j, _moved_coeff(j, COEFF_STEP * per_unit[k]), COEFF_STEP)
              for k, j in enumerate(COEFFS)]
    levers += [(j, _moved_pp(axis), 1.0) for axis, j in enumerate(PP)]
    cols = [j for j, _, _ in levers]
    out = []
    for d, ln in zip(designs, lines, strict=True):
        raw = raw_pixels(camera, ln.points, shape) - c
        u, n = line_frame(d.angle)
        E = np.column_stack([_across(camera, raw, ln.sigma, shape, n, moved) / step
                             for _, moved, step in levers])
        J = np.column_stack([ln.points @ u, -np.ones(len(ln.points))])
        X = np.column_stack([J, E]) / ln.sigma[:, None]
        if ln.chol is not None:
            X = solve_triangular(ln.chol, X, lower=True, check_finite=False)
        Jw, Ew = X[:, :2], X[:, 2:]
        coef = np.linalg.lstsq(Jw, Ew, rcond=None)[0]
        G, sv = d.G.copy(), d.s.copy()
        G[:, cols] = Ew - Jw @ coef
        sv[cols] = -coef[0]
        out.append(replace(d, G=G, s=sv))
    return out


def still_departs(designs: Sequence[_Design], lone: Sequence[int], lam_u: np.ndarray,
                  ranges: LensRanges, alpha: float) -> bool:
    """Whether the marks not read as bent (``lone``: the marks a lens change cannot have
    bowed, :func:`align.lens_terms.lone_departures`, :func:`align.lens_terms.lens_or_bends`)
    still depart from the calibration together at ``alpha`` (their joint check): then the
    bends do not explain the departure, and the lens is not its model. (Each of them may be
    within the calibration's u on its own — user 12's rig, the other camera's model: the
    straight marks bowed 13-15 sigma each, inside the model's u, jointly p 1e-9..1e-18.)"""
    rest = [d for k, d in enumerate(designs) if k not in lone]
    return bool(rest) and camera_departure(rest, lam_u, ranges, alpha)[0] < alpha


def pp_coupling(camera: CameraModel, line: LineGeometry, shape: tuple[int, int],
                ranges: LensRanges) -> dict[str, float]:
    """One mark's angle components [rad] of the model's principal point taken anywhere
    within ``ranges.pp_px`` of the image centre (per axis a uniform about the model's own,
    half-width the range plus the model's distance from the centre: / sqrt 3), through the
    model's distortion (:func:`align.camera_model_u.angle_sensitivity`; keys ``pp.cx``,
    ``pp.cy``)."""
    h, w = shape
    K = camera.camera_matrix
    half = ranges.pp_px + np.abs(K[:2, 2] - [(w - 1) / 2, (h - 1) / 2])
    return pp_angle_coupling(camera, line, shape, half / np.sqrt(3))


def lens_beyond_model(lines: Sequence[LineGeometry], scale: float, ranges: LensRanges,
                      alpha: float, camera: CameraModel, shape: tuple[int, int]
                      ) -> LensBeyondModel:
    """The lens of a camera whose marks ``lines`` (already undistorted by its model) depart
    from the model: solved as without one, within ``ranges`` (the defaults when they declare
    the camera distortion-free: a model that is not the lens says nothing of that).

    Parameters
    ----------
    lines : sequence of LineGeometry
        The camera's marks, centres [px] in the model's undistorted frame.
    scale : float
        The half-diagonal R [px].
    ranges : LensRanges
        The plausible lens (Type B) beyond the model.
    alpha : float
        Significance of the solve's tests.
    camera : imaging.CameraModel
        The model departed from: its principal point is carried (:func:`pp_coupling`).
    shape : tuple of int
        The image's (rows, columns).
    """
    if not np.any(ranges.vector()):
        ranges = LensRanges(max_u_arcsec=ranges.max_u_arcsec)
    sol, designs = solve_lens(lines, scale, ranges, alpha)
    return LensBeyondModel(sol, tuple({**angle_coupling(sol, d), **pp_coupling(camera, ln, shape,
                                                                                ranges)}
                                      for d, ln in zip(designs, lines, strict=True)))


def carried(terms: Mapping[str, float], coupling: Mapping[str, float]) -> dict[str, float]:
    """One mark's model terms with the check's widening term (:data:`WIDENING`: one
    alternative reading) replaced by the undetermined lens's components ``coupling``, under
    the same name (``camera_or_bent.lens_k1``, ...: the term's size is their root sum of
    squares, and marks of one camera share them)."""
    out = dict(terms)
    names = [k for k in WIDENING if out.pop(k, None) is not None]
    name = names[0] if names else WIDENING[1]
    out.update({f"{name}.{k}": float(v) for k, v in coupling.items()})
    return out
