"""The calibration's orchestrator: which method the poses call for, the residual loop over
the ML stage (:mod:`align.calibration.model`), the known-pose cross-check, and the result.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from align.calibration.between import between_problem
from align.calibration.geometry import (
    HEMISPHERE_RAD,
    SURROUND_RAD,
    cone_estimate,
    cone_half_angle,
)
from align.calibration.known import (
    FIXTURE_ERROR_RAD,
    KnownPoseStage,
    cross_check,
    faces_of,
    fit_known,
    has_six_faces,
    labelled,
    recognise_directions,
    resolve_signs,
)
from align.calibration.model import (
    CANDIDATES,
    IN_TIME,
    OVERFIT_CHI2,
    PRIOR_ANGLE_RAD,
    PRIOR_BIAS_G,
    PRIOR_SCALE,
    CalibrationStage,
    admissible,
    walk_physical,
)
from align.calibration.nonlinearity import (
    UNEXCLUDED,
    bound_increment,
    declared_bounds,
    k3_separability,
    nonlinearity_statement,
    unexcluded_k3,
)
from align.calibration.plan import MIN_POSES as PLAN_MIN
from align.calibration.stability import (
    PPM,
    STABILITY,
    stability_gain,
    stability_reason,
    stability_statement,
)
from align.calibration.steps import step_problem
from align.calibration.triad import CORE, Poses, TriadModel, delta_g, per_axis, pose_gradient
from align.calibration.unproven import (
    PLAUSIBLE,
    plausible_effects,
    plausible_reason,
    plausible_term,
)
from align.calibration.walk import WANDER, walk_covariance, wander_fit
from align.calibration.wander import ScaleWander, corrected_poses, scale_wander, wander_reason
from align.calibration.widen import (
    ALIASED,
    AMBIGUITY,
    AMBIGUOUS_BIC,
    STRUCTURE,
    Alternative,
    Widening,
    ambiguity_reason,
    ambiguity_term,
    bound_cov,
    positive_part,
    structure_term,
    widen,
)
from align.errors import InputError, NotApplicable
from align.loop import Candidate, LoopReport, bic, optimistic_fit, run_loop
from axisbase.units import DEG

SCALE_FACTOR_DEFINITION = (
    "scale_factors_*: output per g along each sensitive axis, k_i |r_i(beta)|, u propagated "
    "from (k, beta); model.k_v_per_g is the model's K of u = K R(beta) (a + b), whose R has "
    "rows of length 1 + O(beta^2)")
"""What the reported scale factors are (in the JSON next to them)."""


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate`: algebraic start, final model, loop report.

    Attributes
    ----------
    algebraic : TriadModel
        The algebraic (closed-form) first estimate; unit — (its own fields carry units).
    model : TriadModel
        The refined model (maximum likelihood, the loop's effects); unit —.
    loop : LoopReport
        The residual loop's report (effects tried, added, refused, skipped); unit —.
    signs : tuple of float
        The scale factors' signs (+1 or -1 per axis) — dimensionless.
    noise_known : bool
        The poses carried their samples' scatter (else u from the residual); unit —.
    method : str
        ``ellipsoid`` or ``known-pose``; unit —.
    known : KnownPoseFit or None
        The known-pose fit, when the six faces were among the poses; unit —.
    cross_check : dict or None
        Ellipsoid vs known-pose per parameter: difference and its z — dimensionless.
    notes : tuple of str
        What the user should know (poses left out, units stretched); unit —.
    widening : Widening or None
        How u was widened for unexplained structure (None: not widened); unit —.
    problems : tuple of str
        Why the result is not ok (empty: ok); unit —.
    stability : dict or None
        What u assumes about the scale factors' wander over the run (``ppm`` [ppm] or None
        when assumed stable, ``assumed``, ``statement``:
        :func:`align.calibration.stability.stability_statement`); unit —.
    nonlinearity : dict or None
        The declared K2/K3 bounds, the terms carried in u, whether the poses separate K3
        from k (:func:`align.calibration.nonlinearity.nonlinearity_statement`); unit —.
    """

    algebraic: TriadModel
    model: TriadModel
    loop: LoopReport
    signs: tuple[float, float, float]
    noise_known: bool
    method: str = "ellipsoid"
    known: object = None
    cross_check: dict | None = None
    notes: tuple[str, ...] = ()
    widening: Widening | None = None
    problems: tuple[str, ...] = ()
    stability: dict | None = None
    nonlinearity: dict | None = None

    @property
    def ok(self) -> bool:
        """Whether the result is a measurement (``problems`` empty): not when the effects
        the poses cannot tell apart leave u far beyond the noise's
        (:meth:`~align.calibration.widen.Widening.undetermined`)."""
        return not self.problems

    @property
    def residual_rms_g(self) -> float:
        return self.loop.after.rms

    def effect_lines(self, unit: str = "") -> list[str]:
        """The loop's summary with every effect's components by axis (one line each)."""
        out = []
        for line in self.loop.summary_lines():
            out.append(line)
            if line.startswith("added "):
                e = next(x for x in self.loop.effects if line.startswith(f"added {x.name}:"))
                out += [f"    {e.name}_{ax}: {v:+.4g} ± {u:.2g} {e.unit}"
                        for ax, v, u in e.components]
        return out

    def to_dict(self, poses: Poses) -> dict:
        m, a = self.model, self.algebraic
        return {
            "scale_factors_v_per_g": m.sensitivity().tolist(), "beta_rad": m.beta.tolist(),
            "bias_g": m.bias.tolist(),
            "scale_factors_u_v_per_g": m.sensitivity_u().tolist(),
            "scale_factor_definition": SCALE_FACTOR_DEFINITION,
            "beta_u_rad": m.u_per_axis("beta").tolist(),
            "bias_u_g": m.u_per_axis("bias").tolist(),
            "scale_sign": list(self.signs), "residual_rms_g": self.residual_rms_g,
            "dof": self.loop.after.dof,
            "effects": [e.to_dict() for e in self.loop.effects],
            "unexplained_structure": self.loop.unexplained_structure,
            "noise_known": self.noise_known,
            "algebraic": {"scale_factors_v_per_g": a.sensitivity().tolist(),
                          "beta_rad": a.beta.tolist(), "bias_g": a.bias.tolist()},
            "poses": [{"pose": lab, "dg_g": float(d)} for lab, d in
                      zip(poses.labels, delta_g(m, poses), strict=True)],
            "model": m.to_dict(),
            "method": self.method,
            "refused_effects": [r.to_dict() for r in self.loop.refused],
            "known_pose": self.known.to_dict() if self.known is not None else None,
            "cross_check": self.cross_check,
            "u_widening": None if self.widening is None else self.widening.to_dict(),
            "scale_stability": self.stability,
            "nonlinearity": self.nonlinearity,
        }


