"""What the fusion's loop may take as an explanation, and what E's u must carry of the rest.

Two rules keep the loop from a silent wrong answer:

* **A nuisance beyond any set-up error is no explanation.** The loop's nuisances (a camera's
  roll, the reference face's azimuth offset, the table axis's tilt, the platform's levelling)
  are small set-up errors; a larger one is declared in session.toml (``roll_deg``,
  ``reference_offset_arcsec``, ``table_tilt_arcsec``). A fit that takes one beyond
  :data:`UNDECLARED_LIMIT_DEG` is a near-degenerate candidate absorbing what another effect
  left (a 30″ camera roll read as an 8° reference-face offset, 28600 ± 7171″, E off by 5.8 u):
  :func:`admissible` refuses it, the loop reports it (``refused``) and the result is not ok.
* **An effect the data cannot exclude is carried in u.** A candidate the loop tested but did
  not add whose estimate is not near zero (beyond :data:`NOT_EXCLUDED_Z` of its u — within the
  look-elsewhere threshold, so not named) and whose freeing would move E by more than
  :data:`SHIFT_FRACTION` of u is carried in E's covariance as a Type B term ΔE ΔEᵀ, ΔE the
  shift of E when it is freed. Freeing an effect of estimate b ± u_b adds k k' u_b² to cov(E)
  (k = dE/db) and moves E by k b; E[(k b)²] = k² (u_b² + b_true²): in expectation the Type B
  term is what freeing the effect would cost, and it covers the effect if it is real (a 30″
  camera roll not named at p 0.006 left E_zY 9.4 u off; carried, 1.9 u). A candidate the
  data cannot *determine* (a roll or the reference face's offset whose u freed exceeds its
  plausible range's σ) is judged first and carried over that range instead
  (:mod:`align.fusion.undetermined`): its estimate freed is a draw of that u about zero, whose
  shift is no measure of it (camera B's roll freed at 298″ moved E_yZ 772″; its range ±34.6″).
  The levelling and the table's tilt have no range: these rules judge them.
* **An alternative the loop did not exclude is carried in u.** Judged beside the final model
  a candidate near-degenerate with an effect the loop named is no test at all (freed beside
  it, both run away: a 30″ roll of camera B beside the platform's levelling the loop named in
  its place, -6147 ± 7292″, or +156 ± 6082″). The question is then whether the data choose
  the named effect *over* the candidate: in the model with the candidate in place of the
  named effect, would the loop add the named effect back (its test at the loop's ``alpha``)?
  If not, the loop's choice is not established at its own level, and where the
  alternative's E differs from the final E by more than :data:`SHIFT_FRACTION` of u that
  difference is carried as a Type B term ΔE ΔEᵀ (the levelling named in place of the roll
  had left E_yZ 4.9 u off, ok, at seed 18 — Δχ² 3.7 between the two — and 7.7 u at seed 24,
  where the noise mimics a levelling of 3.3 u and the levelling given the roll is at p 0.006).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.fusion.observations import E_NAMES
from align.fusion.undetermined import carried_variance
from align.loop import Candidate, LoopReport, Stage, StageFit, Term, f_test
from axisbase.errors import NotApplicable
from axisbase.units import ARCSEC

UNDECLARED_LIMIT_DEG = 1.0
"""The largest undeclared nuisance the loop may name [deg]. Its nuisances are set-up errors of
arc-seconds to arc-minutes (a camera mounted square to its fixture, a reference face machined
on it, a table levelled); a degree is a set-up that was never squared and is declared
(session.toml), and the marks' nominal check allows 10° for declared rolls only."""

NOT_EXCLUDED_Z = 2.0
"""A candidate not added whose estimate lies beyond this many u from zero is one the data
cannot exclude (the data favour it at ~95 %, below the loop's look-elsewhere threshold). For an
effect of m components (a tilt's x, y) the same tail: freeing it lowers χ² by more than the
χ²(m) quantile at P(|N(0, 1)| > NOT_EXCLUDED_Z) = 4.6 % (its length beyond 2 u would be
13.5 % for m = 2)."""

SHIFT_FRACTION = 0.5
"""...and whose freeing moves some angle of E by more than this fraction of its u is carried in
u (a smaller shift adds < 12 % to u: negligible)."""

NOT_EXCLUDED_TAG = " not excluded ("
"""What names a carried candidate's share in E's budget (``<candidate> not excluded (…)``)."""


