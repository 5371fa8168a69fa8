"""The candidates the fusion carries as not excluded, as ``align plan`` predicts them after a
measurement (:func:`predict`).

The fusion carries a candidate it tested but could not exclude as a Type B term in E's u
(:mod:`align.fusion.plausible`) and keeps its Jacobian in the budget's linearisation, held at
zero (``Linearisation.held``). Freed there, it moves E by k b̂ and lowers χ² by b̂ᵀ Σ_bb⁻¹ b̂;
after a measurement k and Σ_bb are those of the new information, and the new estimate is a
draw about the one now: in each draw the fusion's own rules (``judge``) and the loop's
test decide whether the candidate is carried, named or dropped (docs/decision.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import)

from align.fusion.budget import Group, Linearisation, inverse
from align.fusion.observations import E_NAMES, LEVEL, REF, ROLL, TILT
from align.fusion.plausible import NOT_EXCLUDED, UNDETERMINED, judge
from align.fusion.undetermined import Undetermined, carried_variance, default_sigma, freed_u
from align.loop import sidak
from axisbase.units import ARCSEC

# The default of ``declared``: read-only (one object shared by every call).
NONE_DECLARED: Mapping[str, float] = MappingProxyType({})

RESOLVES = {
    ROLL: "a reversed view of that camera (the platform turned 180° on the table), or its "
          "roll calibrated",
    LEVEL: "levelled static poses with the platform inverted (Z down) as well as Z up, or "
           "camera views of E_xZ, E_yZ: they separate the levelling from E",
    TILT: "levelled static poses at more table angles (the table's tilt turns with it, the "
          "platform's axes do not)",
    REF: "a goniometer log with the reference face's offset known (declared in session.toml)",
}
"""What separates each kind of candidate from E when no measurement of the plan's kinds
does (by the observation equations, align/fusion/observations.py); unit —."""


@dataclass(frozen=True)
class Carried:
    """A candidate E's u carries as not excluded (:mod:`align.fusion.plausible`), as the
    linearisation predicts it for some data.

    Attributes
    ----------
    name : str
        The candidate (``platform_level``, ``camera_roll[A]``); unit —.
    estimate, u : float
        Its size when freed and that size's u [rad].
    shift : tuple of float
        The shift of the six angles (``E_NAMES``) when it is freed: its Type B share of u² is
        its square [rad].
    p : float
        The probability that the fusion carries it (its estimate on the new data a new draw
        about the one now, :func:`predict`); 1 for the session's own data — dimensionless.
    named : float
        The probability that the new data make it significant at the loop's level: named, E
        corrected for it, its share of u² that of freeing it — dimensionless.
    share : tuple of float
        Its expected share of u² of the six angles (``shift²`` × carried, over the draws)
        [rad²].
    """

    name: str
    estimate: float
    u: float
    shift: tuple[float, ...]
    p: float = 1.0
    share: tuple[float, ...] = (0.0,) * 6
    named: float = 0.0

    def to_dict(self) -> dict:
        return {"name": self.name, "estimate_arcsec": self.estimate / ARCSEC,
                "u_arcsec": self.u / ARCSEC, "p_carried": self.p,
                "shift_arcsec": dict(zip(E_NAMES, (v / ARCSEC for v in self.shift),
                                         strict=True))}

    @property
    def label(self) -> str:
        return f"{self.name} not excluded ({self.estimate / ARCSEC:+.1f} ± {self.u / ARCSEC:.1f}″)"


NAMED_ALPHA = 1e-3
"""The fusion loop's level (``align.fusion.fuse``'s ``alpha``): a candidate whose χ² drop
passes it (Šidák over ``NAMED_TESTED`` candidates) and lowers BIC by ``NAMED_MIN_BIC`` is
named, not carried — dimensionless."""
NAMED_TESTED = 5
"""Candidates a fusion round tests (two cameras' rolls, the reference face's offset, the
table's tilt, the platform's levelling) — dimensionless."""
NAMED_MIN_BIC = 6.0
"""The loop's least BIC drop (``run_loop``'s ``min_delta_bic``) — dimensionless."""
REDRAWS = 256
"""Draws of a carried candidate's estimate on the new data (:func:`predict`): the share's
mean to ~3 % of itself at p = 0.5, fixed (seed 0) so that a plan is reproducible."""


@dataclass(frozen=True)
class Prediction:
    """u of the six angles as the fusion would state them after a measurement.

    Attributes
    ----------
    u : numpy.ndarray
        The expected u (√ of the expected u²) of the six angles, ``E_NAMES`` order [rad].
    u_sd : numpy.ndarray
        The standard deviation of that u over the draws of the carried candidates' new
        estimates [rad] (0 without carried candidates).
    carried : tuple of Carried
        The session's carried candidates with the probability each stays carried; unit —.
    ranged : tuple of Undetermined
        The session's undetermined nuisances (``Linearisation.ranged``) the fusion would
        still carry over their plausible range, with their u freed and E shift after the
        measurement (:func:`ranged_after`); unit —.
    """

    u: np.ndarray
    u_sd: np.ndarray
    carried: tuple[Carried, ...]
    ranged: tuple[Undetermined, ...] = ()

    def still(self, name: str) -> bool:
        """Whether ``name`` is more likely carried than not after the measurement."""
        return any(c.name == name and c.p >= 0.5 for c in self.carried)


def _named(drop: float, tested: float, width: int, n_rows: int) -> bool:
    """Whether the fusion loop would name a candidate whose freeing lowers χ² by ``drop``
    (``width`` components, ``n_rows`` observations; ``tested``: the drop its test sees, on
    the χ²(``width``) scale): its test at the loop's level after Šidák over the round's
    candidates, and its BIC drop."""
    return bool(sidak(float(special.chdtrc(width, tested)), NAMED_TESTED) < NAMED_ALPHA
                and drop - width * np.log(n_rows) > NAMED_MIN_BIC)


def _with_declared(info: np.ndarray, free: Sequence[int], idx: Sequence[int], b: np.ndarray,
                   declared: Sequence[tuple[Sequence[int], Sequence[float]]]) -> np.ndarray:
    """Candidate ``b`` [rad] (parameters ``idx``) estimated with each ``declared`` candidate
    (its indices, its value [rad]) fixed at its value instead of 0: with the ``free``
    parameters marginalised (the Schur complement M of ``info``), b(r) = b(0) − M_bb⁻¹ M_br r."""
    for didx, value in declared:
        j = [*free, *idx, *didx]
        n, w = len(free), len(idx)
        Ij = info[np.ix_(j, j)]
        M = Ij[n:, n:] - Ij[n:, :n] @ np.linalg.solve(Ij[:n, :n], Ij[:n, n:])
        b = b - np.linalg.solve(M[:w, :w], M[:w, w:] @ np.asarray(value))
    return b


def sigmas(lin: Linearisation, declared: Mapping[str, float] = NONE_DECLARED
           ) -> dict[str, float]:
    """The σ of the plausible range [rad] of each candidate that has one: ``declared`` (a
    camera's roll calibrated: its calibration's u), else as the fusion had it (declared in
    session.toml or the default, ``Linearisation.ranges``; a result written before those:
    the undetermined ones' and the default)."""
    out = {n: s for n, s in ((n, default_sigma(n)) for n in _names(lin)) if s is not None}
    out |= {n: s for n, _, s in lin.ranged} | dict(lin.ranges) | dict(declared)
    return out


def _names(lin: Linearisation) -> list[str]:
    """Every candidate the loop did not add (carried, undetermined, the others)."""
    return [n for n, *_ in (*lin.held, *lin.ranged, *lin.others)]


def _columns(lin: Linearisation) -> dict[str, tuple[int, ...]]:
    return {n: tuple(idx) for n, idx, *_ in (*lin.held, *lin.ranged, *lin.others)}


def freed_beside(lin: Linearisation, info: np.ndarray, named: Sequence[str] = ()
                 ) -> dict[str, tuple[float, np.ndarray]]:
    """Each one-column candidate not in ``named`` freed alone beside the estimated parameters
    and the candidates ``named`` (the loop's model after a measurement), with information
    ``info`` (over every parameter): its u freed [rad] (inf: not separable) and its E shift
    per unit k = dE/db — as :func:`align.fusion.undetermined.undetermined` frees it."""
    cols = _columns(lin)
    base = [*lin.free, *(i for n in named for i in cols[n])]
    I_ff = info[np.ix_(base, base)]
    out = {}
    for name, idx in cols.items():
        if name in named or len(idx) != 1:
            continue  # (a vector nuisance has no range: the fusion carries none for it)
        col = info[base, idx[0]]
        k = np.linalg.lstsq(I_ff, col, rcond=None)[0]
        out[name] = (freed_u(float(info[idx[0], idx[0]] - col @ k),
                             float(info[idx[0], idx[0]]), lin.inflation), k[:6])
    return out


def ranged_after(lin: Linearisation, info: np.ndarray,
                 declared: Mapping[str, float] = NONE_DECLARED, named: Sequence[str] = ()
                 ) -> tuple[Undetermined, ...]:
    """The candidates the fusion would carry over their plausible range with information
    ``info`` (over every parameter) and the loop's model with the candidates ``named`` — every
    candidate with a range (:func:`sigmas`; one ``declared``, calibrated, with its
    calibration's u as its range), freed alone beside the model (:func:`freed_beside`) and
    judged by the fusion's rule (:func:`align.fusion.plausible.judge`, undetermined first):
    its u freed u_f, and its share σ² u_f²/(σ² + u_f²) k kᵀ; none when the new data determine
    it (u_f ≤ σ: the loop's tests judge it, and a candidate the loop did not name is taken
    as not named after)."""
    sig = sigmas(lin, declared)
    out = []
    for name, (u_f, k) in freed_beside(lin, info, named).items():
        s = sig.get(name)
        if judge(u_f, s) == UNDETERMINED:
            out.append(Undetermined(name, s, float(u_f), k * np.sqrt(carried_variance(s, u_f)),
                                    name in declared))
    return tuple(out)


def predict(lin: Linearisation, add: Sequence[Group] = (), drop: Sequence[str] = (),
            redraw: bool = True, declared: Mapping[str, float] = NONE_DECLARED) -> Prediction:
    """u of the six angles as the fusion would state them with the groups named in ``drop``
    left out and ``add`` added, and the candidates it would carry.

    Each candidate the session's fusion carries (``lin.held``) is freed in the linearisation:
    with (E, b) of covariance Σ, freeing b moves E by k b̂ (k = Σ_Eb Σ_bb⁻¹) and lowers χ² by
    b̂ᵀ Σ_bb⁻¹ b̂. The new estimate b̂' is not known before the data are taken: it is drawn
    about b̂ with the covariance of b̂ − b̂' — the added data's draw, the dropped (replaced)
    data's, and the change of the kept data's weights (for data only added: Σ_bb − Σ'_bb;
    ``redraw`` False: b̂' = b̂). In each draw the candidate is named when the loop's test
    would take it (:func:`_named`; its share of u² then what freeing it adds). Then, in each
    draw, every candidate the loop did not name there — carried, undetermined or neither
    before — is judged beside the model with the ones it named, by the fusion's rules in the
    fusion's order (:func:`align.fusion.plausible.judge`): undetermined (u freed beyond its
    range's σ, declared or default: carried over that range, :func:`ranged_after`), else, for
    a carried one, not excluded (its share (k b̂')²), else dropped; u² is the fixed model's
    plus the mean share. New data that separate b from E shrink k: the shift falls below u/2
    and the term drops; an effect named beside a near-degenerate candidate leaves that one
    undetermined (freed beside the levelling, camera B's roll at 4549″ > σ 34.6″). A
    candidate more likely named than not is in the model against which the less significant
    ones' estimates are drawn (the loop adds the best first), as is one ``declared`` (a
    camera's roll calibrated, name -> its calibration's u [rad]: no longer a candidate, E
    corrected for it at its estimate; judged over the calibration's u as its range) — what
    it absorbed is no longer left for the others, whose estimates move with it
    (:func:`_with_declared`)."""
    kept = [g for g in lin.groups if g.source not in drop]
    infos = (lin.information([*kept, *add]), lin.information(), lin.information(kept),
             lin.information(add))
    free = list(lin.free)
    n_rows = sum(len(g.A) for g in [*kept, *add])
    # (the carried candidates are judged against u without the ranged terms, as the fusion
    # judges them before it adds those)
    u2 = np.diag(inverse(infos[0][np.ix_(free, free)]))[:6] * lin.inflation**2
    fixed = [(i, e) for n, i, e, _ in lin.held if n in declared]
    own = not add and not drop  # the session's own data: the fusion decided (not re-judged)
    held = []
    for name, idx, est, p_loop in sorted((h for h in lin.held if h[0] not in declared),
                                         key=lambda h: h[3]):
        # what the session's data left for it once the others are in the model
        d = _draw(infos, free, idx, _with_declared(infos[1], free, idx, np.array(est), fixed),
                  p_loop, n_rows, redraw, own, lin.inflation)
        held.append((name, d))
        if d.named.mean() >= 0.5:
            fixed.append((idx, est))
    named = [frozenset(n for n, d in held if d.named[r]) for r in range(REDRAWS)]
    sig = sigmas(lin, declared)
    # the session's own data: the fusion decided which it carries over their range
    keep = {n for n, *_ in lin.ranged} if own else set(_columns(lin))
    beside = {s: (freed_beside(lin, infos[0], sorted(s)),
                  {r.name: r for r in ranged_after(lin, infos[0], declared, sorted(s))
                   if r.name in keep})
              for s in set(named)}
    share = np.zeros((REDRAWS, 6))
    hits = {n: np.zeros(REDRAWS, bool) for n, _ in held}
    ranged_share: dict[str, np.ndarray] = {}
    ranged_of: dict[str, Undetermined] = {}
    u_e = np.sqrt(u2)
    for r, s in enumerate(named):
        freed, unknown = beside[s]
        for name, d in held:
            if name in s:
                share[r] += d.freed
                continue
            x = d.draws[r]
            u_f = freed.get(name, (0.0, None))[0]
            verdict = judge(u_f, sig.get(name), d.chi[r], len(x), d.size(x), d.K @ x, u_e)
            if own:  # the fusion carried it (judged beside its own model, not re-judged)
                verdict = NOT_EXCLUDED
            if verdict == NOT_EXCLUDED:
                hits[name][r] = True
                share[r] += np.square(d.K @ x)
        for name, und in unknown.items():
            share[r] += np.square(und.shift)
            ranged_share.setdefault(name, np.zeros(REDRAWS))[r] = 1.0
            ranged_of.setdefault(name, und)
    out = []
    for name, d in held:
        mine = np.where(np.array([name in s for s in named])[:, None], d.freed, 0.0) + np.where(
            hits[name][:, None], np.square(d.draws @ d.K.T), 0.0)
        out.append(Carried(name, d.size(d.b), float(np.sqrt(d.g @ d.Cbb @ d.g)),
                           tuple(d.K @ d.b), float(hits[name].mean()), tuple(mine.mean(0)),
                           float(d.named.mean())))
    # an undetermined nuisance more likely carried than not, with its expected share
    ranged = []
    for name, und in ranged_of.items():
        sh = np.sqrt(np.mean([np.square(beside[s][1][name].shift) if name in beside[s][1]
                              else np.zeros(6) for s in named], axis=0))
        if ranged_share[name].mean() >= 0.5:  # (its expected share: the sign of one)
            ranged.append(replace(und, shift=sh * np.where(und.shift < 0, -1.0, 1.0)))
    u = np.sqrt(u2 + share)
    order = [h[0] for h in lin.held]
    return Prediction(np.sqrt(u2 + share.mean(0)), u.std(0),
                      tuple(sorted(out, key=lambda c: order.index(c.name))), tuple(ranged))


@dataclass(frozen=True)
class _Draws:
    """One held candidate's draws of its estimate on the new data (:func:`_draw`)."""

    b: np.ndarray         # its estimate now [rad]
    draws: np.ndarray     # its estimate on the new data, REDRAWS × width [rad]
    chi: np.ndarray       # the χ² drop of freeing it, per draw
    named: np.ndarray     # whether the loop names it, per draw
    K: np.ndarray         # dE/db, 6 × width
    Cbb: np.ndarray       # its covariance freed [rad²]
    freed: np.ndarray     # what naming it adds to u² of the six angles [rad²]

    @property
    def g(self) -> np.ndarray:
        size = float(np.linalg.norm(self.b))
        return self.b / size if size > 0 else np.full(len(self.b), np.sqrt(1.0 / len(self.b)))

    def size(self, x: np.ndarray) -> float:
        """Its size: one component's signed value, a vector's length [rad]."""
        return float(x[0]) if len(x) == 1 else float(np.linalg.norm(x))


def _draw(infos: tuple[np.ndarray, ...], free: list[int], idx: Sequence[int], b: np.ndarray,
          p_loop: float, n_rows: int, redraw: bool, own: bool, inflation: float) -> _Draws:
    """One held candidate (parameters ``idx``, estimate ``b`` [rad], the loop's p-value now
    ``p_loop``) after the measurement (``infos``: the information after, now, of the kept
    groups, of the added ones): its estimate's draws on the new data and, in each, whether
    the loop names it."""
    info, info_now, info_kept, info_add = infos
    j, n = [*free, *idx], len(free)
    C = inverse(info[np.ix_(j, j)])
    Cbb = C[n:, n:]
    K = C[:6, n:] @ np.linalg.inv(Cbb)
    # b̂ = Σ_b Σ_g A_gᵀ C_g⁻¹ y_g: the kept data's gain changes, the rest are new draws
    ix = np.ix_(j, j)
    S0, S1 = inverse(info_now[ix])[n:], C[n:]
    d = ((S0 - S1) @ info_kept[ix] @ (S0 - S1).T
         + S0 @ (info_now - info_kept)[ix] @ S0.T + S1 @ info_add[ix] @ S1.T)
    w, v = np.linalg.eigh((d + d.T) / 2 if redraw else 0 * d)
    z = np.random.default_rng(0).standard_normal((REDRAWS, len(b)))
    draws = b + z @ (v * np.sqrt(np.clip(w, 0.0, None))).T
    chi = np.einsum("ij,ij->i", draws, np.linalg.solve(Cbb, draws.T).T)
    # the loop's test is not χ²(w) on the drop (it divides by the fit's χ²/dof, its
    # weights are estimated): its p-value now fixes the scale of the drop it sees
    now_drop = float(b @ np.linalg.solve(S0[:, n:], b))
    scale = max(1.0, now_drop / float(special.chdtri(len(idx), max(p_loop, 1e-300))))
    named = np.array([_named(c, c / scale, len(idx), n_rows) for c in chi])
    if own:
        named[:] = False
    return _Draws(b, draws, chi, named, K, Cbb, np.diag(K @ Cbb @ K.T) * inflation**2)