def calibrate(poses: Poses, signs: Sequence[float] | None = None, alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES,
              fixture_error_rad: float | None = None,
              signs_as: str = "--scale-sign",
              scale_stability_ppm: float | None = None,
              stability_default: bool = False,
              nonlinearity_bound: tuple[float | None, float | None] | None = None
              ) -> Calibration:
    """Calibrate the triad from its poses.

    * Fewer than 9 poses, or poses that are all faces, with the six faces (labelled
      ``+x,-x,...`` or imucal's ``x_p,x_a,...``, or recognised from the means): the
      known-pose (six-position) fit alone.
    * 9 or more: algebraic ellipsoid fit, ML refinement, the residual loop over the effects
      (each guarded by :func:`admissible`); when the six faces are among the poses, the
      known-pose fit runs too and the two are cross-checked (``cross_check``, ``notes``).

    ``signs``: the scale factors' signs; None: from labelled faces when the poses carry
    them, else +,+,+ (an explicit one that contradicts the labels is refused:
    :func:`align.calibration.known.resolve_signs`). ``fixture_error_rad``: declared placement
    error of the faces (default :data:`align.calibration.known.FIXTURE_ERROR_RAD`).
    ``signs_as``: how the user gave ``signs`` (the flag, or session.toml's key), for the
    messages.

    Parameters
    ----------
    poses : Poses
        Mean output of each static pose (N, 3) [the triad's unit: V, g, m/s², counts],
        with times [s], temperatures, the standard error of each mean and labels (the
        faces' labels fix the signs).
    signs : sequence of float, optional
        The scale factors' signs (see above).
    alpha : float
        Significance level of the residual loop's tests.
    candidates : sequence of Candidate
        The effects the loop may add.
    fixture_error_rad : float, optional
        Declared placement error of the faces [rad].
    scale_stability_ppm : float, optional
        How stable the scale factors are over the run, ± [ppm] (checked by
        :func:`align.calibration.stability.stability_ppm`): u covers a wander of that size
        (:mod:`align.calibration.stability`, the ``scale_stability`` term); None or 0: no
        term. ``align calibrate`` and ``align run`` pass the user's declaration
        (:func:`align.calibration.stability.chosen_ppm`); a caller of the library states it
        here.
    stability_default : bool
        Nothing was declared and the poses carry no temperature column: the result states
        that the scale factors were assumed stable (``Calibration.stability``).
    nonlinearity_bound : (float or None, float or None), optional
        The datasheet's bounds on K2 [1/g] and K3 [1/g²] (:mod:`align.calibration.nonlinearity`):
        the loop refuses either beyond it, and one not added is carried in u (the
        ``nonlinearity_bound`` term). None: the physical priors, nothing carried.

    Returns
    -------
    Calibration
        The algebraic start and the final triad model (scale factors [unit/g], bias
        [unit], axes; their covariance), the loop's report and the notes.

    Raises
    ------
    InputError
        Too few usable poses, poses that do not determine the ellipsoid (a plane, a
        cone), signs that contradict the labelled faces.

    Examples
    --------
    The seed paper's 14-pose tumble of a synthetic triad (``synth.tumble``, with its truth;
    pose numbers carry no face labels, so the signs of k are given):

    >>> import numpy as np
    >>> from synth.tumble import TumbleSpec, tumble
    >>> from align import calibrate
    >>> from align.calibration import poses_from_samples
    >>> d = tumble(TumbleSpec(seed=1))
    >>> cal = calibrate(poses_from_samples(d.pose[d.pose < d.n_cal], d.u[d.pose < d.n_cal],
    ...                                    d.t[d.pose < d.n_cal]), signs=(-1, -1, -1))
    >>> k_true = np.array(d.spec.triad.k)
    >>> bool(np.all(np.abs(cal.model.k - k_true) < 4 * cal.model.sensitivity_u()))
    True
    """
    fe = FIXTURE_ERROR_RAD if fixture_error_rad is None else fixture_error_rad
    stated = stability_statement(scale_stability_ppm or 0.0, stability_default,
                                 poses.temp is not None)
    declared = declared_bounds(nonlinearity_bound)
    faces = faces_of(poses)
    signs = signs_t = resolve_signs(poses, faces, signs, signs_as)
    six = has_six_faces(faces)
    # Poses that are all faces (however many) span six directions: the ellipsoid's nine
    # parameters are not determined by them, the known-pose fit is.
    if len(poses.u) < 9 or (six and all(f is not None for f in faces)):
        if not six:
            raise InputError(f"only {len(poses.u)} usable poses; the ellipsoid needs at least 9 "
                             "(the paper's cube gives 14), or the six faces labelled "
                             "+x,-x,+y,-y,+z,-z for the known-pose (six-position) method")
        kf = fit_known(poses, faces, signs, fe)
        rep = run_loop(KnownPoseStage(kf, poses), ())
        model, widening, notes = kf.model, None, ()
        increments = []
        if rep.unexplained_structure and kf.dof > 0:
            # The same widening as the ellipsoid's: u covers the structure left.
            increments.append(_structure_increment(
                rep, kf.projection, kf.residuals_w, kf.dof, kf.noise_known, "pose-axis",
                bound=kf.dof < len(kf.model.names) + 3))
        increments += _stability_increment(kf.scale_gain, scale_stability_ppm,
                                           stability_default)
        # The faces cannot tell K3 from k (x³ = x at ±1 g) nor K2 from a bias.
        increments += bound_increment(kf.scale_gain, poses.u / kf.model.k, declared, ())
        if increments:
            model, widening = widen(kf.model, increments)
            notes = (widening.warning(),)
        return Calibration(kf.model, model, rep, signs_t, poses.sigma_u is not None,
                           "known-pose", kf, None, notes, widening,
                           step_problem(poses.steps, model.k, model.cov), stated,
                           nonlinearity_statement(declared, (), False))
    try:
        stage = CalibrationStage(poses, signs, bounds=declared)
    except InputError as exc:
        cone = cone_estimate(poses.u)
        if cone < SURROUND_RAD:  # the fit failed on poses clustered in a cone: say so
            raise InputError(f"geometry: the {len(poses.u)} poses span only a cone of "
                             f"~{cone / DEG:.0f}° about one direction ({exc}): {TUMBLE}") from None
        raise
    stage, rep = noise_model(stage, candidates, alpha)
    wander = None
    if stability_default and not scale_stability_ppm:  # what the poses' own slopes show
        wander = scale_wander(stage.poses, rep.after.payload, alpha)
        stated = {**stated, "wander": None if wander is None else wander.to_dict()}
        if wander is not None and wander.found:  # each pose back to the scale at t_ref
            poses = corrected_poses(poses, wander)  # (the known-pose cross-check's too)
            stage, rep = noise_model(CalibrationStage(poses, signs, bounds=declared),
                                     candidates, alpha)
    kf, cc, notes = None, None, _cone_notes(rep.after.payload, poses)
    model, widening = rep.after.payload, None
    increments = []
    if rep.unexplained_structure and rep.after.dof > 0:
        # Structure remains: u must cover it (widen), never the clean-data u.
        A, r_w = stage.projection[tuple(t.name for t in rep.terms)]
        increments.append(_structure_increment(rep, A, r_w, rep.after.dof,
                                               stage.sigma is not None, "pose"))
    alts = alternatives(stage, rep, candidates, admissible(stage, overfit=False))
    if alts:
        increments.append((AMBIGUITY, ambiguity_reason(
            tuple(t.name for t in rep.terms), alts, max(PLAN_MIN, len(poses.u))),
            ambiguity_term(alts, len(model.names))))
    names = tuple(t.name for t in rep.terms)
    bounded = bound_increment(_ellipsoid_gain(stage, rep), stage.poses.u / model.k,
                              declared, names)
    plaus = [(a, p) for a, p in plausible_effects(
        stage.fits, rep, candidates, admissible(stage, overfit=False),
        [a.effects for a in alts]) if not (bounded and a.effects.split(" + ")[-1] in declared)]
    if plaus:
        increments.append((PLAUSIBLE, plausible_reason(plaus, alpha),
                           plausible_term(plaus, len(model.names))))
        alts = [*alts, *(a for a, _ in plaus)]
    try:
        weak, unmeasured = unexcluded_k3(stage, rep, candidates, admissible(
            stage, overfit=False), [a.effects.split(" + ")[-1] for a, _ in plaus]), None
    except NotApplicable as exc:  # (the loop's screen had not fitted it: not separable)
        weak, unmeasured = None, str(exc)
    if weak is not None and weak.carried:  # nothing bounds the K3 the poses barely see
        increments.append((UNEXCLUDED, weak.reason(), weak.term(len(model.names))))
    increments += bounded  # (a declared term BIC prefers is carried at its bound above)
    if scale_stability_ppm:
        increments += _stability_increment(_ellipsoid_gain(stage, rep), scale_stability_ppm,
                                           stability_default)
    elif wander is not None:
        stated = _data_statement(wander, stated)
        if wander.found:
            gain = _ellipsoid_gain(stage, rep)
            increments.append((STABILITY, stated["statement"], gain @ wander.cov @ gain.T))
    problems: tuple[str, ...] = ()
    if increments:
        model, widening = widen(model, increments, alts)
        if any(t != UNEXCLUDED for t, _, _ in increments):  # (K3 not excluded alone: the
            notes = (*notes, widening.warning())  # design's, stated under the table)
        why = widening.undetermined(tuple(t.name for t in rep.terms),
                                    max(PLAN_MIN, len(poses.u)), WANDER)
        problems = (why,) if why else ()
    problems = (*problems, *step_problem(poses.steps, model.k, model.cov),
                *between_problem(stage, rep))
    if not labelled(poses):
        # Unlabelled: only poses the ellipsoid puts within 2° of an axis are faces here.
        a = rep.after.payload.specific_force(poses.u, poses.t, poses.temp)
        faces = recognise_directions(a)
    if has_six_faces(faces):
        kf = fit_known(poses, faces, signs, fe)
        cc, w = cross_check(rep.after.payload, kf.model)
        notes = (*notes, *w)
    separable, why_not = k3_separability(candidates, rep, unmeasured)
    return Calibration(stage.start, model, rep, signs_t, stage.sigma is not None,
                       "ellipsoid", kf, cc, notes, widening, problems, stated,
                       nonlinearity_statement(declared, names, separable, why_not, weak))


