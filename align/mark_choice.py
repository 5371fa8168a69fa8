"""The marks' loop's decisions on the edge: the reading the other side of each one, and how
much of it the reported angle and u carry.

The residual loop (:func:`align.loop.run_loop`) adds an effect when its test passes and
leaves the residual's structure to widen u when the structure tests find it; each decision
is a threshold on a statistic that a new measurement of the same mark would draw again. Where
the statistic lies within its own sampling spread of the threshold, a re-measurement (or an
imperceptibly different input: the band fit's width a fraction of a pixel off) takes the other
side as readily, and an angle read from one side only jumps by the difference between the
readings (the real photos: up to 3.9 u). Here each such decision's other reading is made, and
the mark's angle and u are the readings averaged by the chance of each side:

* the decision's margin is the statistic's normal score minus the threshold's
  (:func:`effect_margin`, :func:`structure_margin`). A p-value's normal score
  ``-ndtri(p)`` has sampling spread ~1 whatever the test (for a chi2(m) statistic it is
  ~ sqrt(chi2), whose spread under any noncentrality is sqrt((2m + 4 lam) / (4 (m + lam)))
  <= 1); BIC's criterion is a threshold on the chi2 drop, taken on sqrt(drop) the same way;
* the other side's weight is the chance a re-measurement lands there, Phi(-|margin|),
  renormalised to vanish at the band's edge :data:`CHOICE_BAND` (:func:`flip_weight`): 0.5 at
  the threshold from either side, so the angle is continuous across it, and exactly the
  plain decision outside the band;
* the angle moves toward the other reading by that weight q, and u adds the named Type B
  term ``model_choice``: sqrt(q (1 - q)) times the readings' difference (half of it at the
  threshold), and the other reading's larger u by 2q (all of it at the threshold): u covers
  both readings there, and equals the decided one's at the band's edge.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.errors import NotApplicable
from align.loop import (
    Candidate,
    EffectReport,
    LoopReport,
    StageFit,
    StructureReport,
    Term,
    bic,
    f_test,
)
from align.loop.loop import structure_of

CHOICE_BAND = 2.0
"""Half-width of the band about a decision's threshold, in the sampling spread (1) of the
statistic's normal score: a decision within it flips on a re-measurement at least
Phi(-2) = 2.3 % of the time, and its other reading is carried; outside it, the plain
decision (the weight is renormalised to reach 0 there, so nothing jumps at the edge)."""

MIN_DELTA_BIC = 6.0
"""The least drop of BIC an effect must bring (the marks' loop's, :func:`run_loop`'s)."""


@dataclass(frozen=True)
class Alternative:
    """The other side of one of the loop's decisions on a mark.

    Attributes
    ----------
    what : str
        The decision, in words (``"bent_mark dropped"``, ``"structure left"``); unit —.
    margin : float
        The statistic's normal score minus the threshold's (> 0: the test passed) —
        dimensionless, in the score's sampling spread.
    weight : float
        The chance the other side carries (:func:`flip_weight`) — dimensionless.
    report : LoopReport
        The loop's report as that side reads it.
    structured : bool or None
        The structure decision that side takes (None: its own structure tests').
    """

    what: str
    margin: float
    weight: float
    report: LoopReport
    structured: bool | None = None


def flip_weight(margin: float, band: float = CHOICE_BAND) -> float:
    """The weight of the side of a decision a statistic ``margin`` (normal-score units,
    > 0: passed) does *not* take: Phi(-|margin|) renormalised to 0 at ``band`` and 0.5 at 0.
    """
    m = abs(float(margin))
    if not m < band:
        return 0.0
    lo = special.ndtr(-band)
    return float((special.ndtr(-m) - lo) / (1.0 - 2.0 * lo))


def effect_margin(base: StageFit, ext: StageFit, term: Term, tested: int, searched: int,
                  alpha: float, min_delta_bic: float = MIN_DELTA_BIC) -> float:
    """How far ``term`` (``ext`` = ``base`` + term) passes the loop's two tests, in the
    sampling spread of their statistics (> 0: it is added): the smaller of the F-test's
    normal score above the threshold's (p corrected for the term's look-elsewhere trials
    and Holm over ``tested`` candidates, as the loop does) and sqrt(chi2 drop) above the
    drop BIC needs."""
    p = f_test(base, ext, term.width)
    p_thr = -np.expm1(np.log1p(-alpha) / max(term.trials * max(tested, 1), 1.0))
    m_p = float(special.ndtri(p_thr) - special.ndtri(min(max(p, 1e-300), 1.0)))
    drop = base.chi2 - ext.chi2
    d_bic = bic(ext, searched + term.searched) - bic(base, searched)
    need = drop + d_bic + min_delta_bic  # the drop at which d_bic = -min_delta_bic
    if base.sigma is None:  # (BIC on ln RSS: the F-test's margin alone)
        return m_p
    m_b = float(np.sqrt(max(drop, 0.0)) - np.sqrt(max(need, 0.0)))
    return min(m_p, m_b)


def structure_margin(s: StructureReport) -> float:
    """How far the structure tests' worst p-value is below their threshold (alpha over the
    number of tests), in normal-score units (> 0: structure found; -inf: no tests)."""
    if not s.tests:
        return -np.inf
    p = min(t.p_value for t in s.tests)
    return float(special.ndtri(s.alpha / len(s.tests)) - special.ndtri(min(max(p, 1e-300), 1.0)))


def _other_side(margin: float, band: float, taken: bool) -> float:
    """The weight of the reading the loop did not take, for a decision it took (``taken``:
    the effect is in) whose statistic stands ``margin`` from its threshold now: 0 outside
    the band (the loop's decision stands); within it, the chance of the other side (above
    0.5 where the final model's test no longer agrees with the round that decided)."""
    if not abs(margin) < band:
        return 0.0
    w = flip_weight(margin, band)
    return w if (margin > 0) == taken else 1.0 - w


def _build(cand: Candidate, fit: StageFit) -> Term | None:
    try:
        return cand.build(fit)
    except NotApplicable:
        return None


def _refit(stage, terms: Sequence[Term]) -> StageFit | None:
    try:
        return stage.fit(list(terms))
    except (NotApplicable, np.linalg.LinAlgError):
        return None


def alternatives(stage, rep: LoopReport, candidates: Sequence[Candidate], alpha: float,
                 admissible: Callable[[StageFit, StageFit, Term], str | None] | None = None,
                 band: float = CHOICE_BAND, min_delta_bic: float = MIN_DELTA_BIC
                 ) -> list[Alternative]:
    """The other side of each of the loop's decisions on ``rep`` that lies within ``band``
    of its threshold: each effect added, dropped; each candidate not added, added; the
    structure decision, flipped.

    Each effect's test is taken against the final model (the loop's last round: Holm over the
    candidates it tests there), so the margin is continuous in the data; with one effect, as
    on nearly every mark, it is the test the loop took.
    """
    out: list[Alternative] = []
    terms = list(rep.terms)
    after = rep.after
    names = {t.name for t in terms}
    built = {c.name: _build(c, after) for c in candidates if c.name not in names}
    free = sum(t is not None for t in built.values())
    for i, t in enumerate(terms):  # each effect added: dropped
        rest = terms[:i] + terms[i + 1:]
        base = _refit(stage, rest)
        if base is None:
            continue
        m = effect_margin(base, after, t, free + 1, sum(r.searched for r in rest), alpha,
                          min_delta_bic)
        q = _other_side(m, band, taken=True)
        if q > 0:
            alt = replace(rep, after=base, terms=tuple(rest),
                          effects=tuple(e for e in rep.effects if e.name != t.name),
                          structure_after=structure_of(base, alpha))
            out.append(Alternative(f"{t.name} dropped", m, q, alt))
    searched = sum(t.searched for t in terms)
    for c in candidates:  # each candidate not added: added
        t = built.get(c.name)
        if t is None:
            continue
        ext = _refit(stage, [*terms, t])
        if ext is None or (admissible is not None and admissible(after, ext, t) is not None):
            continue
        m = effect_margin(after, ext, t, free, searched, alpha, min_delta_bic)
        q = _other_side(m, band, taken=False)
        if q > 0:
            est, u = ext.effects.get(t.name, (float("nan"), float("nan")))
            eff = EffectReport(t.name, est, u, t.unit, after.rms, ext.rms,
                               float(bic(ext, searched + t.searched) - bic(after, searched)),
                               float(f_test(after, ext, t.width)), c.description)
            alt = replace(rep, after=ext, terms=(*terms, t), effects=(*rep.effects, eff),
                          structure_after=structure_of(ext, alpha))
            out.append(Alternative(f"{t.name} added", m, q, alt))
    if not rep.refused:  # (a refused effect is structure whatever the tests say)
        m = structure_margin(rep.structure_after)
        q = flip_weight(m, band)
        if q > 0:
            out.append(Alternative("structure " + ("not left" if m > 0 else "left"), m, q, rep,
                                   structured=not m > 0))
    return out


def blend(angle: float, u: float, others: Sequence[tuple[float, float, float]]
          ) -> tuple[float, float]:
    """The decided reading (``angle``, ``u`` [rad]) moved toward each other reading
    (weight q, angle, u) by q; returns (angle, model_choice [rad]): the Type B term u adds in
    quadrature, sqrt(sum of q (1 - q) d^2 + min(1, 2 q) max(0, u_q^2 - u^2)), d the
    readings' difference (wrapped to +-90 deg)."""
    a, var = angle, 0.0
    for q, a_q, u_q in others:
        d = float((a_q - angle + np.pi / 2) % np.pi - np.pi / 2)
        a += q * d
        var += q * (1 - q) * d * d + min(1.0, 2 * q) * max(0.0, u_q * u_q - u * u)
    return float(a), float(np.sqrt(var))
