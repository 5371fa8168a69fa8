"""The non-linearity the loop did not fit: K2 and K3 from the accelerometer's datasheet (a
limit on the loop's candidates and a Type B term for what the poses cannot measure), and,
nothing declared, the K3 the poses do not exclude.

A cubic non-linearity K3 (u_i = k_i (x_i + K3_i x_i³), IEEE Std 1293) is odd like k: at
±1 g x³ = x, so on the six faces it is k itself (k is the 1 g chord k (1 + K3)) and only poses
with intermediate components (edges, corners) separate the two — on the paper's 14 poses
not to within the physical bound (the loop skips it), on 26 cube poses at a 0.3 mg noise
barely (user 8: K3 = 100 µg/g³ moved k by 7-8.5 of its u with no test seeing it). K2 is even:
on the faces a bias. The data alone cannot bound what they do not show; the datasheet can.

Declared (``--nonlinearity-bound K2,K3`` in µg/g², µg/g³; ``[calibration]
k2_bound_ug_per_g2``, ``k3_bound_ug_per_g3``):

1. the loop refuses a K2 or K3 candidate beyond the declared bound (it replaces the default
   physical prior, :func:`align.calibration.model.prior_bound`, for that term; K3 is then
   also tried only where the poses measure it to a third of the declared bound);
2. a declared term the loop did not add is carried in u: K_a uniform over ±bound on each
   axis a, independently (GUM 4.3.7), and propagated exactly through the fit. A reading's
   relative change from K_n is ε_pa = K_a x_pa^(n-1) (x = u / k the axis's input [g]), so
   with G the fit's gain per relative change of each pose-axis reading
   (:func:`align.calibration.stability.stability_gain`, the known-pose fit's
   ``scale_gain``) parameter j moves by S_ja K_a, S_ja = Σ_p G_j,3p+a x_pa^(n-1), and the
   term is S diag(bound² / 3) Sᵀ — ``nonlinearity_bound`` in ``u_widening``. An added term
   carries its own u in the fit's covariance.

Nothing declared (:func:`unexcluded_k3`):

* where the poses cannot separate K3 from k at all (the known-pose route: k is the 1 g
  chord k (1 + K3); the loop skipped it — the paper's 14 poses, u(K3) beyond a third of its
  physical bound: k lies between that chord and the linear coefficient, :data:`FACES_WHY`)
  u is unchanged and the result says so once (JSON ``nonlinearity``, a line under the
  calibration table), naming the flag;
* where the loop tried K3 and did not add it (nor a plausible effect carried it) but the
  poses measure it only weakly — the free-K3 fit would move a scale factor by more than
  :data:`MOVES_K` of its noise u (26 cube poses: ×3 at any noise, a design's property; user
  8's K3 = 100 µg/g³ there: a χ² drop of 5-9 in half the tumbles, k 7.4-9.1 u off, no test
  at a 1 % false-alarm rate can see it) — u carries it: the free-K3 fit is an alternative
  the parameters are averaged over (its shift of the nine core parameters as a rectangular
  half-width, plus its covariance beyond the chosen fit's, as a plausible effect's), the
  term ``k3_not_excluded`` in ``u_widening`` per parameter, K3 in ``nonlinearity.carried``
  and the statement under the table. It is the design's, true of every clean tumble on such
  poses: stated, not a warning (alone it raises none); a declared bound replaces it;
* where the free fit does not determine K3 (its term beyond
  :data:`~align.calibration.widen.USEFUL_FACTOR` of k's noise u: the 28-pose plan, the
  Xsens recording) it is not carried and the statement says k is the linear coefficient at
  K3 = 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from align.calibration.effects import K3, NONLIN
from align.calibration.model import CalibrationStage
from align.calibration.widen import RECTANGULAR, USEFUL_FACTOR, Alternative, positive_part
from align.errors import InputError
from align.loop import Candidate, LoopReport, bic
from align.loop.fit import StageFit, Term

BOUND = "nonlinearity_bound"
"""The term's name in ``u_widening``."""
UNEXCLUDED = "k3_not_excluded"
"""The term's name in ``u_widening`` for a K3 the loop tried and did not add that the poses
do not exclude (nothing declared)."""
MOVES_K = 1.0
"""That K3 is carried where it moves a scale factor by more than this many of the scale
factor's noise u (its term's u beside the noise's; 26 cube poses: ×3-7) and at most
:data:`~align.calibration.widen.USEFUL_FACTOR` of it: beyond, the free fit does not determine
K3 on these poses (the 28-pose plan: its K3 correlated ±1 over the axes, u(k) ×1e3, while a
K3 along that direction rendered at twice its u leaves χ² 111 on 19 dof without the
candidate — the linear covariance is not what the data exclude there): not carried, stated."""
UG = 1e-6
"""A declared µg/g² (µg/g³) in the model's 1/g (1/g²)."""
FLAG = "--nonlinearity-bound"
KEYS = {NONLIN: "[calibration] k2_bound_ug_per_g2", K3: "[calibration] k3_bound_ug_per_g3"}
UNITS = {NONLIN: "µg/g²", K3: "µg/g³"}
ORDER = {NONLIN: 2, K3: 3}
MAX_UG = {NONLIN: 1e4, K3: 2e3}
"""Largest bound a user may declare [µg/g², µg/g³]: the loop's physical priors
(:data:`~align.calibration.model.ATTITUDE_PRIOR_G` 1e-2 g at 1 g for K2,
:data:`~align.calibration.model.K3_PRIOR_G` 2e-3 g for K3); beyond, the triad is no
accelerometer to calibrate with a linear model."""


