"""Effects that pass their own test but not the family's: carried in u, not added.

The residual loop adds an effect only when its test survives the count over every candidate
of the round (Holm in Sidak's form, :func:`align.loop.run_loop`): that keeps clean data free
of false effects, but an effect with a large pull on the parameters and little signal of its
own then goes unmodelled while the parameters carry its shift. A cubic non-linearity K3 on
26 cube poses is the case: its columns are nearly k's, so 100 µg/g³ moves k by 7-9 of its u
while K3's own test reaches p ~ 4e-4 (a chi2 drop of 18 on 3 parameters) — significant by
itself, not after the count over 17 candidates.

Such an effect is plausible: the data alone prefer it (its own likelihood-ratio test at the
loop's alpha, and BIC by the loop's margin), and its physical bound admits it. Its fit is
then one of the models the parameters are averaged over (as the alternatives of
:mod:`align.calibration.widen`): its shift of the nine core parameters from the chosen fit as
the half-width of a rectangular distribution, plus its own covariance beyond the chosen one's
(the sensitivity of the parameters to the effect times the effect's own u) — the term
``plausible_effect``, named on the terminal, in ``warnings`` and per parameter in the JSON.

The own test here divides no chi2 excess out (the loop's test does, so that an understated
noise does not manufacture effects): widening is the safe side of that doubt.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import special

from align.calibration.widen import RECTANGULAR, Alternative, positive_part
from align.loop import Candidate, LoopReport, bic
from align.loop.fit import StageFit, Term
from align.loop.loop import sidak

PLAUSIBLE = "plausible_effect"
PLAUSIBLE_ALPHA = 5e-3
"""Family-wise level (Sidak over the round's candidates) at which an effect not added is
plausible enough to carry in u: half of issue 19's 1 % budget for a clean tumble's
decisions (the other half: the structure and ambiguity widenings, 0-0.33 % measured,
docs/false-alarms.md). Adding an effect keeps the loop's alpha (1e-3)."""
MIN_DELTA_BIC = 6.0
"""The loop's margin in BIC (:func:`align.loop.run_loop`'s ``min_delta_bic``): an effect is
plausible only where BIC prefers it by as much as the loop would need to add it."""


def own_p(base: StageFit, trial: StageFit, width: int, trials: float) -> float:
    """The candidate's own likelihood-ratio p-value, look-elsewhere corrected for its own
    search (``trials``), not for the other candidates (noise unknown: the F test)."""
    drop = base.chi2 - trial.chi2
    if drop <= 0 or width <= 0 or trial.dof <= 0:
        return 1.0
    if base.sigma is None:
        p = special.fdtrc(width, trial.dof, (drop / width) / max(trial.chi2 / trial.dof,
                                                                 1e-300))
    elif trial.noise_dof is not None and np.isfinite(trial.noise_dof):
        p = special.fdtrc(width, trial.noise_dof, drop / width)
    else:
        p = special.chdtrc(width, drop)
    return sidak(float(p), trials)


def plausible_effects(fits: dict[tuple[str, ...], tuple[StageFit, tuple[Term, ...]]],
                      rep: LoopReport, candidates: Sequence[Candidate],
                      guard: Callable[[StageFit, StageFit, Term], str | None],
                      skip: Sequence[str] = (), level: float = PLAUSIBLE_ALPHA
                      ) -> list[tuple[Alternative, float]]:
    """The effects of the loop's last round not added that BIC prefers to the final fit by
    the loop's margin, admitted by the physical ``guard``, when at least one of them passes
    its own test at ``level`` family-wise (Sidak over the round's candidates: the gate, whose
    rate on clean data is ``level``); else none. Each as an
    :class:`~align.calibration.widen.Alternative` (its shift and excess covariance over the
    final fit) with its family-wise p. ``fits``: the stage's fits by effect names; ``skip``:
    effect sets already weighed elsewhere (the ambiguity term's)."""
    final = rep.after
    names = tuple(t.name for t in rep.terms)
    searched = sum(t.searched for t in rep.terms)
    b_final = bic(final, searched)
    core, cov = _core(final.payload), np.asarray(final.payload.cov, float)[:9, :9]
    skipped = {s.name for s in rep.skipped}
    tested = sum(1 for c in candidates if c.name not in names and c.name not in skipped
                 and c.build(final) is not None)
    out, gate = [], False
    for cand in candidates:
        key = (*names, cand.name)
        if cand.name in names or key not in fits or " + ".join(key) in skip:
            continue
        trial, terms = fits[key]
        term = terms[-1]
        d_bic = bic(trial, searched + term.searched) - b_final
        if not d_bic < -MIN_DELTA_BIC or guard(final, trial, term):
            continue
        p = sidak(own_p(final, trial, term.width, term.trials), max(tested, 1))
        gate = gate or p < level
        m = trial.payload
        out.append((Alternative(" + ".join(key), "", float(d_bic), float("nan"),
                                _core(m) - core,
                                positive_part(np.asarray(m.cov, float)[:9, :9] - cov)), p))
    return out if gate else []


def plausible_reason(found: list[tuple[Alternative, float]], alpha: float) -> str:
    """Why u was widened for them."""
    each = ", ".join(f"{a.effects.split(' + ')[-1]} (p = {p:.2g} over the candidates, dBIC "
                     f"{a.d_bic:+.1f})" for a, p in found)
    return (f"plausible but not added: {each}: the declared model doubted at "
            f"{PLAUSIBLE_ALPHA:g} over the candidates, no effect at the loop's alpha {alpha:g}"
            ": u carries the parameters' shift with each effect BIC prefers and its own u")


def plausible_term(found: list[tuple[Alternative, float]], n_params: int) -> np.ndarray:
    """The covariance: each effect's shift of the nine core parameters as a rectangular
    half-width, plus its covariance beyond the chosen fit's, summed over the effects."""
    out = np.zeros((n_params, n_params))
    for a, _ in found:
        out[:9, :9] += np.outer(a.shift, a.shift) / RECTANGULAR**2 + a.excess
    return out


def _core(m) -> np.ndarray:
    return np.concatenate([m.k, m.beta, m.bias])
