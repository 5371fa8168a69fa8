"""The candidates the fusion carries as not excluded, as ``align plan`` predicts them after a
measurement (:func:`predict`).

The fusion carries a candidate it tested but could not exclude as a Type B term in E's u
(:mod:`align.fusion.plausible`) and keeps its Jacobian in the budget's linearisation, held at
zero (``Linearisation.held``). Freed there, it moves E by k b̂ and lowers χ² by b̂ᵀ Σ_bb⁻¹ b̂;
after a measurement k and Σ_bb are those of the new information, and the new estimate is a
draw about the one now: in each draw the fusion's own rule (``is_carried``) and the loop's
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
from align.fusion.plausible import is_carried
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


def ranged_after(lin: Linearisation, info: np.ndarray, declared: Mapping[str, float] = NONE_DECLARED
                 ) -> tuple[Undetermined, ...]:
    """The undetermined nuisances (``lin.ranged``; one ``declared``, calibrated, with its
    calibration's u [rad] as its range) the fusion would carry over their plausible range with
    information ``info`` (over every parameter): each
    freed alone beside the estimated parameters, as the fusion judges it
    (:func:`align.fusion.undetermined.undetermined`) — its u freed u_f, its E shift per unit
    k = dE/db, and its share σ² u_f²/(σ² + u_f²) k kᵀ; none when the new data determine it
    (u_f ≤ σ: the loop's tests judge it, and a nuisance the session did not name is taken as
    not named after)."""
    free = list(lin.free)
    I_ff = info[np.ix_(free, free)]
    out = []
    for name, idx, sigma in lin.ranged:
        if len(idx) != 1:
            continue
        sigma = declared.get(name, sigma)
        col = info[free, idx[0]]
        k = np.linalg.lstsq(I_ff, col, rcond=None)[0]
        u_f = freed_u(float(info[idx[0], idx[0]] - col @ k), float(info[idx[0], idx[0]]),
                      lin.inflation)
        v = carried_variance(sigma, u_f)
        if v > 0:
            out.append(Undetermined(name, sigma, float(u_f), k[:6] * np.sqrt(v),
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
    would take it (:func:`_named`; its share of u² then what freeing it adds), else carried
    when the fusion's own rule says so (:func:`align.fusion.plausible.is_carried`; its share
    (k b̂')²), else dropped; u² is the fixed model's plus the mean share. New data that
    separate b from E shrink k: the shift falls below u/2 and the term drops. A candidate
    more likely named than not is in the model against which the less significant ones are
    judged (the loop adds the best first), as is one ``declared`` (a camera's roll
    calibrated, name -> its calibration's u [rad]: no longer a candidate, E corrected for it at
    its estimate; an undetermined one is carried over the calibration's u,
    :func:`ranged_after`) — what it absorbed
    is no longer left for the others, whose estimates move with it (:func:`_with_declared`)."""
    kept = [g for g in lin.groups if g.source not in drop]
    infos = (lin.information([*kept, *add]), lin.information(), lin.information(kept),
             lin.information(add))
    free = list(lin.free)
    n_rows = sum(len(g.A) for g in [*kept, *add])
    u2 = np.diag(inverse(infos[0][np.ix_(free, free)]))[:6] * lin.inflation**2
    # (the carried candidates are judged against u without the ranged terms, as the fusion
    # judges them before it adds those)
    ranged = ranged_after(lin, infos[0], declared)
    # A carried candidate the new data no longer determine (u freed beyond its range's σ: data
    # replaced) the fusion would carry over its range instead (is_carried's rule): so here.
    # (A range declared in session.toml is not in the linearisation: the default's σ.)
    sig = {n: default_sigma(n) for n, *_ in lin.held if n not in declared}
    lost = {r.name: r for r in ranged_after(replace(lin, ranged=tuple(
        (n, i, sig[n]) for n, i, *_ in lin.held if sig.get(n) is not None)), infos[0])}
    ranged = (*ranged, *lost.values())
    fixed = [(i, e) for n, i, e, _ in lin.held if n in declared]
    share = np.zeros((REDRAWS, 6))
    out = []
    own = not add and not drop  # the session's own data: the fusion decided (not re-judged)
    for name, idx, est, p_loop in sorted((h for h in lin.held if h[0] not in declared),
                                         key=lambda h: h[3]):
        # what the session's data left for it once the others are in the model
        c, mine = _one(infos, free, idx, _with_declared(infos[1], free, idx, np.array(est),
                                                        fixed),
                       p_loop, np.sqrt(u2), n_rows, redraw, own, lin.inflation, lost.get(name))
        out.append(replace(c, name=name))
        share += mine
        if c.named >= 0.5:
            fixed.append((idx, est))
    u2 = u2 + sum((np.square(r.shift) for r in ranged), np.zeros(6))
    u = np.sqrt(u2 + share)
    order = [h[0] for h in lin.held]
    return Prediction(np.sqrt(u2 + share.mean(0)), u.std(0),
                      tuple(sorted(out, key=lambda c: order.index(c.name))), ranged)


def _one(infos: tuple[np.ndarray, ...], free: list[int], idx: Sequence[int], b: np.ndarray,
         p_loop: float, u_e: np.ndarray, n_rows: int, redraw: bool, own: bool,
         inflation: float, lost: Undetermined | None = None) -> tuple[Carried, np.ndarray]:
    """One held candidate (parameters ``idx``, estimate ``b`` [rad], the loop's p-value now
    ``p_loop``) after the measurement (``infos``: the information after, now, of the kept
    groups, of the added ones): its :class:`Carried` (unnamed) and its share of u² of the
    six angles in each draw [rad²]; ``lost``: its range's term when the data after no longer
    determine it (never carried then: :func:`align.fusion.plausible.is_carried`)."""
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
    rng = {} if lost is None else {"u_freed": lost.u_freed, "sigma": lost.sigma}
    hit = ~named & np.array([is_carried(c, len(idx), float(np.linalg.norm(x)), K @ x, u_e,
                                        **rng) for c, x in zip(chi, draws, strict=True)])
    if own:
        hit[:], named[:] = True, False
    freed = np.diag(K @ Cbb @ K.T) * inflation**2  # what naming it adds to u²
    mine = (np.where(hit[:, None], np.square(draws @ K.T), 0.0)
            + np.where(named[:, None], freed, 0.0))
    size = float(np.linalg.norm(b))
    g = b / size if size > 0 else np.full(len(b), np.sqrt(1.0 / len(b)))
    if len(b) == 1:  # one component: its signed value (a vector's one number: its length)
        size, g = float(b[0]), np.ones(1)
    return Carried("", size, float(np.sqrt(g @ Cbb @ g)), tuple(K @ b), float(hit.mean()),
                   tuple(mine.mean(0)), float(named.mean())), mine
