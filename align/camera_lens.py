"""The lens of one camera as its marks meet it: the lens solved from the marks or taken from a
camera model (:mod:`align.lens`), what it adds to each mark's u (named terms, and their signed
components shared by the marks of one lens), and the largest bow it can still leave on each
mark (beyond which a bow is a bent mark, docs/camera.md)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.camera_model_u import model_coupling
from align.lens import LensRanges, LineGeometry, solve_lens
from align.lens_bump import (
    beyond_declared_note,
    bonferroni,
    bump_note,
    move_explains,
    move_or_bent,
    moved_or_bent_note,
    pp_move,
    stability_coupling,
    weigh_declared,
)
from align.lens_fallback import carried, lens_beyond_model, model_lever, still_departs
from align.lens_terms import (
    angle_coupling,
    bow_reach,
    camera_departure,
    check_camera,
    lens_bow,
    lens_or_bends,
    lone_departures,
    pp_cross_coupling,
)
from align.lens_terms import (
    undistorted as lens_undistorted,
)
from align.lens_wiggle import without_wiggle
from align.mark_stage import half_diagonal, noise_dof, texture_scale
from imaging import CameraModel, MarkMeasurement, fit_line, on_line, undistort_points
from imaging.lens import PARAMS


def lens_lines(ms: Sequence[MarkMeasurement], scales: Sequence[float] | None = None
               ) -> list[LineGeometry]:
    """The marks as the lens solver sees them (sigma with the texture's re-read scale;
    ``scales``: each mark's :func:`align.mark_stage.texture_scale`, when already read)."""
    scales = [texture_scale(m) for m in ms] if scales is None else scales
    return [LineGeometry(m.points, m.sigma * np.sqrt(ts), m.chol)
            for m, ts in zip(ms, scales, strict=True)]


def camera_lens_u(camera: CameraModel, shape: tuple[int, int]) -> np.ndarray:
    """A calibration's standard uncertainties (``align camera``'s ``u``) as the lens vector's
    (:data:`imaging.lens.PARAMS`: k1, k2, p at the half-diagonal, aspect, principal point)."""
    u = camera.u or {}
    R = half_diagonal(shape)
    fx, fy = float(camera.camera_matrix[0, 0]), float(camera.camera_matrix[1, 1])
    a = R / fx

    def g(k: str) -> float:
        v = float(u.get(k, 0.0))
        return v if np.isfinite(v) else 0.0

    # The aspect's own u when the calibration states it (fx, fy correlated); else fx's and
    # fy's as if independent (an upper bound).
    aspect = g("aspect") if "aspect" in u else np.hypot(g("fx") / fx, g("fy") / fy) * fy / fx
    return np.array([g("k1") * a**2, g("k2") * a**4, g("p1") * a, g("p2") * a,
                     aspect, g("cx"), g("cy")])


def camera_lens_vector(camera: CameraModel, shape: tuple[int, int]) -> np.ndarray:
    """The model's own distortion as the lens vector's k1, k2, p1, p2 (at the half-diagonal,
    as :func:`camera_lens_u`); aspect and principal point 0 (the model's are its own frame)."""
    d = np.zeros(4)
    c = np.ravel(camera.dist_coeffs)[:4]
    d[:c.size] = c
    a = half_diagonal(shape) / float(camera.camera_matrix[0, 0])
    return np.array([d[0] * a**2, d[1] * a**4, d[2] * a, d[3] * a, 0.0, 0.0, 0.0])


def camera_lens_cov(camera: CameraModel, shape: tuple[int, int]) -> np.ndarray | None:
    """A calibration's joint covariance (``cov``, :data:`imaging.camera_cov.INTRINSICS`)
    as the lens vector's (:data:`imaging.lens.PARAMS`, the units of :func:`camera_lens_u`):
    J C Jᵀ; None for a file without one (before format 4). k3's r⁶ is booked with k2's r⁴
    at the half-diagonal (the lens vector has no k3; k2 and k3 of one calibration are
    strongly anticorrelated, and their sum is what bows a mark there)."""
    if camera.cov is None:
        return None
    fx, fy = float(camera.camera_matrix[0, 0]), float(camera.camera_matrix[1, 1])
    a = half_diagonal(shape) / fx
    J = np.zeros((len(PARAMS), 9))
    J[0, 4], J[1, 5], J[1, 8], J[2, 6], J[3, 7] = a**2, a**4, a**6, a, a
    J[4, 0], J[4, 1] = -fy / fx**2, 1.0 / fx  # the aspect fy / fx
    J[5, 2] = J[6, 3] = 1.0
    C = J @ camera.cov @ J.T
    return 0.5 * (C + C.T)


MOVED_OR_BENT = "camera_moved_or_bent"
"""The u term of a principal point's move that one frame's marks cannot tell from bent marks
(:func:`align.lens_bump.move_or_bent`'s ``"undecided"``)."""

CAMERA_MODEL = "camera model"
"""The lens record's ``source`` when a camera model (``--camera``, ``[cameras.X] model``) is
the lens."""


@dataclass(frozen=True)
class CameraLens:
    """What the lens of one camera adds to each of its marks: the lens vector applied to the
    centres before the loop (None: nothing; a camera model already undistorted them), the
    named angle-u terms per mark [rad], the notes, the saved dict; ``coupling``: each
    mark's terms as signed components on the lens's error directions (shared by every mark
    of this lens, :func:`align.lens_terms.angle_coupling`).

    The terms are the coupling's sizes: a term is the root sum of squares of its components
    (``lens_fit.0``, ``lens_fit.1``, ... for a fitted lens's covariance, one each else)."""

    lam: np.ndarray | None
    notes: tuple[str, ...]
    record: Mapping
    max_u_rad: float
    coupling: tuple[dict[str, float], ...] = ()
    model_as: str = "--camera"
    """How the user gives this camera a model: the flag, or session.toml's key."""
    bow_px: tuple[float, ...] = ()
    """Per mark, the largest sagitta [px] the lens can still leave on it (what the lines
    leave undetermined, or the calibration's u): a larger bow is no lens
    (:func:`bow_bound`)."""
    unresolved: bool = False
    """The marks' departure from the camera's model fits neither a changed lens nor bent
    marks beside the calibrated one (:func:`align.lens_terms.lens_or_bends`): every angle of
    the camera is not ok."""

    @property
    def terms(self) -> tuple[dict[str, float], ...]:
        """Named standard uncertainties [rad] per mark (the coupling's sizes per term)."""
        return tuple(_term_sizes(c) for c in self.coupling)


def _term_sizes(coupling: Mapping[str, float]) -> dict[str, float]:
    """Root sum of squares per term name (``lens_fit.0`` and ``lens_fit.1`` are ``lens_fit``)."""
    out: dict[str, float] = {}
    for k, v in coupling.items():
        name = k.split(".")[0]
        out[name] = float(np.hypot(out.get(name, 0.0), v))
    return out


def camera_lens(ms: Sequence[MarkMeasurement], camera: CameraModel | None = None,
                ranges: LensRanges | None = None, alpha: float = 1e-3, label: str = ""
                ) -> CameraLens:
    """:func:`_camera_lens`; ``label`` names a session's camera (its messages then name
    session.toml's ``[cameras.LABEL] model``, not ``--camera``)."""
    lens = _camera_lens(ms, camera, ranges, alpha, label)
    return replace(lens, model_as=f"[cameras.{label}] model") if label else lens


def _camera_lens(ms: Sequence[MarkMeasurement], camera: CameraModel | None = None,
                 ranges: LensRanges | None = None, alpha: float = 1e-3, label: str = ""
                 ) -> CameraLens:
    """The lens of one camera from all its marks ``ms`` (one frame, or all its images).

    Without a camera model: identifiability, then the determined parameters fitted jointly
    and the rest carried in u (:func:`align.lens.solve_lens`). With one: the model *is* the
    lens (the centres are already undistorted by it); its u is propagated into every angle,
    nothing is fitted on top, and marks that disagree with it beyond their u are a warning
    naming the camera, the disagreement added to u.
    """
    ranges = ranges or LensRanges()
    max_u = ranges.max_u_arcsec * np.pi / 180 / 3600
    if not ms:
        return CameraLens(None, (), {}, max_u)
    shape = ms[0].image_shape
    R = half_diagonal(shape)
    # A wiggle of >= 2 periods along a mark is fitted first: the lens reads what is left.
    scales = [texture_scale(m) for m in ms]  # (two fits of a correlated mark's centres each)
    lines = [without_wiggle(ln, alpha, noise_dof(m, ts))[0]
             for ln, m, ts in zip(lens_lines(ms, scales), ms, scales, strict=True)]
    who = f"camera {label}" if label else "camera"
    if camera is None and not np.any(ranges.vector()):
        # Declared distortion-free: nothing to determine, nothing to carry.
        return CameraLens(None, (),
                          {"source": "declared distortion-free", "lines": len(ms),
                           "ranges": ranges.to_dict()}, max_u, tuple({} for _ in ms),
                          bow_px=tuple(0.0 for _ in ms))
    z = float(-special.ndtri(alpha / 2))
    if camera is None:
        sol, designs = solve_lens(lines, R, ranges, alpha)
        coupling = tuple({**angle_coupling(sol, d), **pp_cross_coupling(sol, d, R)}
                         for d in designs)
        notes = tuple(f"{who}: {n}" for n in sol.notes)
        # A line no lens of the others explains: no bow of it is the lens's.
        bows = bow_bound(lines, sol.lam, bow_reach(sol, z), R)
        bows = tuple(0.0 if k in sol.bent_lines else b for k, b in enumerate(bows))
        return CameraLens(sol.lam if np.any(sol.lam) else None, notes,
                          {"source": "marks", **sol.to_dict()}, max_u, coupling,
                          bow_px=bows)
    lam_cov = camera_lens_cov(camera, shape)
    # The marks are checked against the calibration's joint covariance where the file has
    # one (k1, k2, k3 of one calibration strongly anticorrelated: their u's as if
    # independent miss a departure along their well-determined combination).
    lam_u = (camera_lens_u(camera, shape) if lam_cov is None
             else np.sqrt(np.clip(np.diag(lam_cov), 0.0, None)))
    lam_chk = lam_u if lam_cov is None else lam_cov
    zero = np.zeros_like(lam_u)
    notes = []
    # The calibration's parameters jointly (k1, k2, k3 of one calibration are strongly
    # correlated: their terms added as if independent overstate the angle's u), at the
    # model's own distortion (a file without cov: its u's, align/camera_model_u.py).
    terms_l = [model_coupling(camera, ln.points, ln.sigma, ln.chol, shape) for ln in lines]
    if camera.cov is None:
        notes.append(f"{who}: its model holds no covariance of its parameters (a file "
                     "written elsewhere, or before camera format 4): their u's are taken as "
                     "independent (fx, fy tied by its aspect), which can misstate an angle's u "
                     "either way (0.3-3x on the real chessboard lens) and lets the principal "
                     "point's u turn marks far from the centre beyond the lens bound; re-run "
                     "`align camera` for the joint covariance, or add the calibration's `cov` "
                     "to the file")
    p, dlam, designs = check_camera(lines, zero, lam_chk, R, ranges, alpha)
    # The model's principal point as the check's lever (align/lens_fallback.py).
    designs = model_lever(designs, lines, camera, shape)
    p, dlam = camera_departure(designs, lam_chk, ranges, alpha)
    # The principal point moved alone (a bump: the lens re-seated on the sensor) is a
    # hypothesis of its own: 2 dof, where the lens change's test spreads its bows over up to
    # 7; the two tested together, Bonferroni (align/lens_bump.py).
    move = pp_move(designs, lam_chk, ranges.pp_stability_px)
    p_raw = p
    p, p_pp = bonferroni(p, move.p)
    unresolved = False
    told = lens_or_bends(designs, lam_chk, ranges, alpha) if p < alpha else None
    if told is None:
        lone = (lone_departures(designs, lam_chk, ranges, alpha,
                                camera_lens_vector(camera, shape)) if p < alpha else ())
    else:
        lone = told.departing if told.verdict == "bends" else ()
    if lone and still_departs(designs, lone, lam_chk, ranges, alpha):
        # The other marks depart together too: no bend explains that (align/lens_fallback.py).
        lone, told = (), None
    # A principal point's move that explains every mark's bow is the reading of a bump; bent
    # marks are then no better an explanation of the bows unless the other marks rule the
    # move out; where they rule out neither, both readings stand (align/lens_bump.py).
    mob = (move_or_bent(designs, move, alpha, lone)
           if len(ms) > 1 and p_pp < alpha and move_explains(designs, move, lam_chk, ranges,
                                                               alpha) else None)
    if mob is not None and lone:
        # The user's declared stability of the principal point (not the default) rules out a
        # move beyond it: the bent reading stands (docs/camera.md).
        mob = weigh_declared(mob, move, ranges, alpha)
    moved = mob is not None and mob.verdict == "move"
    if moved:
        lone, told = (), None
    if lone:
        # A departure no two marks agree on, or one the other marks do not show (a changed
        # lens bows every mark by what its position predicts; these stay straight), is the
        # bent marks' bows: the lens stays the calibrated one (nothing widened), and each
        # mark's own loop names its bend and reads it end to end (its bow is beyond what the
        # calibration leaves it).
        which = ", ".join(str(k) for k in lone)
        why = ("no other mark agrees on a change of the lens" if told is None else
               f"a lens change that made them would bow the other marks "
               f"{told.separation:.1f} sigma, and they show {told.seen:+.2f} of that")
        if mob is None or mob.verdict != "undecided":
            also = ("" if mob is None or not mob.beyond_declared else
                    beyond_declared_note(move, ranges.pp_stability_px))
            notes.append(f"{who}: the bow of line(s) {which} of {len(ms)} is not the "
                         f"calibrated lens's and {why}{also}: read as bent mark(s), the "
                         "calibration kept")
        p_used = 1.0
        dlam = np.zeros_like(dlam)
        if mob is not None and mob.verdict == "undecided":
            # The other marks tell neither reading apart: the calibration's angles are given
            # and each one's change under the move enters u as a Type B term (the truth
            # anywhere between, uniform: / sqrt 3), as lens_or_bends' 'undecided' does.
            notes.append(moved_or_bent_note(who, move, p_pp, lone, len(ms), mob,
                                            ranges.pp_stability_declared))
            for t, d in zip(terms_l, designs, strict=True):
                t[MOVED_OR_BENT] = float(d.s @ move.dlam()) / np.sqrt(3)
    else:
        p_used = p
    if moved or (len(ms) > 1 and p_used >= alpha and p_pp < alpha and not lone):
        # The bows show the principal point moved, the lens otherwise as calibrated: named,
        # and taken as a changed lens (below: undetermined beyond the calibration).
        notes.append(bump_note(who, move, p_pp))
        dlam, p_used = move.dlam(), min(p_pp, p_used)
        for t, d in zip(terms_l, designs, strict=True):
            t["camera_disagreement"] = float(d.s @ dlam)
    elif len(ms) == 1 and p < alpha and not lone:
        # One mark whose bow a plausible lens (the model's own plus a change) could make: a
        # bent mark and a model that misses the lens (a sign slip, a recalibrated lens) leave
        # it alike, and no other mark can tell them apart. Neither reading is the lens: u
        # carries the lens as undetermined beyond the calibration (below); when that is
        # beyond the lens bound the angle is lens-limited (not ok).
        what = ", ".join(f"{k} {v:+.3g}" for k, v in zip(PARAMS, dlam, strict=True) if v)
        notes.append(f"{who}: its one mark bows beyond what the calibrated lens leaves it "
                     f"(p = {p:.2g}): either the mark is bent or the lens differs from its "
                     f"calibration ({what} on top of it), and one mark cannot tell which; "
                     "neither reading is trusted: the lens is taken as undetermined beyond the "
                     "calibration, as without a model, and u carries it (camera_or_bent); image "
                     "more marks far from the centre or recalibrate the camera (`align camera`)")
        terms_l[0]["camera_or_bent"] = float(designs[0].s @ dlam) / np.sqrt(3)
    elif told is not None and told.verdict == "undecided":
        # The other marks cannot tell a changed lens from bent marks (too near the centre,
        # too short, too few to show the bow the change predicts for them): both readings
        # stand; the calibration's is given, and the difference of each mark's angle under
        # the two enters u as a Type B term (the truth anywhere between, uniform: /sqrt 3).
        which = ", ".join(str(k) for k in told.departing)
        what = ", ".join(f"{k} {v:+.3g}" for k, v in zip(PARAMS, told.dlam, strict=True)
                         if v)
        notes.append(f"{who}: cannot tell whether the lens differs from its calibration "
                     f"({what} on top of it) or line(s) {which} of {len(ms)} are bent: the "
                     f"other marks would show the change's bow only {told.separation:.1f} "
                     "sigma apart; neither reading is trusted: the lens is taken as "
                     "undetermined beyond the calibration, as without a model, and u carries it "
                     "(camera_or_bent); image straight marks far from the centre or recalibrate "
                     "the camera (`align camera`)")
        for t, d in zip(terms_l, designs, strict=True):
            t["camera_or_bent"] = float(d.s @ told.dlam) / np.sqrt(3)
        dlam, p_used = told.dlam, p
    elif told is not None and told.verdict == "neither":
        # No one changed lens predicts every mark from the others, and no straight mark
        # shows that the calibration holds: bent marks and a changed lens cannot be told
        # apart, and no u covers a reading that may be either: not ok.
        which = ", ".join(str(k) for k in told.departing)
        notes.append(f"{who}: NOT OK: the marks depart from the calibrated lens in a way no "
                     f"one lens change explains (line(s) {which} of {len(ms)} depart on their "
                     "own), and no straight mark shows that the calibration holds: a changed "
                     "lens and bent marks cannot be told apart; recalibrate the camera "
                     "(`align camera`) or image straight marks far from the centre")
        unresolved = True
        # u still widened by the change all the marks call for (as when they agree): the
        # angles are not ok, but a session's fusion should not take them as sharp.
        for t, d in zip(terms_l, designs, strict=True):
            t["camera_disagreement"] = float(d.s @ dlam)
    elif p_used < alpha and len(ms) > 1:
        also = ""
        if told is not None:
            # The change the agreeing marks call for (a departing mark that does not fit it
            # is bent on top of the changed lens: its loop reads it end to end).
            dlam = told.dlam
            if told.dropped:
                also = (f"; line(s) {', '.join(str(k) for k in told.dropped)} do not fit that "
                        "change either: bent marks")
        what = ", ".join(f"{k} {v:+.3g}" for k, v in zip(PARAMS, dlam, strict=True) if v)
        notes.append(f"{who}: the lens differs from its calibration (the marks' bows call for "
                     f"{what} on top of it, p = {p:.2g}){also}: neither the calibration nor "
                     "that change is trusted: the lens is taken as undetermined beyond the "
                     "calibration, as without a model, and u carries it (camera_disagreement); "
                     "recalibrate the camera (`align camera`)")
        for t, d in zip(terms_l, designs, strict=True):
            t["camera_disagreement"] = float(d.s @ dlam)
    lam, record = None, {"source": CAMERA_MODEL}
    if p_used >= alpha:
        # The model kept: its principal point may have moved since calibration within the
        # declared stability, which no bow may show (a Type B term, docs/camera.md).
        terms_l = [{**t, **stability_coupling(camera, ln, shape, ranges.pp_stability_px)}
                   for t, ln in zip(terms_l, lines, strict=True)]
    reach = z * lam_u + (np.abs(dlam) if p_used < alpha else 0.0)
    if p_used < alpha:
        # The marks show the lens is not its model: neither the model's reading nor the one
        # change their bows call for is trusted; the lens beyond the model is undetermined,
        # as without a model (align/lens_fallback.py): its u replaces the widening above.
        fb = lens_beyond_model(lines, R, ranges, alpha, camera, shape)
        terms_l = [carried(t, c) for t, c in zip(terms_l, fb.coupling, strict=True)]
        lam = fb.sol.lam if np.any(fb.sol.lam) else None
        reach = z * lam_u + bow_reach(fb.sol, z)
        record = {**fb.sol.to_dict(), "source": "marks", "camera_model": "departed from"}
    return CameraLens(lam, tuple(notes),
                      {**record, "p_marks_agree": p_raw, "pp_move": move.to_dict(),
                       "pp_stability_px": ranges.pp_stability_px,
                       "pp_stability_declared": ranges.pp_stability_declared,
                       "u_from": ("joint covariance" if camera.cov is not None else
                                  "parameters' u as if independent"),
                       "bent_lines": list(lone),
                       "pp_move_or_bent": None if mob is None else mob.to_dict(),
                       "lens_or_bent": None if told is None else told.verdict,
                       "u_lens_vector": lam_u.tolist()}, max_u, tuple(terms_l),
                      bow_px=bow_bound(lines, zero if lam is None else lam, reach, R),
                      unresolved=unresolved)


def bow_bound(lines: Sequence[LineGeometry], lam: np.ndarray, reach: np.ndarray, scale: float
              ) -> tuple[float, ...]:
    """Per line, the largest sagitta [px] a lens within ``reach`` of ``lam`` leaves on it
    (each parameter's bow at its reach, added in the worst case: a bow beyond this has no
    lens's shape at this line's position).

    The bows per unit are derivatives; a strong radial lens bends more than its derivative
    at ``lam`` says (the undistortion's next terms, ~30 % at k1 -0.17 near the corners), so
    they are also taken at the radial terms' reach either way, and the largest is used."""
    probes = [lam]
    for s1 in (-1, 1):
        for s2 in (-1, 1):
            p = lam.copy()
            p[:2] += np.array([s1, s2]) * reach[:2]
            probes.append(p)
    out = []
    for ln in lines:
        bows = np.array([lens_bow(ln, p, scale) for p in probes])
        bows = bows[np.all(np.isfinite(bows), axis=1)]  # a probe that folds says nothing
        worst = np.max(np.abs(bows), axis=0) if len(bows) else np.full(len(reach), np.inf)
        out.append(float(worst @ reach))
    return tuple(out)


def claimed_lens(lam: np.ndarray | None, record: Mapping | None) -> np.ndarray | None:
    """``lam`` without the parameters fitted free with the angles (their sign open,
    :func:`align.lens._marginalise`): the lens the record claims, through which positions
    (offsets, a family's middles) are read. A free parameter is the angles' estimator and
    carried in their u, not in the positions' (a lens-free 1280 x 1024 scene: a free k1 of
    0.024 +- 0.02 moved a mark's offset 10 px at +- 0.05 px)."""
    if lam is None or not record or record.get("source") != "marks":
        return lam
    par = record.get("parameters", {})
    return np.where([bool(par.get(p, {}).get("applied")) for p in PARAMS], lam, 0.0)


def undistorted_mark(m: MarkMeasurement, lam: np.ndarray) -> MarkMeasurement:
    """The mark with its centres (and their sigma, regressors, line and groove ends)
    undistorted by the lens vector ``lam``."""
    q, s = lens_undistorted(LineGeometry(m.points, m.sigma, m.chol), lam,
                            half_diagonal(m.image_shape))
    regs = dict(m.regressors, x=q[:, 0], y=q[:, 1], r2=(q**2).sum(1))
    line = fit_line(q, s, reject_sigma=None, chol=m.chol)
    ends = (None if m.ends_px is None else on_line(
        undistort_points(m.ends_px, lam, half_diagonal(m.image_shape)), line.angle_rad,
        line.offset_px))
    return replace(m, points=q, sigma=s, regressors=regs, ends_px=ends, line=line)


LENS_TERMS = ("lens_", "camera_")
