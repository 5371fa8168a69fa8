"""The residual loop: fit, test the residual, add the effect the data call for, repeat, report.

A *stage* (a line fit along a mark, face angles over revolutions, an ellipsoid over poses, the
fusion) implements ``fit(terms) -> StageFit``: it fits its declared model plus the given extra
terms and returns residuals, their standard uncertainties (or None when unknown), regressors
and the quantities of interest. *Candidates* build a :class:`Term` (design columns with a name,
unit and physical meaning) from the current fit. The loop scores each candidate by refitting,
adds the best one only if an F-test (corrected for searched parameters) and BIC both call for
it, and stops when nothing more is significant. Structure that remains is reported, never
hidden.

A candidate that does not apply to the data (its builder returns None or raises
:class:`~axisbase.errors.NotApplicable`, or its refit does) or whose refit is singular
(``numpy.linalg.LinAlgError``) is skipped, and the report says which and why
(``LoopReport.skipped``). Anything else a candidate raises is a defect and propagates.
With ``-v`` (the ``align`` logger at DEBUG) the loop logs every candidate it tries, with its
p-value and ΔBIC, and what it decided.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from scipy import special  # (not scipy.stats: 1 s to import; the same functions)

from align.loop.structure import StructureReport, check_structure
from axisbase.errors import NotApplicable

log = logging.getLogger("align.loop")


@dataclass(frozen=True)
class Term:
    """Extra design columns for one effect.

    Attributes
    ----------
    name : str
        The effect's name (``earth_rate``, ``camera_roll[B]``).
    unit : str
        Unit of its estimate (``rad/s``, ``rad``).
    columns : ndarray, shape (N,) or (N, m)
        Regressors entering the stage's model linearly.
    searched : int
        Nonlinear parameters chosen by a search before fitting (e.g. a frequency), counted
        in BIC.
    trials : float
        Independent trials of that search (the look-elsewhere factor).
    meta : mapping of str to float
        What the stage needs to interpret the term (e.g. a period [s]).
    """

    name: str
    unit: str
    columns: np.ndarray
    searched: int = 0
    trials: float = 1.0
    meta: Mapping[str, float] = field(default_factory=dict)

    @property
    def width(self) -> int:
        return int(np.asarray(self.columns).reshape(len(self.columns), -1).shape[1])


@dataclass(frozen=True)
class StageFit:
    """What a stage returns from one fit.

    Attributes
    ----------
    residuals : ndarray, shape (N,)
        Observed minus fitted, in the observations' unit.
    sigma : ndarray, shape (N,), or None
        Their standard uncertainties (None: unknown, the tests then estimate the noise).
    n_params : int
        Parameters fitted (``dof`` = N - n_params; ``chi2`` = sum (r / sigma)^2).
    regressors : mapping of str to ndarray
        Quantities the residuals may depend on (time, period, position along a mark).
    order : str
        The regressor the structure tests order the residuals by.
    effects : mapping of str to (float, float)
        Per term name, (estimate, standard uncertainty) in the term's unit.
    quantities : mapping of str to (float, float)
        The stage's quantities of interest, name -> (value, u), SI/radians.
    components : mapping of str to tuple of (str, float, float)
        For effects with several parameters, (label, estimate, u) of each (the ``effects``
        entry is the most significant one).
    payload : object
        The stage's own fitted model.
    noise_dof : float or None
        Degrees of freedom of an *estimated* noise covariance behind ``sigma`` (None: sigma
        known); the effect and structure tests then use their null distributions with an
        estimated covariance (F- and t-type instead of chi2 and normal).
    """

    residuals: np.ndarray
    sigma: np.ndarray | None
    n_params: int
    regressors: Mapping[str, np.ndarray]
    order: str
    effects: Mapping[str, tuple[float, float]]
    quantities: Mapping[str, tuple[float, float]]
    components: Mapping[str, tuple[tuple[str, float, float], ...]] = field(default_factory=dict)
    payload: object = None
    noise_dof: float | None = None
    sequence: bool = True
    """False when the residuals are not independent in their order (a fit with fewer
    degrees of freedom than residuals whose projection correlates them, as the known-pose
    fit's 18 components in 6 dof): only the chi2 and regressor tests then apply."""

    @property
    def n(self) -> int:
        return int(len(self.residuals))

    @property
    def dof(self) -> int:
        return self.n - self.n_params

    @property
    def chi2(self) -> float:
        if self.sigma is None:
            return float(np.sum(self.residuals**2))
        return float(np.sum((self.residuals / self.sigma) ** 2))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2))) if self.n else float("nan")