def admissible(current: StageFit, trial: StageFit, term: Term) -> str | None:
    """The loop's physical prior: the reason to refuse ``term`` when its fitted size is beyond
    :data:`UNDECLARED_LIMIT_DEG`, else None."""
    est, u = trial.effects.get(term.name, (0.0, 0.0))
    if not abs(est) > np.deg2rad(UNDECLARED_LIMIT_DEG):
        return None
    return (f"fitted {est / ARCSEC:+.0f} ± {u / ARCSEC:.0f}″, beyond any undeclared set-up "
            f"error ({UNDECLARED_LIMIT_DEG:g}°): a near-degenerate candidate absorbing another "
            "effect, not this data's (declare a known large offset in session.toml; add "
            "reversal views or X/Y-up poses to separate the effects)")


@dataclass(frozen=True)
class NotExcluded:
    """A candidate the loop did not add but the data cannot exclude.

    Attributes
    ----------
    name : str
        The candidate; unit —.
    estimate, u : float
        Its fitted value and standard uncertainty when freed [rad].
    shift : numpy.ndarray
        The shift of the six angles (``E_NAMES``) when it is freed [rad] (in place of
        ``instead_of``, when given).
    instead_of : str or None
        The effect the loop named that it replaces (an alternative explanation), or None
        (freed beside the loop's effects); unit —.
    """

    name: str
    estimate: float
    u: float
    shift: np.ndarray
    instead_of: str | None = None

    def to_dict(self) -> dict:
        return {"name": self.name, "estimate": self.estimate, "u": self.u,
                "shift": self.shift.tolist(), "instead_of": self.instead_of}

    @classmethod
    def from_dict(cls, d: dict) -> NotExcluded:
        return cls(str(d["name"]), float(d["estimate"]), float(d["u"]),
                   np.array(d["shift"], float), d.get("instead_of"))

    @property
    def label(self) -> str:
        """How the budget names its Type B share."""
        where = "" if self.instead_of is None else f" in place of {self.instead_of}"
        return (f"{self.name}{NOT_EXCLUDED_TAG}{self.estimate / ARCSEC:+.1f} ± "
                f"{self.u / ARCSEC:.1f}″{where}; declare it, or add reversal views)")


def _excluded(drop: float, width: int) -> bool:
    """Whether an effect of ``width`` components whose freeing lowers χ² by ``drop`` is
    beyond :data:`NOT_EXCLUDED_Z` of its u (the same tail in χ²(width))."""
    return bool(special.chdtrc(width, max(drop, 0.0)) < 2 * special.ndtr(-NOT_EXCLUDED_Z))


def _refit(stage: Stage, terms: Sequence[Term]) -> StageFit | None:
    try:
        return stage.fit(list(terms))
    except (NotApplicable, np.linalg.LinAlgError):
        return None  # not separable from E by these data: the loop passed it by too


def _e(fit: StageFit) -> np.ndarray:
    return np.array([fit.quantities[n][0] for n in E_NAMES])


def not_excluded(stage: Stage, candidates: Sequence[Candidate], loop: LoopReport,
                 cov: np.ndarray, alpha: float, skip: Sequence[str] = ()) -> list[NotExcluded]:
    """The candidates of ``loop`` not added (nor in ``skip``: those the data cannot determine,
    :func:`align.fusion.undetermined.undetermined`, carried over their plausible range) that
    the data cannot exclude and that move E by more than :data:`SHIFT_FRACTION` of its u
    (``cov``: E's 6×6 [rad²]), each re-judged against the final model:

    * freed beside the loop's terms, beyond :data:`NOT_EXCLUDED_Z` u (in χ² for several
      components) and within :data:`UNDECLARED_LIMIT_DEG`; or
    * in place of a term the loop added (an alternative explanation), within
      :data:`UNDECLARED_LIMIT_DEG`, with the replaced term, freed back, not significant at
      the loop's ``alpha`` (its χ² test, :func:`align.loop.f_test`; the fusion's terms are
      not searched, one trial): the shift is the alternative's E less the final E.

    A candidate both ways is carried once, by its larger shift (in units of E's u)."""
    cur = loop.after
    added = [t.name for t in loop.terms]
    u_e = np.sqrt(np.diag(cov))
    e0 = _e(cur)
    out = []
    for cand in candidates:
        if cand.name in added or cand.name in skip:
            continue
        try:
            term = cand.build(cur)
        except (NotApplicable, np.linalg.LinAlgError):
            continue  # not separable from E by these data: the loop passed it by too
        if term is None:
            continue
        found = []
        joint = _refit(stage, [*loop.terms, term])
        if joint is not None:
            est, u = joint.effects.get(term.name, (0.0, float("inf")))
            # (judged determined already: ``skip`` holds the undetermined, judge's first rule)
            if judge(0.0, None, cur.chi2 - joint.chi2, term.width, est, _e(joint) - e0,
                     u_e) == NOT_EXCLUDED:
                found.append(NotExcluded(cand.name, float(est), float(u), _e(joint) - e0))
        for named in loop.terms:
            alt = _refit(stage, [t if t is not named else term for t in loop.terms])
            if alt is None:
                continue
            est, u = alt.effects.get(term.name, (0.0, float("inf")))
            # The named effect freed back beside the candidate (the joint model): would the
            # loop add it, or is its choice over the candidate not established at the
            # loop's own level? (A singular joint fit — the two not separable at all — is
            # bounded by the better of the two: the drop is then at most the χ² difference.)
            p = (f_test(alt, joint, named.width) if joint is not None else
                 float(special.chdtrc(named.width, max(alt.chi2 - min(cur.chi2, alt.chi2),
                                                       0.0))))
            if in_place_of(est, p, alpha):
                found.append(NotExcluded(cand.name, float(est), float(u), _e(alt) - e0,
                                         named.name))
        k = largest([c.shift for c in found], u_e)
        if k is not None:
            out.append(found[k])
    return out


