"""The residual loop: fit, test the residual, add the effect the data call for, repeat, report.

A *stage* (a line fit along a mark, face angles over revolutions, an ellipsoid over poses, the
fusion) implements ``fit(terms) -> StageFit``: it fits its declared model plus the given extra
terms and returns residuals, their standard uncertainties (or None when unknown), regressors
and the quantities of interest. *Candidates* build a :class:`Term` (design columns with a name,
unit and physical meaning) from the current fit. The loop scores each candidate by refitting,
adds the best one only if an F-test (corrected for searched parameters, and Holm over the
candidates a round tests) and BIC both call for it; when no candidate passes alone it tries
sets of them on different instruments together (:func:`_joint`: two real effects can each
leave the other's excess in the residual the test scales by), and stops when nothing more
is significant. Structure that remains is reported, never hidden.

A candidate that does not apply to the data (its builder returns None or raises
:class:`~axisbase.errors.NotApplicable`, or its refit does) or whose refit is singular
(``numpy.linalg.LinAlgError``) is skipped, and the report says which and why
(``LoopReport.skipped``). Anything else a candidate raises is a defect and propagates.
With ``-v`` (the ``align`` logger at DEBUG) the loop logs every candidate it tries, with its
p-value and ΔBIC, and what it decided.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from scipy import special  # (not scipy.stats: 1 s to import; the same functions)

from align.loop.fit import Candidate, Stage, StageFit, Term
from align.loop.report import (
    EffectReport,
    LoopReport,
    RefusedEffect,
    SkippedCandidate,
)
from align.loop.structure import StructureReport, check_structure
from axisbase.errors import NotApplicable

log = logging.getLogger("align.loop")


def bic(fit: StageFit, extra_k: int = 0) -> float:
    """BIC: chi2 + k ln N with known sigma; N ln(RSS/N) + k ln N otherwise (lmfit's form)."""
    k = fit.n_params + extra_k
    if fit.sigma is None:
        return fit.n * np.log(max(fit.chi2, 1e-300) / fit.n) + k * np.log(fit.n)
    return fit.chi2 + k * np.log(fit.n)


def f_test(base: StageFit, ext: StageFit, m: int) -> float:
    """p-value of the extra m parameters (nested models).

    With known sigma: the likelihood-ratio test, delta chi2 ~ chi2(m), with delta chi2
    divided by the extended fit's chi2/dof when that exceeds 1 (so an understated sigma does
    not manufacture effects). With unknown sigma: the F-test.
    """
    if ext.dof < 0 or m <= 0:
        return 1.0
    drop = base.chi2 - ext.chi2
    if drop <= 0:
        return 1.0
    if base.sigma is not None:
        excess = max(1.0, ext.chi2 / ext.dof) if ext.dof > 0 else 1.0
        if ext.noise_dof is not None and np.isfinite(ext.noise_dof):
            # The weights come from a covariance estimated on noise_dof degrees of freedom:
            # the extra terms' quadratic form is Hotelling's T^2, i.e. F(m, nu) for the
            # statistic drop / m (nu large: chi2(m) / m again).
            return float(special.fdtrc(m, ext.noise_dof, drop / excess / m))
        return float(special.chdtrc(m, drop / excess))
    if ext.dof == 0:
        return 1.0
    return float(special.fdtrc(m, ext.dof, (drop / m) / max(ext.chi2 / ext.dof, 1e-300)))


def structure_of(fit: StageFit, alpha: float) -> StructureReport:
    return check_structure(fit.residuals, fit.sigma, fit.regressors[fit.order],
                          fit.regressors, fit.dof, alpha, fit.noise_dof, fit.sequence)


SCREEN_MARGIN = 3.0
"""A stage may predict each candidate's chi2 drop by a linearised (score) test before its
refit (``stage.screen(current, terms, names)``: name -> predicted chi2); the loop refits only
candidates that would pass with SCREEN_MARGIN times the predicted drop plus
:data:`SCREEN_SLACK` — a screen that cannot turn away an effect the refit would take (the
refit's drop differs from the linear one by the effect's curvature, percent for the
calibration's effects: ``tests/align/test_calibration_speed.py`` checks the loop's choices
with and without it)."""
SCREEN_SLACK = 4.0


def optimistic_fit(current: StageFit, chi2_pred: float, extra_params: int) -> StageFit:
    """A stand-in for the refit of ``current`` with ``extra_params`` more parameters whose
    linearised chi2 is ``chi2_pred``: its drop made SCREEN_MARGIN times larger plus
    SCREEN_SLACK (the residuals scaled to that chi2), for the tests a screen applies."""
    drop = SCREEN_MARGIN * max(current.chi2 - chi2_pred, 0.0) + SCREEN_SLACK
    chi2 = max(current.chi2 - drop, 1e-12 * max(current.chi2, 1e-300))
    return replace(current, residuals=current.residuals * np.sqrt(chi2 / current.chi2)
                   if current.chi2 > 0 else current.residuals,
                   n_params=current.n_params + extra_params)


def sidak(p: float, trials: float) -> float:
    """The p-value of the smallest of ``trials`` independent tests: 1 - (1 - p)^trials
    (Sidak's look-elsewhere / family correction; ~ trials * p for small p)."""
    return float(-np.expm1(trials * np.log1p(-min(p, 1 - 1e-16))))


def _may_pass(current: StageFit, chi2_pred: float, term: Term, searched: int, alpha: float,
              min_delta_bic: float) -> bool:
    """Whether a candidate predicted to leave ``chi2_pred`` could pass the loop's tests
    (with the screen's margin): a stand-in fit with the predicted chi2 goes through the
    same BIC and F-test."""
    trial = optimistic_fit(current, chi2_pred, term.width)
    d_bic = bic(trial, searched + term.searched) - bic(current, searched)
    p = f_test(current, trial, term.width)
    return sidak(p, term.trials) < alpha and d_bic < -min_delta_bic


def run_loop(stage: Stage, candidates: Sequence[Candidate], alpha: float = 1e-3,
             min_delta_bic: float = 6.0, max_effects: int = 4,
             admissible: Callable[[StageFit, StageFit, Term], str | None] | None = None,
             retest_refused: bool = False) -> LoopReport:
    """Run the residual loop over ``stage`` with ``candidates``.

    An effect is added when its F-test p-value, corrected for the look-elsewhere search of
    its term (``Term.trials``) and for the number of candidates the round tests (Holm's
    step-down in Sidak's form: a round of m candidates tests each at 1 - (1 - alpha)^(1/m),
    the next round at m - 1), is below ``alpha`` and it lowers BIC by at least
    ``min_delta_bic``; the best such effect is added first. ``alpha`` is then the chance that
    a round adds an effect to data that have none, whatever the number of candidates. A
    round where none passes alone adds the smallest set of candidates on different
    instruments that passes together (:func:`_joint`; at most 2 ``alpha`` a round on clean
    data, the two families').
    ``admissible(current, trial, term)`` may refuse a significant effect (returns the reason,
    else None): the refusal is reported in ``LoopReport.refused``, never silent. A candidate
    that does not apply or whose refit is singular is reported in ``LoopReport.skipped``.

    Parameters
    ----------
    stage : Stage
        Fits its observations with a list of terms (``stage.fit(terms) -> StageFit``).
    candidates : sequence of Candidate
        The effects that may be added.
    alpha : float
        Significance level of the effect and structure tests.
    min_delta_bic : float
        Least drop of BIC an effect must bring.
    max_effects : int
        Most effects added.
    admissible : callable, optional
        ``admissible(current, trial, term) -> str | None``: a reason to refuse a
        significant effect (a physical prior), else None.
    retest_refused : bool
        A refused candidate that a later round (after an admissible effect was added) finds
        no longer significant is dropped from ``refused``: the effect added explains what it
        absorbed. For a stage that carries the candidates it did not add in u (the fusion:
        :mod:`align.fusion.plausible`); elsewhere a refusal stands.

    Returns
    -------
    LoopReport
        Before/after fits, the effects added, refused and skipped.
    """
    refused: dict[str, RefusedEffect] = {}
    skipped: dict[str, SkippedCandidate] = {}
    terms: list[Term] = []
    start = time.perf_counter()
    current = stage.fit(terms)
    before = current
    s_before = structure_of(current, alpha)
    log.debug("loop %s: declared model: N %d, RMS %.4g, chi2/dof %s; structure %s",
              type(stage).__name__, current.n, current.rms, _chi2_dof(current),
              _structure_note(s_before))
    effects: list[EffectReport] = []
    searched = 0
    screen = getattr(stage, "screen", None)
    while len(effects) < max_effects:
        best = None
        predicted = screen(current, terms, [c.name for c in candidates]) if screen else {}
        tried = []
        tested = 0  # hypotheses this round: tried, or turned away by the screen
        for cand in candidates:
            if any(t.name == cand.name for t in terms):
                continue
            if cand.name in predicted:
                term = cand.build(current)
                if term is not None and not _may_pass(current, predicted[cand.name], term,
                                                      searched, alpha, min_delta_bic):
                    log.debug("loop   candidate %s: screened out (linearised chi2 %.4g from "
                              "%.4g)", cand.name, predicted[cand.name], current.chi2)
                    tested += 1
                    if retest_refused:  # explained by the effects added since
                        refused.pop(cand.name, None)
                    continue
            trial, term = _try(stage, cand, current, terms, skipped)
            if trial is None:
                continue
            tested += 1
            skipped.pop(cand.name, None)  # tried now: not skipped after all
            d_bic = (bic(trial, searched + term.searched)
                     - bic(current, searched))
            p = f_test(current, trial, term.width)
            tried.append((cand, term, trial, sidak(p, term.trials), float(d_bic)))
        lead = None  # the best admissible candidate by its own test (refusals' order)
        refusal = False  # a significant candidate refused this round
        for cand, term, trial, p_term, d_bic in tried:
            # Holm over the candidates: the round adds the best of `tested` hypotheses, so
            # each is tested at the family's level (Sidak's exact form of alpha / tested);
            # later rounds test fewer (the step-down). Without it a round of m candidates
            # adds a false effect m times as often as alpha says.
            p_adj = sidak(p_term, tested)
            log.debug("loop   candidate %s: p %.3g (look-elsewhere corrected, %g trials; "
                      "Holm over %d candidates), dBIC %+.1f (needs p < %g and dBIC < %+.1f)",
                      cand.name, p_adj, term.trials, tested, d_bic, alpha, -min_delta_bic)
            if p_term >= alpha or d_bic >= -min_delta_bic:
                if retest_refused:  # explained by the effects added since: no structure left
                    refused.pop(cand.name, None)
                continue
            # A significant effect outside its physical prior is refused and reported as
            # structure the model lacks: a test on the residual, at the level of each
            # candidate's own test and in the order the candidates lead (as before the count
            # of candidates entered), so that a refusal is not lost to the correction that
            # guards against adding effects (a clipped pose's scale_warmup, user6).
            why = admissible(current, trial, term) if admissible is not None else None
            if why is not None:
                refusal = True
                if lead is None or d_bic < lead:
                    log.debug("loop   candidate %s: significant but refused: %s", cand.name,
                              why)
                    refused[cand.name] = RefusedEffect(cand.name, why, p_term, float(d_bic))
                continue
            lead = d_bic if lead is None else min(lead, d_bic)
            if p_adj < alpha and (best is None or d_bic < best[0]):
                best = (d_bic, p_adj, term, trial, cand)
        if best is None:
            # Sets only where nothing significant was refused: a set must not stand in for
            # a refused effect (a clipped pose's scale_warmup, refused, was absorbed by
            # bias_drift + cross_z_xz in 14 poses: tests/align/test_calibration_speed.py).
            joint = None if refusal else _joint(
                stage, current, terms, tried, tested, searched, alpha, min_delta_bic,
                admissible, max_effects - len(effects))
            if joint is None:
                log.debug("loop %s: no candidate significant: stop", type(stage).__name__)
                break
            members, trial, p_adj, d_bic = joint
            log.debug("loop %s: added %s jointly (p %.3g, dBIC %+.1f)", type(stage).__name__,
                      " + ".join(c.name for c, _ in members), p_adj, d_bic)
            for cand, term in members:
                est, u = trial.effects.get(term.name, (float("nan"), float("nan")))
                effects.append(EffectReport(term.name, est, u, term.unit, current.rms,
                                            trial.rms, d_bic, p_adj, cand.description))
                terms.append(term)
                searched += term.searched
            current = trial
            continue
        d_bic, p_adj, term, trial, cand = best
        log.debug("loop %s: added %s (p %.3g, dBIC %+.1f)", type(stage).__name__, cand.name,
                  p_adj, d_bic)
        est, u = trial.effects.get(term.name, (float("nan"), float("nan")))
        effects.append(EffectReport(term.name, est, u, term.unit, current.rms, trial.rms,
                                    float(d_bic), p_adj, cand.description))
        terms.append(term)
        searched += term.searched
        current = trial
    # Re-read the estimates from the final fit (later terms can shift earlier ones).
    effects = [EffectReport(e.name, *current.effects.get(e.name, (e.estimate, e.u)), e.unit,
                            e.rms_before, e.rms_after, e.delta_bic, e.p_value, e.description,
                            tuple(current.components.get(e.name, ())))
               for e in effects]
    # (no effect added: the final fit is the first, and so is its structure)
    s_after = s_before if current is before else structure_of(current, alpha)
    log.debug("loop %s: final model: RMS %.4g, chi2/dof %s; structure %s; %.3f s",
              type(stage).__name__, current.rms, _chi2_dof(current), _structure_note(s_after),
              time.perf_counter() - start)
    added = {t.name for t in terms}
    return LoopReport(tuple(effects), before, current, s_before, s_after, tuple(terms),
                      tuple(r for n, r in refused.items() if n not in added),
                      tuple(s for n, s in skipped.items() if n not in added))


JOINT_MOST = 5
"""Most candidates the joint step (:func:`_joint`) combines: the ones that lower BIC most."""


def _joint(stage: Stage, current: StageFit, terms: Sequence[Term],
           tried: Sequence[tuple[Candidate, Term, StageFit, float, float]], tested: int,
           searched: int, alpha: float, min_delta_bic: float,
           admissible: Callable[[StageFit, StageFit, Term], str | None] | None, room: int
           ) -> tuple[tuple[tuple[Candidate, Term], ...], StageFit, float, float] | None:
    """The smallest set of candidates that together pass the loop's tests when none does
    alone, or None.

    With known sigma the loop's test divides each candidate's chi2 drop by the chi2/dof its
    refit leaves (an understated sigma must not manufacture effects); with two real effects
    the one not yet fitted leaves that excess large, and neither passes alone (two cameras
    rolled 24″: p 0.32 and 0.05 though each lowers BIC by 72 and 121 and is 9-11 sigma).
    Sets of 2, 3, ... of the round's candidates that each lower BIC by ``min_delta_bic``
    alone, are admissible and act on different instruments (:func:`instrument`: at most one
    member per instrument) are then refitted together. A set is added when its joint fit
    leaves no structure (the excess that held its members back is theirs), its joint
    test, corrected for look-elsewhere (the product of its terms' trials) and for the
    number of sets of its size and smaller the round's ``tested`` candidates form (Sidak),
    is below ``alpha``, it lowers BIC by ``min_delta_bic``, and each member, against the set
    without it, is significant at ``alpha`` and lowers BIC by ``min_delta_bic`` (no
    passenger rides on the others) and is admissible in the joint fit. The smallest such
    set is taken, the one lowering BIC most among sets of that size.

    Why one member per instrument: effects on one instrument's observations combine into a
    shape none of them has, and a set of them stands in for an effect no candidate models —
    user 10's mid-run 0.5 mg bias step (seed 1) was absorbed by nonlinearity_k3 +
    scale_warmup (chi2 6.4 / 3 dof after, no structure, calibration ok: a wrong answer),
    seed 2's by bias_hysteresis + nonlinearity_k2 (chi2 27 / 3 dof). Effects on different
    instruments' observations cannot: each residual is one member's, and the set's chi2 drop
    is the sum of its members' alone (1.000 for the two rolls; 1.09-1.13 for the
    calibration's sets).
    """
    ok = [(cand, term, trial, d_bic) for cand, term, trial, _, d_bic in tried
          if d_bic < -min_delta_bic
          and (admissible is None or admissible(current, trial, term) is None)]
    ok = sorted(ok, key=lambda x: x[3])[:JOINT_MOST]
    fits = {frozenset([cand.name]): trial for cand, _, trial, _ in ok}
    family = 0  # sets of the round's candidates tested so far (the Sidak count)
    for size in range(2, min(len(ok), room) + 1):
        family += math.comb(tested, size)
        best = None
        for combo in itertools.combinations(ok, size):
            if len({instrument(t.name) for _, t, *_ in combo}) < size:
                continue  # two members on one instrument's observations: not a set
            key = frozenset(c.name for c, *_ in combo)
            try:
                joint = stage.fit([*terms, *(t for _, t, *_ in combo)])
            except (NotApplicable, np.linalg.LinAlgError):
                continue
            fits[key] = joint
            d_bic = (bic(joint, searched + sum(t.searched for _, t, *_ in combo))
                     - bic(current, searched))
            trials = math.prod(t.trials for _, t, *_ in combo)
            p_adj = sidak(sidak(f_test(current, joint, sum(t.width for _, t, *_ in combo)),
                                trials), family)
            if not (p_adj < alpha and d_bic < -min_delta_bic):
                continue
            if structure_of(joint, alpha).structured:
                continue  # the set does not explain the excess that held its members back
            if all(_member_needed(fits.get(key - {c.name}), joint, t, alpha, min_delta_bic)
                   and (admissible is None or admissible(current, joint, t) is None)
                   for c, t, *_ in combo) and (best is None or d_bic < best[3]):
                best = (tuple((c, t) for c, t, *_ in combo), joint, p_adj, float(d_bic))
        if best is not None:
            return best
    return None


def instrument(name: str) -> str:
    """The instrument an effect acts on, from its name: ``camera_roll[A]`` -> ``A``; an
    effect named without brackets (``scale_warmup``, ``reference_face_offset``) acts on the
    stage's own observations, named ``""``."""
    head, sep, rest = name.partition("[")
    return rest.rstrip("]") if sep else ""


def _member_needed(without: StageFit | None, joint: StageFit, term: Term, alpha: float,
                   min_delta_bic: float) -> bool:
    """Whether ``term`` is significant and lowers BIC in ``joint`` against the fit
    ``without`` it (None: not fitted, so not shown)."""
    if without is None:
        return False
    d_bic = bic(joint, term.searched) - bic(without)
    return (sidak(f_test(without, joint, term.width), term.trials) < alpha
            and d_bic < -min_delta_bic)


def _try(stage: Stage, cand: Candidate, current: StageFit, terms: Sequence[Term],
         skipped: dict[str, SkippedCandidate]) -> tuple[StageFit | None, Term | None]:
    """The refit with ``cand``'s term, or (None, None) with the candidate recorded in
    ``skipped`` when it does not apply or its refit is singular."""
    try:
        term = cand.build(current)
        if term is None:
            raise NotApplicable("does not apply to these data")
        return stage.fit([*terms, term]), term
    except NotApplicable as exc:
        why = str(exc) or "does not apply to these data"
    except np.linalg.LinAlgError as exc:
        why = f"singular refit ({exc})" if str(exc) else "singular refit"
    log.debug("loop   candidate %s: skipped: %s", cand.name, why)
    skipped[cand.name] = SkippedCandidate(cand.name, why)
    return None, None


def _chi2_dof(fit: StageFit) -> str:
    return "n/a (noise unknown)" if fit.sigma is None else f"{fit.chi2 / max(fit.dof, 1):.3f}"


def _structure_note(s: StructureReport) -> str:
    w = s.worst
    return ("none" if not s.structured else
            f"{w.name} p {w.p_value:.2g}" if w is not None else "found")