def bound_ug(value: object, name: str, where: str) -> float:
    """The one rule for a declared bound (the flag's and the session keys'): a finite number
    in [0, :data:`MAX_UG`] of the term's unit; :class:`InputError` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} = {value!r}: expected a number of {UNITS[name]}")
    v = float(value)
    if not math.isfinite(v) or not 0.0 <= v <= MAX_UG[name]:
        raise InputError(f"{where} = {value!r}: the {name} bound must be a number of "
                         f"{UNITS[name]} in [0, {MAX_UG[name]:g}] (the physical prior)")
    return v


def parse_flag(text: str) -> tuple[float | None, float | None]:
    """``--nonlinearity-bound K2,K3`` [µg/g², µg/g³] -> (K2 [1/g], K3 [1/g²]); an empty
    part declares nothing for that term (``,100``: K3 alone)."""
    parts = text.split(",")
    if len(parts) != 2 or not any(p.strip() for p in parts):
        raise InputError(f"{FLAG} {text!r}: give two numbers K2,K3 in µg/g² and µg/g³ "
                         "(e.g. 50,100; ,100 for K3 alone; 0 for a term the datasheet rules "
                         "out)")
    out: list[float | None] = []
    for p, name in zip(parts, (NONLIN, K3), strict=True):
        if not p.strip():
            out.append(None)
            continue
        try:
            v: object = float(p)
        except ValueError:
            v = p.strip()
        out.append(bound_ug(v, name, f"{FLAG} {name[-2:].upper()}") * UG)
    return out[0], out[1]


def session_bounds(table: dict, src: str) -> tuple[float | None, float | None] | None:
    """session.toml's ``[calibration] k2_bound_ug_per_g2`` and ``k3_bound_ug_per_g3`` ->
    (K2 [1/g], K3 [1/g²]), None where a key is absent (None: neither); ``src`` prefixes the
    keys in a refusal."""
    out = tuple(bound_ug(table[key.split()[-1]], n, src + key) * UG
                if key.split()[-1] in table else None for n, key in KEYS.items())
    return None if out == (None, None) else (out[0], out[1])


def declared_bounds(bound: tuple[float | None, float | None] | None) -> dict[str, float]:
    """The declared bounds by candidate name (K2 [1/g], K3 [1/g²]); None entries left out."""
    if bound is None:
        return {}
    return {n: float(b) for n, b in zip((NONLIN, K3), bound, strict=True) if b is not None}


def sensitivity(gain: np.ndarray, x: np.ndarray, name: str) -> np.ndarray:
    """S (n_params, 3): each parameter's change per unit of the term on each axis
    [parameter unit per 1/g^(n-1)]; ``gain`` (n_params, 3N) per relative change of each
    pose-axis reading, ``x`` (N, 3) each axis's input [g]."""
    eps = x ** (ORDER[name] - 1)  # relative change of each reading per unit of the term
    n = len(x)
    return np.stack([gain[:, 3 * np.arange(n) + a] @ eps[:, a] for a in range(3)], axis=1)


def bound_increment(gain: np.ndarray | None, x: np.ndarray, declared: dict[str, float],
                    added: Sequence[str]) -> list[tuple[str, str, np.ndarray]]:
    """The ``nonlinearity_bound`` term (term, why, covariance) for the declared terms not in
    ``added`` (none when nothing is carried)."""
    carried = {n: b for n, b in declared.items() if n not in added and b > 0}
    if gain is None or not carried:
        return []
    cov = np.zeros((gain.shape[0], gain.shape[0]))
    for name, b in carried.items():
        s = sensitivity(gain, x, name)
        cov += (s * (b / RECTANGULAR) ** 2) @ s.T
    return [(BOUND, bound_reason(carried), cov)]