def noise_model(stage: CalibrationStage, candidates: Sequence[Candidate], alpha: float
                ) -> tuple[CalibrationStage, LoopReport]:
    """The loop under the noise model the pose means support. When the samples' bias walk
    entered the stage's noise (:class:`~align.calibration.model.CalibrationStage`), the loop
    runs again under white noise, and the walk is kept only when the pose means beyond the
    effects that loop found still show it: a walk of fitted level in their residual
    (:func:`~align.calibration.walk.wander_fit`, its shape the samples' walk) lowers
    −2 log L by more than ln N (one parameter in BIC). The samples' low frequencies within
    a pose (seconds) do not say how the bias goes on from pose to pose (minutes): a flicker
    floor or a settling looks like a walk there, and a warming bias under a walk's covariance
    is explained by the walk and not found (the BMI160 of openaxes-imu9 read by ``align
    calibrate``: cross_z_xz under the walk; bias_warmup + K2 under white noise leave
    chi2 18.9 on 21 dof, and the walk's fitted level in that residual is 0)."""
    rep = run_loop(stage, candidates, alpha=alpha, admissible=admissible(stage))
    if stage.walk is None:
        return stage, rep
    white = CalibrationStage(stage.poses, np.sign(stage.start.k), walk=False,
                             bounds=stage.bounds)
    rep_w = run_loop(white, candidates, alpha=alpha, admissible=admissible(white))
    effects = tuple(t.name for t in rep_w.terms)
    w = 1.0 / white.sigma
    shape = w[:, None] * stage.walk[0] * w[None, :]
    r, J = white.projection[effects][1], white.jacobians[effects]
    if rep_w.after.dof < MIN_WALK_DOF or rep_w.after.chi2 < OVERFIT_CHI2 * rep_w.after.dof:
        return stage, rep  # too little residual beyond the effects to exclude the walk
    gain = wander_fit(r, J, shape, 0.0).m2ll - wander_fit(r, J, shape).m2ll
    if gain > np.log(len(stage.poses.u)):
        return stage, rep
    return white, rep_w


