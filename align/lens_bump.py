"""A camera bumped after its calibration (issue 18, user 15): the principal point moved, the
lens otherwise unchanged.

A knock that re-seats the lens on the sensor moves the principal point by pixels while k1, k2
stay. Under a strong distortion that turns every mark away from the centre (user 15's 640 x 480
camera, k1_cv -0.265: 60-90″ per px for marks 150-200 px out) but bows it little: three marks
of one frame determine the move only to ~3 px per axis, so a bump the angles feel 20 u deep
(8 px: +584″ at ± 32″) is a 2.5-sigma bow, and the check of the whole lens change (up to 7
parameters, :func:`align.lens_terms.camera_departure`) dilutes it further. Two answers,
both here:

* the move as its own hypothesis (2 dof: the principal point's columns of the marks' designs,
  :func:`align.lens_fallback.model_lever`), tested beside the lens change with Bonferroni
  over the two (:func:`pp_move`): a move the bows show is named and taken as a changed lens
  (the lens beyond the model undetermined, u widened, usually lens-limited), also where one
  mark's bow alone would pass for a bent mark if the move explains every mark
  (:func:`move_explains`) and the other marks do not rule it out; where they rule out
  neither the move nor the bend, both readings stand (:func:`move_or_bent`: the move's
  change of each angle carried in u as ``camera_moved_or_bent``);
* the declared stability of the principal point since calibration (``pp_stability_px``,
  :class:`align.lens_design.LensRanges`) carried in every angle of the model as the Type B
  term ``camera_pp_stability`` (:func:`stability_coupling`): a move within it is covered
  where no bow could show it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import special

from align.camera_model_u import angle_sensitivity
from align.lens import LensRanges, LineGeometry
from align.lens_design import _Design
from align.lens_terms import camera_departure, lens_cov
from imaging import CameraModel
from imaging.camera_cov import INTRINSICS
from imaging.lens import PARAMS

PP = (PARAMS.index("cx"), PARAMS.index("cy"))
STABILITY = "camera_pp_stability"
"""The u term of the declared stability (components ``camera_pp_stability.pp.cx``, ``.cy``)."""


@dataclass(frozen=True)
class PPMove:
    """The principal point's move since calibration the marks' bows call for.

    Attributes
    ----------
    shift_px : tuple of float
        (dx, dy) [px], the lens otherwise as calibrated.
    u_px : tuple of float
        Its standard uncertainties [px] (the bows', the calibration's and the declared
        stability's together: under no move beyond the stability the shift is N(0, that)).
    p : float
        Its chi-square probability (2 dof) under that null, before any multiplicity
        correction — dimensionless.
    p_bound : float
        The same against the stability taken as a bound (each axis's variance s² rather than
        s²/3: the move consistent with ``|d| <= s`` within the bows' and calibration's u),
        what a declared stability is weighed by (:func:`weigh_declared`) — dimensionless.
    """

    shift_px: tuple[float, float]
    u_px: tuple[float, float]
    p: float
    p_bound: float = 1.0

    def dlam(self) -> np.ndarray:
        """The move as a lens vector change (:data:`imaging.lens.PARAMS`)."""
        out = np.zeros(len(PARAMS))
        out[list(PP)] = self.shift_px
        return out

    def to_dict(self) -> dict:
        return {"shift_px": list(self.shift_px), "u_px": list(self.u_px), "p": self.p,
                "p_bound": self.p_bound}


def pp_move(designs: Sequence[_Design], lam_u: np.ndarray, stability_px: float) -> PPMove:
    """The principal point's move the marks' ``designs`` (with its columns:
    :func:`align.lens_fallback.model_lever`) call for, the rest of the lens held, and its
    probability against the calibration's u (``lam_u``: per PARAMS, or the joint covariance)
    plus the declared stability (uniform over +- ``stability_px``: its variance s²/3)."""
    j = list(PP)
    F = sum(d.G[:, j].T @ d.G[:, j] for d in designs)
    b = sum(d.G[:, j].T @ d.z for d in designs)
    if not np.all(np.isfinite(F)) or np.linalg.matrix_rank(F) < len(j):
        return PPMove((0.0, 0.0), (np.inf, np.inf), 1.0)
    shift = -np.linalg.solve(F, b)
    C0 = np.linalg.inv(F) + lens_cov(lam_u)[np.ix_(j, j)]
    C = C0 + np.eye(len(j)) * stability_px**2 / 3.0
    stat = float(shift @ np.linalg.solve(C, shift))
    bound = float(shift @ np.linalg.solve(C0 + np.eye(len(j)) * stability_px**2, shift))
    u = np.sqrt(np.diag(C))
    return PPMove((float(shift[0]), float(shift[1])), (float(u[0]), float(u[1])),
                  float(special.chdtrc(len(j), stat)), float(special.chdtrc(len(j), bound)))


def move_explains(designs: Sequence[_Design], move: PPMove, lam_u: np.ndarray,
                  ranges: LensRanges, alpha: float) -> bool:
    """Whether the ``move`` explains every mark's departure from the calibration: within the
    plausible range of the principal point (``ranges.pp_px`` per axis), and with it taken
    off, neither the marks together nor any one of them departs at ``alpha``
    (:func:`align.lens_terms.camera_departure`)."""
    shift = np.array(move.shift_px)
    if not np.all(np.abs(shift) <= ranges.pp_px):
        return False
    j = list(PP)
    rest = [replace(d, z=d.z + d.G[:, j] @ shift) for d in designs]
    return all(camera_departure(g, lam_u, ranges, alpha)[0] >= alpha
               for g in (rest, *([d] for d in rest)))


@dataclass(frozen=True)
class MoveOrBent:
    """A move that explains every mark (:func:`move_explains`) against the reading of some
    marks as bent beside a kept calibration, as the other (straight) marks tell them.

    Attributes
    ----------
    verdict : str
        (unit —) ``"move"`` (the others do not rule out the move the bent marks alone call for),
        ``"bent"`` (they rule out the move fitted to all the marks: they are straight) or
        ``"undecided"`` (they rule out neither reading: both stand).
    separation : float
        How far apart the two readings leave the other marks: the bow the move predicts for
        them, in sigma (whitened norm) — dimensionless.
    seen : float
        What they show of it, as a fraction of ``separation`` (0: straight, 1: the move's) —
        dimensionless.
    beyond_declared : bool
        (unit —) ``"bent"`` because the move the frame would allow is beyond the user's declared
        stability of the principal point (:func:`weigh_declared`), not because the other
        marks rule it out.
    """

    verdict: str
    separation: float
    seen: float
    beyond_declared: bool = False

    def to_dict(self) -> dict:
        return {"verdict": self.verdict, "separation": self.separation, "seen": self.seen,
                "beyond_declared": self.beyond_declared}


def _shown(designs: Sequence[_Design], others: Sequence[int], shift: np.ndarray
           ) -> tuple[float, float]:
    """The bow [sigma] the principal point's ``shift`` predicts for the ``others`` marks
    (whitened norm) and their residual along it (the fit's sign: z = -G dlam)."""
    j = list(PP)
    pred = [designs[k].G[:, j] @ shift for k in others]
    sep = float(np.sqrt(sum(p @ p for p in pred)))
    if not np.isfinite(sep) or sep == 0:
        return 0.0, 0.0
    return sep, -float(sum(designs[k].z @ p for k, p in zip(others, pred, strict=True))) / sep


def move_or_bent(designs: Sequence[_Design], move: PPMove, alpha: float,
                 bent: Sequence[int]) -> MoveOrBent:
    """Where a ``move`` explains every mark (:func:`move_explains`) and marks ``bent`` read
    as bent beside the kept calibration (the others straight), which reading the other
    marks support.

    * the move the bent marks alone call for (least norm: one mark determines one
      combination of cx, cy) would bow the others by a separation; where they show it within
      z sigma, the bent reading is no better an explanation: ``"move"``;
    * else the move fitted to all the marks: where the others show its bow more than z sigma
      short, they rule it out (they are straight): ``"bent"``; where they show it within
      z sigma and no more than z sigma from straight, one frame's marks cannot tell the two
      readings apart: ``"undecided"`` (user 15's camera moved 22-24 px: the others 4.0 /
      3.6 sigma apart under the two readings, showing 0.72 / 0.90 of the move's bow; a
      0.5 px bent mark beside two straight ones, user 13's lens: a 32-35 px move explains
      it too, the others 2.6 / 1.4 sigma apart).
    """
    z = float(-special.ndtri(alpha / 2))
    others = [k for k in range(len(designs)) if k not in bent]
    if not bent or not others:
        return MoveOrBent("move", 0.0, float("nan"))
    j = list(PP)
    Gb = np.vstack([designs[k].G[:, j] for k in bent])
    zb = np.concatenate([designs[k].z for k in bent])
    sep, seen = _shown(designs, others, -np.linalg.lstsq(Gb, zb, rcond=1e-6)[0])
    if sep == 0 or sep - seen <= z:
        return MoveOrBent("move", sep, seen / sep if sep else float("nan"))
    sep, seen = _shown(designs, others, np.array(move.shift_px))
    if sep == 0:
        return MoveOrBent("undecided", 0.0, float("nan"))
    verdict = ("bent" if abs(sep - seen) > z else "move" if abs(seen) > z else "undecided")
    return MoveOrBent(verdict, sep, seen / sep)


def weigh_declared(told: MoveOrBent, move: PPMove, ranges: LensRanges, alpha: float
                   ) -> MoveOrBent:
    """A move reading (``told``: :func:`move_or_bent`'s ``"move"`` or ``"undecided"``)
    weighed against the principal point's stability the user declared
    (``ranges.pp_stability_declared``; 0 included: "the camera was not knocked"): kept only
    where the move is consistent with it (``move.p_bound`` >= ``alpha``: ``|d|`` against
    ``sqrt(s² + u_d²)``), else the bent reading stands (``beyond_declared``). The default
    stability has no measured basis and weighs nothing: the verdict is returned unchanged
    (where the frame cannot separate the two, both stand)."""
    if (told.verdict == "bent" or not ranges.pp_stability_declared
            or move.p_bound >= alpha):
        return told
    return replace(told, verdict="bent", beyond_declared=True)


def beyond_declared_note(move: PPMove, stability_px: float) -> str:
    """What the bent-mark note adds where a move would also explain the marks but is beyond
    the declared stability (:func:`weigh_declared`)."""
    (dx, dy), (ux, uy) = move.shift_px, move.u_px
    return (f"; a move of the principal point since calibration by ({dx:+.1f}, {dy:+.1f}) ± "
            f"({ux:.1f}, {uy:.1f}) px would also explain the bows but is beyond the declared "
            f"stability (pp_stability_px = {stability_px:g}, p = {move.p_bound:.2g})")


def bonferroni(*ps: float) -> tuple[float, ...]:
    """The p-values of hypotheses tested together, each multiplied by their number (capped
    at 1): a family's false alarms at most alpha when each is taken below alpha."""
    return tuple(min(1.0, len(ps) * p) for p in ps)


def pp_angle_coupling(camera: CameraModel, line: LineGeometry, shape: tuple[int, int],
                      u_px: np.ndarray) -> dict[str, float]:
    """One mark's angle components [rad] of the model's principal point with standard
    uncertainties ``u_px`` (cx, cy) [px], through the model's distortion
    (:func:`align.camera_model_u.angle_sensitivity`; keys ``pp.cx``, ``pp.cy``)."""
    u = np.broadcast_to(np.asarray(u_px, float), (2,))
    j = [INTRINSICS.index("cx"), INTRINSICS.index("cy")]
    cov = np.zeros((len(INTRINSICS), len(INTRINSICS)))
    cov[j, j] = u**2  # the sensitivity's steps: +- u (only cx, cy move)
    g = angle_sensitivity(replace(camera, cov=cov), line.points, line.sigma, line.chol, shape)
    return {"pp.cx": float(g[j[0]] * u[0]), "pp.cy": float(g[j[1]] * u[1])}


def stability_coupling(camera: CameraModel, line: LineGeometry, shape: tuple[int, int],
                       stability_px: float) -> dict[str, float]:
    """The declared stability's components [rad] of one mark's angle
    (``camera_pp_stability.pp.cx``, ``….cy``: uniform over +- ``stability_px`` per axis,
    / sqrt 3); none at 0."""
    if stability_px <= 0:
        return {}
    c = pp_angle_coupling(camera, line, shape, np.full(2, stability_px / np.sqrt(3)))
    return {f"{STABILITY}.{k}": v for k, v in c.items()}


def bump_note(who: str, move: PPMove, p: float, model_as: str = "--camera") -> str:
    """The warning for a move the bows show (``p``: after the multiplicity correction)."""
    (dx, dy), (ux, uy) = move.shift_px, move.u_px
    return (f"{who}: the principal point differs from its calibration by ({dx:+.1f}, {dy:+.1f}) "
            f"± ({ux:.1f}, {uy:.1f}) px (the marks' bows, the rest of the lens as calibrated; "
            f"p = {p:.2g}): the lens moved on the camera since calibration (a knock, a "
            "re-seated or refocused lens)? The lens is taken as undetermined beyond the "
            "calibration, as without a model, and u carries it (camera_disagreement); "
            "recalibrate the camera (`align camera`)")


def moved_or_bent_note(who: str, move: PPMove, p: float, bent: Sequence[int], n: int,
                       told: MoveOrBent, declared: bool = False) -> str:
    """The warning for a move that one frame's marks cannot tell from bent marks
    (:func:`move_or_bent`'s ``"undecided"``; ``p`` after the multiplicity correction). With
    the stability not ``declared`` it says what decides: declaring it, or more marks."""
    (dx, dy), (ux, uy) = move.shift_px, move.u_px
    which = ", ".join(str(k) for k in bent)
    how = ("image more marks in this frame (straight ones far from the centre) or recalibrate "
           "the camera (`align camera`)" if declared else
           "to decide, declare the camera's principal-point stability (`--lens "
           "pp_stability_px=`, `[cameras.X] lens_pp_stability_px`; the default 0.5 px was "
           "not stated and decides nothing) or image more marks in this frame (straight ones "
           "far from the centre)")
    return (f"{who}: cannot tell whether the principal point moved since calibration by "
            f"({dx:+.1f}, {dy:+.1f}) ± ({ux:.1f}, {uy:.1f}) px (p = {p:.2g}; it explains every "
            f"mark's bow) or line(s) {which} of {n} are bent beside the kept calibration: the "
            f"other marks would show the move's bow {told.separation:.1f} sigma apart and "
            f"show {told.seen:+.2f} of it; neither reading is trusted: the calibration's "
            f"angles are given, each one's change under the move carried in u "
            f"(camera_moved_or_bent); {how}")