def bound_reason(carried: dict[str, float]) -> str:
    """Why the term is there (``u_widening.terms`` and the warning)."""
    each = ", ".join(f"{n[-2:].upper()} within ±{b / UG:g} {UNITS[n]}"
                     for n, b in carried.items())
    return (f"non-linearity declared ({each}), not fitted on these poses: carried as a "
            "uniform Type B term through each parameter's sensitivity to it")


FACES_WHY = "at ±1 g x³ = x"
"""Why the six faces cannot separate K3: there k is exactly the 1 g chord. Elsewhere (the
paper's 14 poses: faces and corners, x³ = x/3 at a corner) k lies between the chord and the
linear coefficient (user 8's K3 = ±100 µg/g³: 4.1 u from the chord, 11.5 u from the linear
coefficient at most, ``benchmarks/calibration_k3.py``)."""


def nonlinearity_statement(declared: dict[str, float], added: Sequence[str],
                           k3_separable: bool, why_not: str = FACES_WHY,
                           weak: Unexcluded | None = None) -> dict:
    """The JSON ``nonlinearity`` record: the declared bounds [µg/g², µg/g³] (null: not
    declared), the terms carried in u (``weak``: K3 not excluded, :func:`unexcluded_k3`),
    whether the poses separate K3 from k (``why_not``: why not, in the statement), and the
    statement printed under the table ("" when there is nothing to say)."""
    carried = [n for n, b in declared.items() if n not in added and b > 0]
    if weak is not None and weak.carried:
        carried.append(K3)
    if declared:
        why = ("declared " + ", ".join(f"{n[-2:].upper()} within ±{b / UG:g} {UNITS[n]}"
                                       for n, b in declared.items())
               + (f"; carried in u ({BOUND}): {', '.join(carried)}" if carried else
                  "; fitted by the loop where added"))
    elif weak is not None and weak.carried:
        why = (f"K3 not added, not excluded by these poses: carried in u ({UNEXCLUDED}: k "
               f"moves by up to {weak.moves:.2g} of its noise u); declare the datasheet's "
               f"bound with {FLAG} K2,K3 or {KEYS[K3]} to carry that instead")
    elif weak is not None:
        why = (f"K3 not added and not determined by these poses (fitted, it would leave u of "
               f"k x{weak.moves:.2g}): k is the linear coefficient at K3 = 0; declare the "
               f"datasheet's bound with {FLAG} K2,K3 or {KEYS[K3]} to carry it in u")
    elif not k3_separable:
        what = ("k is the 1 g chord k (1 + K3)" if why_not == FACES_WHY else
                "k lies between the linear coefficient and the 1 g chord k (1 + K3)")
        why = (f"K3 is not separable from k on these poses ({why_not}): {what}; declare "
               f"the datasheet's bound with {FLAG} K2,K3 or {KEYS[K3]} to carry it in u")
    else:
        why = ""
    return {"k2_bound_ug_per_g2": declared[NONLIN] / UG if NONLIN in declared else None,
            "k3_bound_ug_per_g3": declared[K3] / UG if K3 in declared else None,
            "carried": carried, "k3_separable": bool(k3_separable), "statement": why}


@dataclass(frozen=True)
class Unexcluded:
    """K3 the loop tried and did not add, not excluded by the poses: the free-K3 fit as
    the alternative the parameters are averaged over (:data:`UNEXCLUDED`).

    Attributes
    ----------
    alternative : Alternative
        The free-K3 fit's shift of the nine core parameters and its excess covariance.
    k3, u : numpy.ndarray
        The free fit's K3 per axis and its u [1/g²].
    moves : float
        The term's largest u of a scale factor over that scale factor's noise u — ratio.
    """

    alternative: Alternative
    k3: np.ndarray
    u: np.ndarray
    moves: float

    @property
    def carried(self) -> bool:
        """Whether u carries it (:data:`MOVES_K` < moves <= ``USEFUL_FACTOR``)."""
        return bool(self.moves <= USEFUL_FACTOR)

    def reason(self) -> str:
        """Why u was widened (``u_widening.terms`` and the warning)."""
        each = ", ".join(f"{v / UG:+.0f} ± {u / UG:.0f}" for v, u in zip(self.k3, self.u,
                                                                        strict=True))
        return (f"K3 not excluded by these poses (tried, not added; the free fit's K3 x, y, "
                f"z = {each} µg/g³): k moves with it by up to {self.moves:.2g} of its noise "
                "u, so u covers the parameters' spread over the fits with and without it "
                f"(declare the datasheet's bound with {FLAG} ,K3 to carry that instead)")

    def term(self, n_params: int) -> np.ndarray:
        """The covariance: the free fit's shift of the nine core parameters as a
        rectangular half-width, plus its covariance beyond the chosen fit's."""
        out = np.zeros((n_params, n_params))
        a = self.alternative
        out[:9, :9] = np.outer(a.shift, a.shift) / RECTANGULAR**2 + a.excess
        return out