MIN_WALK_DOF = 3
"""Fewest residual degrees of freedom beyond the white loop's effects on which the means may
exclude the samples' walk (:func:`noise_model`); fewer, or a residual an over-fit's size
(chi2/dof below :data:`~align.calibration.model.OVERFIT_CHI2`: 6 effect parameters on 14
poses took a walk's whole signal), and the walk stays."""


def _structure_increment(rep: LoopReport, projection: np.ndarray, residuals_w: np.ndarray,
                         dof: int, noise_known: bool, per: str, bound: bool = False
                         ) -> tuple[str, str, np.ndarray]:
    """The widening for the structure the loop left (:func:`structure_term`): (term, why,
    covariance); ``per``: what one residual is ("pose", "pose-axis")."""
    name, p, _ = rep.structure_evidence
    cov, m = structure_term(projection, residuals_w, dof, noise_known, bound)
    size = (f"{m:.3g} sigma" if noise_known else
            f"{m * 1e6:.3g} µg" if per == "pose" else f"{m:.3g} (output unit)")
    return (STRUCTURE, f"unexplained structure ({name} p = {p:.2g}): a systematic "
            f"error of {size} per {per}", cov)


def _ellipsoid_gain(stage: CalibrationStage, rep: LoopReport) -> np.ndarray:
    """G of :mod:`align.calibration.stability` for the loop's final fit."""
    A, _ = stage.projection[tuple(t.name for t in rep.terms)]
    n = len(stage.poses.u)
    W = (stage.whiten if stage.whiten is not None else
         np.diag(1.0 / stage.sigma) if stage.sigma is not None else np.eye(n))
    m = rep.after.payload
    return stability_gain(A, W, pose_gradient(m, stage.poses), stage.poses.u)


