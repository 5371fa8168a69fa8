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
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from align.camera_model_u import model_coupling
from align.lens import LensRanges, LensSolution, LineGeometry, solve_lens
from align.lens_terms import angle_coupling
from imaging import CameraModel
from imaging.camera_cov import INTRINSICS

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


def pp_coupling(camera: CameraModel, line: LineGeometry, shape: tuple[int, int],
                ranges: LensRanges) -> dict[str, float]:
    """One mark's angle components [rad] of the model's principal point taken anywhere
    within ``ranges.pp_px`` of the image centre (per axis a uniform about the model's own,
    half-width the range plus the model's distance from the centre: / sqrt 3), through the
    model's distortion (:func:`align.camera_model_u.model_coupling`, keys ``pp.i``)."""
    h, w = shape
    K = camera.camera_matrix
    half = ranges.pp_px + np.abs(K[:2, 2] - [(w - 1) / 2, (h - 1) / 2])
    cov = np.zeros((len(INTRINSICS), len(INTRINSICS)))
    cov[2, 2], cov[3, 3] = (half / np.sqrt(3)) ** 2
    got = model_coupling(replace(camera, cov=cov), line.points, line.sigma, line.chol, shape)
    return {f"pp.{k.rsplit('.', 1)[1]}": v for k, v in got.items()}


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
