"""The candidates the fusion carries as not excluded, as ``align plan`` predicts them after a
measurement (:func:`predict`).

The fusion carries a candidate it tested but could not exclude as a Type B term in E's u
(:mod:`align.fusion.plausible`) and keeps its Jacobian in the budget's linearisation, held at
zero (``Linearisation.held``), beside the undetermined ones' (``ranged``) and the loop's other
candidates' (``others``). Freed there, the carried ones move E by k b̂ and lower χ² by
b̂ᵀ Σ_bb⁻¹ b̂; after a measurement k and Σ_bb are those of the new information, and their new
joint estimate is a draw about the one now: in each draw the loop's test names some, and the
fusion's own rules, in its order and by its functions (:func:`align.fusion.plausible.judge`,
``in_place_of``, ``largest``), judge every other candidate beside the named ones:
undetermined, not excluded, or dropped (docs/decision.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import)

from align.fusion.budget import Group, Linearisation, inverse
from align.fusion.observations import E_NAMES, LEVEL, REF, ROLL, TILT
from align.fusion.plausible import NOT_EXCLUDED, UNDETERMINED, in_place_of, judge, largest
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
DRAW_PRIOR_ARCSEC = 60.0 / np.sqrt(3.0)
"""The σ [″] of the prior the draws of a held candidate without a plausible range (the
platform's levelling, the table's tilt) are taken with (:func:`predict`): the default range
of a camera's roll, a set-up error of the same kind. A prior of the draws only: the fusion
has none, and the draws' estimates are judged without it."""
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
    as not named after). Each says whether its range is declared (``declared``, or in
    session.toml: ``Linearisation.declared``) as the fusion's own warning says it."""
    sig = sigmas(lin, declared)
    out = []
    for name, (u_f, k) in freed_beside(lin, info, named).items():
        s = sig.get(name)
        if judge(u_f, s) == UNDETERMINED:
            out.append(Undetermined(name, s, float(u_f), k * np.sqrt(carried_variance(s, u_f)),
                                    name in declared or name in lin.declared))
    return tuple(out)


def _schur(info: np.ndarray, free: Sequence[int], idx: Sequence[int]) -> np.ndarray:
    """The information on parameters ``idx`` with the ``free`` ones marginalised."""
    free, idx = list(free), list(idx)
    I_ff = info[np.ix_(free, free)]
    return info[np.ix_(idx, idx)] - info[np.ix_(idx, free)] @ np.linalg.solve(
        I_ff, info[np.ix_(free, idx)])


def _gain(info: np.ndarray, free: Sequence[int], idx: Sequence[int]) -> np.ndarray:
    """dE/db of each parameter ``idx`` held at b beside the ``free`` ones (6 × len(idx)):
    E's change when it is freed to b̂ is this times b̂."""
    free = list(free)
    return -np.linalg.solve(info[np.ix_(free, free)], info[np.ix_(free, list(idx))])[:6]


def _joint_draws(infos: tuple[np.ndarray, ...], free: list[int], idx: Sequence[int],
                 b: np.ndarray, redraw: bool) -> np.ndarray:
    """``REDRAWS`` draws [rad] of the joint estimate of parameters ``idx`` on the new data
    about ``b`` (``infos``: the information after, now, of the kept groups, of the added
    ones): b̂ = Σ_b Σ_g A_gᵀ C_g⁻¹ y_g, the kept data's gain changes, the rest are new
    draws."""
    info, info_now, info_kept, info_add = infos
    j, n = [*free, *idx], len(free)
    ix = np.ix_(j, j)
    S0, S1 = inverse(info_now[ix])[n:], inverse(info[ix])[n:]
    d = ((S0 - S1) @ info_kept[ix] @ (S0 - S1).T
         + S0 @ (info_now - info_kept)[ix] @ S0.T + S1 @ info_add[ix] @ S1.T)
    w, v = np.linalg.eigh((d + d.T) / 2 if redraw else 0 * d)
    z = np.random.default_rng(0).standard_normal((REDRAWS, len(b)))
    return b + z @ (v * np.sqrt(np.clip(w, 0.0, None))).T


def _size(x: np.ndarray) -> float:
    """A candidate's size: one component's signed value, a vector's length [rad]."""
    return float(x[0]) if len(x) == 1 else float(np.linalg.norm(x))