def _stability_increment(gain: np.ndarray | None, ppm: float | None, default: bool
                         ) -> list[tuple[str, str, np.ndarray]]:
    """The ``scale_stability`` term (none for a stability of 0 or None)."""
    if gain is None or not ppm:
        return []
    return [(STABILITY, stability_reason(ppm, default), bound_cov(gain, ppm * PPM))]


def _data_statement(w: ScaleWander, stated: dict) -> dict:
    """The ``scale_stability`` record when the poses' slopes were asked
    (:mod:`align.calibration.wander`): the wander found and corrected, or none seen beside
    the stated assumption."""
    if w.found:
        return {**stated, "ppm": None, "assumed": False, "statement": wander_reason(w)}
    return {**stated, "statement": stated["statement"]
            + f"; the poses' slopes show no scale wander (p = {w.p:.2g})"}


TUMBLE = "tumble the unit over all directions (the six faces and the eight corners of a cube)"


def _cone_notes(m: TriadModel, poses: Poses) -> tuple[str, ...]:
    """Poses within one hemisphere: a warning with the cone and the largest uncertainties;
    an :class:`InputError` (geometry) when a parameter is not determined by them — its
    3u covers the physical range the loop's guard allows (:data:`PRIOR_SCALE`,
    :data:`PRIOR_ANGLE_RAD`, :data:`PRIOR_BIAS_G`): the data then say nothing about it
    beyond what any triad is, and the linear uncertainty itself no longer holds."""
    cone = cone_half_angle(m.specific_force(poses.u, poses.t, poses.temp))
    if cone >= HEMISPHERE_RAD:
        return ()
    rel = {f"k_{ax}": (v / abs(k), PRIOR_SCALE, f"{v / abs(k):.2%}") for ax, v, k in
           zip("xyz", m.sensitivity_u(), m.sensitivity(), strict=True)}
    ang = {n: (m.u_of(n), PRIOR_ANGLE_RAD, f"{m.u_of(n):.3g} rad") for n in per_axis("beta")}
    bias = {n: (m.u_of(n), PRIOR_BIAS_G, f"{m.u_of(n):.3g} g") for n in per_axis("bias")}
    q = {**rel, **ang, **bias}
    bad = [n for n, (u, prior, _) in q.items() if not (3 * u < prior)]
    where = (f"geometry: the {len(poses.u)} poses span only a cone of ~{cone / DEG:.0f}° about one "
             "direction (no axis seen both up and down)")
    if bad:
        raise InputError(f"{where}: {', '.join(bad)} not determined by them (u "
                         + ", ".join(q[n][2] for n in bad) + f": 3u beyond the physical range "
                         f"{PRIOR_SCALE:.0%}, {PRIOR_ANGLE_RAD} rad, {PRIOR_BIAS_G} g): "
                         f"{TUMBLE}")
    worst_k = max(rel, key=lambda n: rel[n][0])
    worst_b = max(bias, key=lambda n: bias[n][0])
    return (f"calibration: {where}: its uncertainties are large for it (u({worst_k}) "
            f"{rel[worst_k][2]}, u({worst_b}) {bias[worst_b][2]}); {TUMBLE}",)