class Stage(Protocol):
    def fit(self, terms: Sequence[Term]) -> StageFit: ...


@dataclass(frozen=True)
class Candidate:
    """A candidate effect.

    Attributes
    ----------
    name : str
        The effect's name (the Term's).
    unit : str
        Unit of its estimate.
    description : str
        What it is, for the report.
    build : callable
        ``build(current_fit) -> Term``: its columns from the current fit (None, or
        :class:`~axisbase.errors.NotApplicable` raised with the reason, if it does not
        apply).
    """

    name: str
    unit: str
    description: str
    build: Callable[[StageFit], Term | None]


@dataclass(frozen=True)
class EffectReport:
    """An effect the loop added.

    Attributes
    ----------
    name : str
        The effect; unit —.
    estimate : float
        Its value [``unit``].
    u : float
        Its standard uncertainty [``unit``].
    unit : str
        The unit of ``estimate`` and ``u``; unit —.
    rms_before, rms_after : float
        The residual RMS before and after adding it [the stage's residual unit].
    delta_bic : float
        The change in BIC — dimensionless.
    p_value : float
        Its significance (look-elsewhere corrected) — dimensionless.
    description : str
        What it is, in words; unit —.
    components : tuple of (str, float, float)
        Per axis (name, estimate, u) [``unit``].
    """

    name: str
    estimate: float
    u: float
    unit: str
    rms_before: float
    rms_after: float
    delta_bic: float
    p_value: float
    description: str = ""
    components: tuple[tuple[str, float, float], ...] = ()

    def to_dict(self) -> dict:
        d = {"name": self.name, "estimate": self.estimate, "u": self.u, "unit": self.unit,
             "rms_before": self.rms_before, "rms_after": self.rms_after,
             "delta_bic": self.delta_bic, "p_value": self.p_value}
        if self.description:
            d["description"] = self.description
        if self.components:
            d["components"] = [{"axis": c, "estimate": e, "u": u} for c, e, u in self.components]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> EffectReport:
        """From :meth:`to_dict`'s output (a non-finite number saved as null reads as NaN)."""
        def num(k: str) -> float:
            v = d.get(k)
            return float("nan") if v is None else float(v)

        return cls(str(d["name"]), num("estimate"), num("u"), str(d.get("unit", "")),
                   num("rms_before"), num("rms_after"), num("delta_bic"), num("p_value"),
                   str(d.get("description", "")),
                   tuple((str(c["axis"]), float(c["estimate"]), float(c["u"]))
                         for c in d.get("components", ())))


@dataclass(frozen=True)
class RefusedEffect:
    """A candidate the tests called for but the stage's ``admissible`` check refused: why, and
    its significance (it was *not* added).

    Attributes
    ----------
    name : str
        The candidate; unit —.
    reason : str
        Why it was refused; unit —.
    p_value : float
        Its significance — dimensionless.
    delta_bic : float
        Its change in BIC — dimensionless.
    """

    name: str
    reason: str
    p_value: float
    delta_bic: float

    def to_dict(self) -> dict:
        return {"name": self.name, "reason": self.reason, "p_value": self.p_value,
                "delta_bic": self.delta_bic}

    @classmethod
    def from_dict(cls, d: Mapping) -> RefusedEffect:
        return cls(str(d["name"]), str(d["reason"]), float(d["p_value"]),
                   float(d["delta_bic"]))


@dataclass(frozen=True)
class SkippedCandidate:
    """A candidate the loop could not try: it does not apply to these data, or its refit was
    singular (``reason`` says which, in the stage's words).

    Attributes
    ----------
    name : str
        The candidate; unit —.
    reason : str
        Why it was skipped; unit —.
    """

    name: str
    reason: str

    def to_dict(self) -> dict:
        return {"name": self.name, "reason": self.reason}

    @classmethod
    def from_dict(cls, d: Mapping) -> SkippedCandidate:
        return cls(str(d["name"]), str(d["reason"]))