def predict(lin: Linearisation, add: Sequence[Group] = (), drop: Sequence[str] = (),
            redraw: bool = True, declared: Mapping[str, float] = NONE_DECLARED) -> Prediction:
    """u of the six angles as the fusion would state them with the groups named in ``drop``
    left out and ``add`` added, and the candidates it would carry.

    The candidates the session's fusion carries (``lin.held``) are freed together in the
    linearisation: their joint estimate b̂ (from each one's estimate freed alone: b̂ = M⁻¹ r,
    r_c = M_cc b̂_c, M their information with the estimated parameters marginalised) is not
    known on the new data before they are taken; it is drawn about b̂ with the covariance of
    b̂ − b̂' — the added data's draw, the dropped (replaced) data's, and the change of the kept
    data's weights (``redraw`` False: b̂' = b̂). In each draw the loop is replayed on
    r' = M' b̂' (M' after the measurement): it names the most significant candidate while its
    test passes (:func:`_named`; the drop scaled as the loop's own test sees it now, from
    ``loop_p``). Then every candidate it did not name — carried, undetermined or neither
    before — is judged beside the model with the named ones by the fusion's rules in the
    fusion's order: undetermined (:func:`align.fusion.plausible.judge`: its u freed beyond
    its range's σ, declared or default; carried over that range, :func:`ranged_after`), else
    not excluded — freed beside the model (``judge``) or in place of a named effect
    (:func:`align.fusion.plausible.in_place_of`), its larger shift
    (:func:`align.fusion.plausible.largest`) —, else dropped. u² is the model's (the named
    freed) plus the mean of the draws' shares. A ``declared`` candidate (a camera's roll
    calibrated, name -> its calibration's u [rad]) is no longer one: E corrected for it, the
    others' estimates with it fixed at its joint estimate, and judged over the calibration's
    u as its range."""
    kept = [g for g in lin.groups if g.source not in drop]
    infos = (lin.information([*kept, *add]), lin.information(), lin.information(kept),
             lin.information(add))
    info = infos[0]
    free = list(lin.free)
    n_rows = sum(len(g.A) for g in [*kept, *add])
    own = not add and not drop  # the session's own data: the fusion decided (not re-judged)
    # the joint estimate now from each one's estimate alone (the declared ones too)
    owner = [n for n, idx, *_ in lin.held for _ in idx]
    every = [i for _, idx, *_ in lin.held for i in idx]
    est = np.array([v for *_, e, _ in lin.held for v in e], float)
    M0 = _schur(infos[1], free, every)
    r0 = np.array([M0[j, [m for m, o in enumerate(owner) if o == owner[j]]]
                   @ est[[m for m, o in enumerate(owner) if o == owner[j]]]
                   for j in range(len(owner))])
    # Near-degenerate candidates (a roll and the levelling both +20″) have a joint estimate
    # of thousands of ″ ± thousands: the draws are taken with each candidate's plausible
    # range as a prior (``DRAW_PRIOR_ARCSEC`` where it has none), the fusion's estimates in
    # each draw without it.
    # (a ``declared`` one is drawn too, with its calibration among the added data, and the
    # others' estimates are then those with it fixed at its draw)
    rng = sigmas(lin)
    prior = np.zeros(len(lin.params))
    for i, o in zip(every, owner, strict=True):
        prior[i] = rng.get(o, DRAW_PRIOR_ARCSEC * ARCSEC) ** -2
    P = np.diag(prior)
    b_all = (np.linalg.solve(M0 + P[np.ix_(every, every)], r0) if len(every) else est)
    held = [h for h in lin.held if h[0] not in declared]
    names = [h[0] for h in held]
    pos, at = {}, 0  # each held candidate's positions in the joint vector
    for n, idx, *_ in held:
        pos[n] = list(range(at, at + len(idx)))
        at += len(idx)
    H = [i for _, idx, *_ in held for i in idx]
    mine_ = [j for j, o in enumerate(owner) if o not in declared]
    draws = _joint_draws((infos[0] + P, infos[1] + P, infos[2] + P, infos[3]), free, every,
                         b_all, redraw)[:, mine_]
    M = _schur(info, free, H)
    r = draws @ (M + P[np.ix_(H, H)])  # the data's part of each draw's estimate
    G = _gain(info, free, H)  # E's change per unit of each candidate freed
    scale = {}
    M_now = _schur(infos[1], free, H)
    for n, idx, e, p_loop in held:
        s = np.ix_(pos[n], pos[n])
        now_drop = float(np.asarray(e) @ M_now[s] @ np.asarray(e))
        tested = float(special.chdtri(len(idx), max(p_loop, 1e-300)))
        # (p 1: a candidate the fusion could not free beside its model, whose loop test saw
        # no drop — the replay never names it, rather than dividing by that zero)
        scale[n] = max(1.0, now_drop / tested) if tested > 0 else np.inf
    cols = {n: list(idx) for n, idx, *_ in held}
    alone = {n: e for n, _, e, _ in held}
    keep = {n for n, *_ in lin.ranged} if own else set(_columns(lin))
    models: dict[frozenset, tuple] = {}

    def model(S: frozenset) -> tuple:
        """u² of the six angles with the candidates S named; each candidate's u freed and k
        beside that model; the undetermined ones there."""
        if S not in models:
            j = free + [i for n in names if n in S for i in cols[n]]
            models[S] = (np.diag(inverse(info[np.ix_(j, j)]))[:6] * lin.inflation**2,
                         freed_beside(lin, info, sorted(S)),
                         {u.name: u for u in ranged_after(lin, info, declared, sorted(S))
                          if u.name in keep})
        return models[S]

    u2 = model(frozenset())[0]
    sig = sigmas(lin, declared)
    mine = {n: np.zeros((REDRAWS, 6)) for n in names}
    hit = {n: np.zeros(REDRAWS, bool) for n in names}
    named = {n: np.zeros(REDRAWS, bool) for n in names}
    ranged_share: dict[str, np.ndarray] = {}
    ranged_of: dict[str, Undetermined] = {}
    fits: dict[frozenset, tuple] = {}

    def fit(T: Sequence[str], k: int, of: str | None = None
            ) -> tuple[float, np.ndarray | None, np.ndarray]:
        """Draw k's χ² drop, the estimate of candidate ``of`` and E's shift with the
        candidates T freed (all draws solved at once per T)."""
        key = frozenset(T)
        if key not in fits:
            s = [i for m in names if m in key for i in pos[m]]
            bt = (np.linalg.lstsq(M[np.ix_(s, s)], r[:, s].T, rcond=None)[0].T if s
                  else np.zeros((REDRAWS, 0)))
            fits[key] = (np.einsum("ij,ij->i", r[:, s], bt), bt, bt @ G[:, s].T, s)
        chi, bt, e, s = fits[key]
        x = None if of is None else bt[k, [s.index(i) for i in pos[of]]]
        return float(chi[k]), x, e[k]

    for k in range(REDRAWS):
        S: list[str] = []
        while not own:  # the loop: the most significant first, while its test passes
            c0 = fit(S, k)[0]
            drops = {n: fit([*S, n], k)[0] - c0 for n in names if n not in S}
            if not drops:
                break
            n = min(drops, key=lambda n: special.chdtrc(len(pos[n]), drops[n] / scale[n]))
            if not _named(drops[n], drops[n] / scale[n], len(pos[n]), n_rows):
                break
            S.append(n)
        u2S, freed, unknown = model(frozenset(S))
        for n in S:  # what freeing them adds to u², shared among them
            named[n][k] = True
            mine[n][k] = (u2S - u2) / len(S)
        u_e = np.sqrt(u2S)
        c_S, _, e_S = fit(S, k)
        for n in names:
            if n in S:
                continue
            shifts = []
            if own:  # the fusion carried it (judged beside its own model, not re-judged)
                shifts = [G[:, pos[n]] @ np.asarray(alone[n])]  # its shift freed alone
            else:
                c_T, x, e_T = fit([*S, n], k, n)
                verdict = judge(freed.get(n, (0.0,))[0], sig.get(n), c_T - c_S, len(x),
                                _size(x), e_T - e_S, u_e)
                if verdict == UNDETERMINED:
                    continue  # carried over its range (in ``unknown``)
                if verdict == NOT_EXCLUDED:
                    shifts.append(e_T - e_S)
                for t in S:  # in place of a named effect, that one freed back beside it
                    c_A, xa, e_A = fit([*(m for m in S if m != t), n], k, n)
                    p = float(special.chdtrc(len(pos[t]), max(c_T - c_A, 0.0) / scale[t]))
                    if in_place_of(_size(xa), p, NAMED_ALPHA):
                        shifts.append(e_A - e_S)
            j = largest(shifts, u_e) if not own else 0
            if j is not None:
                hit[n][k] = True
                mine[n][k] = np.square(shifts[j])
        for n, und in unknown.items():
            ranged_share.setdefault(n, np.zeros((REDRAWS, 6)))[k] = np.square(und.shift)
            ranged_of.setdefault(n, und)
    share = sum((*mine.values(), *ranged_share.values()), np.zeros((REDRAWS, 6)))
    out = []
    for n, _, e, _ in held:
        s = pos[n]
        e = np.asarray(e, float)
        g = e / np.linalg.norm(e) if np.linalg.norm(e) > 0 else np.full(len(e), len(e)**-0.5)
        out.append(Carried(n, _size(e), float(np.sqrt(g @ inverse(M[np.ix_(s, s)]) @ g)),
                           tuple(G[:, s] @ e), float(hit[n].mean()), tuple(mine[n].mean(0)),
                           float(named[n].mean())))
    # an undetermined nuisance more likely carried than not, with its expected share
    ranged = tuple(replace(ranged_of[n], shift=np.sqrt(sq.mean(0)))
                   for n, sq in ranged_share.items() if np.any(sq, axis=1).mean() >= 0.5)
    order = [h[0] for h in lin.held]
    return Prediction(np.sqrt(u2 + share.mean(0)), np.sqrt(u2 + share).std(0),
                      tuple(sorted(out, key=lambda c: order.index(c.name))), ranged)