def alternatives(stage: CalibrationStage, rep: LoopReport, candidates: Sequence[Candidate],
                 guard) -> list[Alternative]:
    """Sets of effects the data cannot tell from the loop's (:mod:`align.calibration.widen`):
    each effect added replaced by each other candidate, and every other fit the loop tried;
    those the physical guard admits that are within :data:`AMBIGUOUS_BIC` of the final fit or,
    for a replacement, aliased with the effect it replaces (:data:`ALIASED`)."""
    final = rep.after
    names = tuple(t.name for t in rep.terms)
    if not names and not scatter_exceeds(rep):
        return []  # no effect added, the means scatter as the noise: the declared model
    b_final = bic(final, sum(t.searched for t in rep.terms))
    core, cov = _core(final.payload), _core_cov(final.payload)
    explained: dict[tuple[str, ...], tuple[str, float]] = {}
    for k, chosen in enumerate(rep.terms):
        rest = [*rep.terms[:k], *rep.terms[k + 1:]]
        base = stage.fits.get(tuple(t.name for t in rest), (None,))[0] or stage.fit(rest)
        drop = base.chi2 - final.chi2
        predicted = stage.screen(base, rest, [c.name for c in candidates])
        for cand in candidates:
            alt = cand.build(base) if cand.name not in names else None
            if alt is None:
                continue
            if cand.name in predicted:
                # Refit only what might be plausible (the loop's screen, its margin).
                opt = optimistic_fit(base, predicted[cand.name], alt.width)
                if not (bic(opt, sum(t.searched for t in [*rest, alt])) - b_final
                        < AMBIGUOUS_BIC or drop > 0 and (base.chi2 - opt.chi2) / drop
                        >= ALIASED):
                    continue
            try:
                fit = stage.fit([*rest[:k], alt, *rest[k:]])
            except (np.linalg.LinAlgError, NotApplicable):
                continue  # not applicable to these poses (as in the loop)
            explained[tuple(t.name for t in [*rest[:k], alt, *rest[k:]])] = (
                chosen.name, (base.chi2 - fit.chi2) / drop if drop > 0 else float("nan"))
    out = []
    for effects, (fit, terms) in stage.fits.items():
        if not terms or set(names) <= set(effects):
            # The no-effect fit, or the final set itself or one extended by an effect the
            # tests did not call for.
            continue
        d_bic = bic(fit, sum(t.searched for t in terms)) - b_final
        replaces, frac = explained.get(effects, ("", float("nan")))
        if not (d_bic < AMBIGUOUS_BIC or frac >= ALIASED):
            continue
        base = stage.fits.get(effects[:-1], (rep.before,))[0]
        if guard(base, fit, terms[-1]) is None:
            out.append(Alternative(" + ".join(effects), replaces, float(d_bic), float(frac),
                                   _core(fit.payload) - core,
                                   positive_part(_core_cov(fit.payload) - cov)))
    # No effect but a bias wandering between the poses (a bias instability every triad has),
    # its level fitted (one parameter in BIC), weighed against every effect added (on 14
    # poses, each attitude held once, an attitude effect is a function of time too: synth
    # walk 1e-6 g/√s, seed 109, took cross_z_xy, k_x 10.2 u off) and, no effect added,
    # against white noise when the chi2 alone exceeds its 1 - alpha quantile (user5's walk
    # of 1e-7 g a sample: chi2 24.8 on 5 dof, p 1.5e-4, below the structure tests' Bonferroni
    # level; k_z 4.6 u off): plausible within AMBIGUOUS_BIC, or when the samples within the
    # poses do not exclude the level it needs (the poses' means alone cannot tell a wander
    # of a few µg from a drift on 14 poses).
    w = stage.wander()
    if w is not None and w.level > 0:
        d_bic = w.m2ll + (len(CORE) + 1) * np.log(len(stage.poses.u)) - b_final
        bound = stage.poses.walk_bound
        top = (float(np.max(bound / stage.start.k**2)) if bound is not None and
               walk_physical(bound / stage.start.k**2, stage.poses.t) else 0.0)
        if top > 0 and stage.sigma is not None and stage.whiten is None:
            # ... and the pose means allow (a settling within the poses is not a walk).
            p = stage.poses
            top *= stage.means_allow(walk_covariance(
                np.full(3, top) * stage.start.k**2, pose_gradient(stage.start, p), p.t),
                names)
        if w.level <= top:
            # u covers the wander at the largest level the samples allow.
            w = stage.wander(top)
        # Within AMBIGUOUS_BIC counts only beside an effect in time (a wander's shape); an
        # attitude effect (K2 on 24 poses) or no effect, only at a level the samples allow.
        timed = {e for a in out for e in a.effects.split(" + ")} | set(names)
        if d_bic < AMBIGUOUS_BIC and timed & IN_TIME or w.level == top:
            theta = stage.solutions[()][:9] + w.step[:9]
            out.append(Alternative(WANDER, " + ".join(names), float(d_bic), float("nan"),
                                   theta - core, positive_part(w.cov[:9, :9] - cov)))
    return out


def scatter_exceeds(rep: LoopReport) -> bool:
    """Whether the final fit's chi2 alone is beyond its (1 - alpha) quantile (the loop's
    structure set judges it with the other tests, Bonferroni over all)."""
    s = rep.structure_after
    return any(t.name == "chi2" and t.p_value < s.alpha for t in s.tests)


def _core(m: TriadModel) -> np.ndarray:
    return np.concatenate([m.k, m.beta, m.bias])


def _core_cov(m: TriadModel) -> np.ndarray:
    """The covariance of (k, beta, bias) (the model's first nine names)."""
    return np.asarray(m.cov, float)[:9, :9]