@dataclass(frozen=True)
class LoopReport:
    """Before/after of one stage's loop.

    Attributes
    ----------
    effects : tuple of EffectReport
        The effects added, in order, with estimate, u and the RMS before/after.
    before, after : StageFit
        The declared model's fit and the final one.
    structure_before, structure_after : StructureReport
        The residuals' structure tests before and after (``unexplained_structure``: what
        remains after).
    terms : tuple of Term
        The terms of the final model.
    refused : tuple of RefusedEffect
        Significant candidates not added, with why.
    skipped : tuple of SkippedCandidate
        Candidates that could not be tried, with why.

    ``unexplained_structure`` is true when the structure tests still find structure after
    the loop *or* a candidate the data called for was refused: either way the model lacks
    something the residual shows, and the stage must widen u or say not ok.
    """

    effects: tuple[EffectReport, ...]
    before: StageFit
    after: StageFit
    structure_before: StructureReport
    structure_after: StructureReport
    terms: tuple[Term, ...]
    refused: tuple[RefusedEffect, ...] = ()
    skipped: tuple[SkippedCandidate, ...] = ()

    @property
    def unexplained_structure(self) -> bool:
        return self.structure_after.structured or bool(self.refused)

    @property
    def structure_evidence(self) -> tuple[str, float, str]:
        """What shows the structure left: (test or refused candidate, p-value, detail) —
        the structure tests' worst when they find structure, else the most significant
        refused candidate."""
        if self.structure_after.structured or not self.refused:
            w = self.structure_after.worst
            return w.name, w.p_value, w.detail
        r = min(self.refused, key=lambda r: r.p_value)
        return f"{r.name} refused", r.p_value, r.reason

    def summary_lines(self) -> list[str]:
        return self.summary().summary_lines()

    def summary(self) -> LoopSummary:
        """What of this loop a saved result keeps."""
        def chi2_dof(f: StageFit) -> float | None:
            return None if f.sigma is None else f.chi2 / max(f.dof, 1)

        w = self.structure_evidence if self.unexplained_structure else None
        return LoopSummary(self.effects, self.before.rms, self.after.rms,
                           chi2_dof(self.before), chi2_dof(self.after),
                           self.unexplained_structure,
                           None if w is None else w[0], None if w is None else w[1],
                           "" if w is None else w[2], self.refused, self.skipped)


@dataclass(frozen=True)
class LoopSummary:
    """A loop's outcome as a result saves it.

    Attributes
    ----------
    effects : tuple of EffectReport
        The effects added, in order; unit — (theirs are in their fields).
    rms_before, rms_after : float
        Residual RMS of the declared model and of the final one [the stage's residual unit].
    chi2_dof_before, chi2_dof_after : float or None
        χ²/dof against the stated noise (None: noise unknown) — dimensionless.
    unexplained_structure : bool
        Whether structure no candidate explains remains; unit —.
    structure_test, structure_p, structure_detail : str, float, str
        The test that found it, its p-value (dimensionless) and what it saw (None, None, "" if
        none); unit —.
    refused : tuple of RefusedEffect
        Significant candidates the stage's physical checks refused, with why; unit —.
    skipped : tuple of SkippedCandidate
        Candidates not tried (not applicable to these data, or a singular refit), with why;
        unit —.
    """

    effects: tuple[EffectReport, ...]
    rms_before: float
    rms_after: float
    chi2_dof_before: float | None
    chi2_dof_after: float | None
    unexplained_structure: bool
    structure_test: str | None = None
    structure_p: float | None = None
    structure_detail: str = ""
    refused: tuple[RefusedEffect, ...] = ()
    skipped: tuple[SkippedCandidate, ...] = ()

    def summary(self) -> LoopSummary:
        """Itself (a loaded result's loop is already a summary)."""
        return self

    def summary_lines(self) -> list[str]:
        """The loop's before/after for the terminal, one line each."""
        if self.chi2_dof_before is None:
            lines = [f"residual RMS {self.rms_before:.4g} -> {self.rms_after:.4g}; noise "
                     "unknown: no chi2 test, effects judged by F-test"]
        else:
            lines = [f"residual RMS {self.rms_before:.4g} -> {self.rms_after:.4g}; "
                     f"chi2/dof {self.chi2_dof_before:.3f} -> {self.chi2_dof_after:.3f}"]
        for e in self.effects:
            lines.append(f"added {e.name}: {e.estimate:.4g} ± {e.u:.2g} {e.unit} "
                         f"(dBIC {e.delta_bic:.1f}, p {e.p_value:.2g})")
        for r in self.refused:
            lines.append(f"REFUSED {r.name} (p {r.p_value:.2g}): {r.reason}")
        if self.unexplained_structure:
            lines.append(f"UNEXPLAINED STRUCTURE remains: {self.structure_test} "
                         f"p={self.structure_p:.2g} {self.structure_detail}")
        return lines

    def to_dict(self) -> dict:
        """The result-level keys of the JSON contract (``effects``, ``unexplained_structure``)
        and the loop's before/after under ``loop``."""
        return {"effects": [e.to_dict() for e in self.effects],
                "unexplained_structure": self.unexplained_structure,
                "refused_effects": [r.to_dict() for r in self.refused],
                "skipped_candidates": [s.to_dict() for s in self.skipped],
                "loop": {"rms_before": self.rms_before, "rms_after": self.rms_after,
                         "chi2_dof_before": self.chi2_dof_before,
                         "chi2_dof_after": self.chi2_dof_after,
                         "structure_test": self.structure_test,
                         "structure_p": self.structure_p,
                         "structure_detail": self.structure_detail}}

    @classmethod
    def from_dict(cls, d: Mapping) -> LoopSummary:
        lp = d.get("loop") or {}

        def num(k: str) -> float | None:
            v = lp.get(k)
            return None if v is None else float(v)

        nan = float("nan")
        rb, ra = num("rms_before"), num("rms_after")
        return cls(tuple(EffectReport.from_dict(e) for e in d.get("effects", ())),
                   nan if rb is None else rb, nan if ra is None else ra,
                   num("chi2_dof_before"), num("chi2_dof_after"),
                   bool(d.get("unexplained_structure", False)), lp.get("structure_test"),
                   num("structure_p"), str(lp.get("structure_detail", "")),
                   tuple(RefusedEffect.from_dict(r) for r in d.get("refused_effects", ())),
                   tuple(SkippedCandidate.from_dict(s)
                         for s in d.get("skipped_candidates", ())))


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