def in_place_of(size: float, p: float, alpha: float) -> bool:
    """The rule of :func:`not_excluded` for an alternative (also what ``align plan`` predicts
    with): a candidate fitted in place of a named effect to a size ``size`` [rad] within
    :data:`UNDECLARED_LIMIT_DEG`, with the named effect freed back beside it at p-value ``p``
    not significant at the loop's ``alpha`` (its shift then judged by :func:`largest`)."""
    return bool(abs(size) <= np.deg2rad(UNDECLARED_LIMIT_DEG) and not p < alpha)


def largest(shifts: Sequence[np.ndarray], u_e: np.ndarray) -> int | None:
    """Of one candidate's shifts of E (freed beside the model, or in place of a named effect)
    [rad], the index of the one carried: the largest in units of E's u ``u_e`` [rad], if it
    exceeds :data:`SHIFT_FRACTION` of u in some angle; else None."""
    if not len(shifts):
        return None
    k = max(range(len(shifts)), key=lambda i: float(np.max(np.abs(shifts[i]) / u_e)))
    return k if np.any(np.abs(shifts[k]) > SHIFT_FRACTION * u_e) else None


UNDETERMINED = "undetermined"
""":func:`judge`'s verdict for a candidate the data cannot determine: carried over its
plausible range (:mod:`align.fusion.undetermined`)."""
NOT_EXCLUDED = "not excluded"
""":func:`judge`'s verdict for a candidate the data cannot exclude: carried as its shift."""


def judge(u_freed: float, sigma: float | None, drop: float = 0.0, width: int = 1,
          size: float = 0.0, shift: np.ndarray | None = None, u_e: np.ndarray | None = None
          ) -> str | None:
    """The fusion's rules for a candidate the loop did not add, in the fusion's order — the
    one function :func:`align.fusion.fuse` (through :func:`align.fusion.undetermined.
    undetermined`, then :func:`not_excluded`) and ``align plan`` (on each draw of the new
    data, :mod:`align.plan_carried`) judge it by:

    1. :data:`UNDETERMINED` when the data cannot determine it: its u freed ``u_freed`` [rad]
       (inf: not separable from E) beyond ``sigma``, the σ of its plausible range [rad]
       (None: it has none, the platform's levelling and the table's tilt)
       (:func:`align.fusion.undetermined.carried_variance`); its estimate, freed, is then no
       measure of it;
    2. else :data:`NOT_EXCLUDED` when freeing it lowers χ² by ``drop`` (b̂ᵀ cov(b)⁻¹ b̂,
       ``width`` components) beyond :data:`NOT_EXCLUDED_Z`, to a size ``size`` [rad] within
       :data:`UNDECLARED_LIMIT_DEG`, and moves E by ``shift`` [rad] more than
       :data:`SHIFT_FRACTION` of E's u ``u_e`` [rad] in some angle (``shift`` None: no
       estimate to judge, as for a candidate the loop's tests excluded);
    3. else None: the loop's tests judge it (not carried)."""
    if sigma is not None and carried_variance(sigma, u_freed) > 0:
        return UNDETERMINED
    if shift is None:
        return None
    if (_excluded(drop, width) and abs(size) <= np.deg2rad(UNDECLARED_LIMIT_DEG)
            and np.any(np.abs(shift) > SHIFT_FRACTION * u_e)):
        return NOT_EXCLUDED
    return None