def unexcluded_k3(stage: CalibrationStage, rep: LoopReport, candidates: Sequence[Candidate],
                  guard: Callable[[StageFit, StageFit, Term], str | None],
                  carried: Sequence[str]) -> Unexcluded | None:
    """K3 carried in u where nothing bounds it and the poses measure it only weakly.

    The loop's K3 test sees K3 only as far as its columns differ from k's; on 26 cube poses
    at user 8's noise 100 µg/g³ is a noncentrality of ~14 on 3 degrees of freedom (found in
    ~40 % of tumbles) and moves k by 7-8.5 of its u. No test on the data can tell such a K3
    from none at a 1 % false-alarm rate, so whether it is carried is the design's question:
    the free-K3 fit (the loop's last round plus K3, within the physical guard) is an
    alternative the parameters are averaged over (as :mod:`align.calibration.unproven`'s:
    its shift as a rectangular half-width plus its own covariance beyond the chosen fit's),
    carried where it moves a scale factor by more than :data:`MOVES_K` of its noise u.

    None where K3 was added, skipped (not separable: the statement says so), not a
    candidate, declared (:func:`bound_increment` carries it), already in ``carried`` (a
    plausible effect) or beyond the physical guard.

    Raises
    ------
    NotApplicable
        The loop had not fitted K3 and its fit here finds that these poses cannot measure
        it (the reason: not separable, :func:`k3_separability`).
    """
    names = tuple(t.name for t in rep.terms)
    cand = next((c for c in candidates if c.name == K3), None)
    if (cand is None or K3 in names or K3 in stage.bounds or K3 in carried
            or any(s.name == K3 for s in rep.skipped)):
        return None
    key = (*names, K3)
    if key not in stage.fits:
        term = cand.build(rep.after)
        if term is None:
            return None
        try:
            stage.fit([*rep.terms, term])
        except np.linalg.LinAlgError:
            return None  # not applicable to these poses (as in the loop)
    trial, terms = stage.fits[key]
    if guard(rep.after, trial, terms[-1]) is not None:
        return None
    final, free = rep.after.payload, trial.payload
    shift = _core(free) - _core(final)
    excess = positive_part(np.asarray(free.cov, float)[:9, :9]
                           - np.asarray(final.cov, float)[:9, :9])
    u_k = np.sqrt(np.diag(np.asarray(final.cov, float))[:3])
    moves = float(np.max(np.sqrt(shift[:3] ** 2 / RECTANGULAR**2 + np.diag(excess)[:3])
                         / u_k))
    if not moves > MOVES_K:
        return None
    searched = sum(t.searched for t in rep.terms)
    d_bic = bic(trial, searched + terms[-1].searched) - bic(rep.after, searched)
    alt = Alternative(" + ".join(key), "", float(d_bic), float("nan"), shift, excess)
    return Unexcluded(alt, np.array(free.k3, float),
                      np.array([free.u_of(f"{K3}_{ax}") for ax in "xyz"]), moves)


def k3_separability(candidates: Sequence[Candidate], rep: LoopReport,
                    unmeasured: str | None = None) -> tuple[bool, str]:
    """Whether the poses separate K3 from k, and why not: the loop could not try it on them
    (its reason when it says more than the default; ``unmeasured``: the reason found by
    :func:`unexcluded_k3` where the loop's screen had not fitted it), else it was never a
    candidate (:data:`FACES_WHY`)."""
    skip = next((s.reason for s in rep.skipped if s.name == K3), unmeasured)
    separable = skip is None and K3 in {c.name for c in candidates}
    return separable, (FACES_WHY if skip is None else "the poses cannot determine it"
                       if skip == "does not apply to these data" else skip)


def _core(m) -> np.ndarray:
    return np.concatenate([m.k, m.beta, m.bias])