def _may_pass(current: StageFit, chi2_pred: float, term: Term, searched: int, alpha: float,
              min_delta_bic: float) -> bool:
    """Whether a candidate predicted to leave ``chi2_pred`` could pass the loop's tests
    (with the screen's margin): a stand-in fit with the predicted chi2 goes through the
    same BIC and F-test."""
    trial = optimistic_fit(current, chi2_pred, term.width)
    d_bic = bic(trial, searched + term.searched) - bic(current, searched)
    p = f_test(current, trial, term.width)
    p_adj = float(-np.expm1(term.trials * np.log1p(-min(p, 1 - 1e-16))))
    return p_adj < alpha and d_bic < -min_delta_bic


def run_loop(stage: Stage, candidates: Sequence[Candidate], alpha: float = 1e-3,
             min_delta_bic: float = 6.0, max_effects: int = 4,
             admissible: Callable[[StageFit, StageFit, Term], str | None] | None = None
             ) -> LoopReport:
    """Run the residual loop over ``stage`` with ``candidates``.

    An effect is added when its (look-elsewhere corrected) F-test p-value is below ``alpha``
    and it lowers BIC by at least ``min_delta_bic``; the best such effect is added first.
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
        for cand in candidates:
            if any(t.name == cand.name for t in terms):
                continue
            if cand.name in predicted:
                term = cand.build(current)
                if term is not None and not _may_pass(current, predicted[cand.name], term,
                                                      searched, alpha, min_delta_bic):
                    log.debug("loop   candidate %s: screened out (linearised chi2 %.4g from "
                              "%.4g)", cand.name, predicted[cand.name], current.chi2)
                    continue
            trial, term = _try(stage, cand, current, terms, skipped)
            if trial is None:
                continue
            skipped.pop(cand.name, None)  # tried now: not skipped after all
            d_bic = (bic(trial, searched + term.searched)
                     - bic(current, searched))
            p = f_test(current, trial, term.width)
            p_adj = float(-np.expm1(term.trials * np.log1p(-min(p, 1 - 1e-16))))
            log.debug("loop   candidate %s: p %.3g (look-elsewhere corrected, %g trials), "
                      "dBIC %+.1f (needs p < %g and dBIC < %+.1f)", cand.name, p_adj,
                      term.trials, d_bic, alpha, -min_delta_bic)
            if p_adj < alpha and d_bic < -min_delta_bic and (best is None or d_bic < best[0]):
                why = admissible(current, trial, term) if admissible is not None else None
                if why is not None:
                    log.debug("loop   candidate %s: significant but refused: %s", cand.name,
                              why)
                    refused[cand.name] = RefusedEffect(cand.name, why, p_adj, float(d_bic))
                    continue
                best = (d_bic, p_adj, term, trial, cand)
        if best is None:
            log.debug("loop %s: no candidate significant: stop", type(stage).__name__)
            break
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
    s_after = structure_of(current, alpha)
    log.debug("loop %s: final model: RMS %.4g, chi2/dof %s; structure %s; %.3f s",
              type(stage).__name__, current.rms, _chi2_dof(current), _structure_note(s_after),
              time.perf_counter() - start)
    added = {t.name for t in terms}
    return LoopReport(tuple(effects), before, current, s_before, s_after, tuple(terms),
                      tuple(r for n, r in refused.items() if n not in added),
                      tuple(s for n, s in skipped.items() if n not in added))


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
