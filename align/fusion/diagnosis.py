"""Which source disagrees, in which angles: leave-one-source-out on the fused solve.

When the fused solve is inconsistent (chi2 beyond its bound after the loop), each source s is
given its own copy of the six angles, E + d_s, the others keeping E. Linearised at the fused
solution (the angles are arc-minutes, the disagreements arc-seconds), the whitened residual
r and its Jacobian J over every fitted parameter give d_s in closed form: with B_s the part of
dr/dE on s's rows that the other parameters cannot absorb (projected off the columns of J),
d_s = -pinv(B_s) r, the fall in chi2 is |B_s d_s|^2 with rank(B_s) degrees of freedom, and
cov(d_s) = pinv(B_s' B_s). Only the angles s itself determines (in the row space of B_s) are
named. The source whose own E lowers chi2 most — and after which the rest agree — is the one
that disagrees: "the platform static poses disagree with camera, goniometer and ellipsoid in
E_xZ, E_yZ by +22.0″, −19.8″". Two sources seeing different E is what a triad that crept
between the measurements, or a platform that was not level, leaves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.fusion.budget import Budget, with_type_b
from align.fusion.observations import E_NAMES
from align.fusion.pairs import PairShift, pair_shift, pair_shift_from_dict
from align.fusion.projected import extra_fit, model_span
from axisbase.units import ARCSEC

# An angle of a disagreeing source is named when its own d is this many u from zero.
NAME_SIGMA = 3.0
# How a message names each source.
SAYS = {"camera": "camera images", "goniometer": "goniometer log",
        "ellipsoid": "tumble calibration's angles between axes",
        "platform static": "platform static poses"}


@dataclass(frozen=True)
class SourceDisagreement:
    """A source that, given its own E, lets the rest agree.

    Attributes
    ----------
    source : str
        The source; unit —.
    others : tuple of str
        The other sources; unit —.
    delta : numpy.ndarray
        Its own E minus the others' per angle of ``E_NAMES`` [rad] (nan where the source does
        not determine the angle).
    u : numpy.ndarray
        The standard uncertainty of ``delta`` [rad].
    chi2_drop : float
        The fall in χ² when the source gets its own E — dimensionless.
    dof : int
        Its degrees of freedom — dimensionless.
    p_value : float
        The fall's p-value — dimensionless.
    chi2_rest : float
        The χ² that remains — dimensionless.
    dof_rest : int
        Its degrees of freedom — dimensionless.
    also : tuple of str
        Other sources that, given their own E, make the rest agree as well (which one moved,
        the data cannot tell); unit —.
    pairs : PairShift or None
        The platform static poses' up/down pairs shifting together, when those poses are
        named and the shift is significant (:mod:`align.fusion.pairs`; its cause is then not
        creep); unit —.
    """

    source: str
    others: tuple[str, ...]
    delta: np.ndarray
    u: np.ndarray
    chi2_drop: float
    dof: int
    p_value: float
    chi2_rest: float
    dof_rest: int
    # Other sources that, given their own E, make the rest agree as well: which one of them
    # moved, the data cannot tell (a creep between the cameras' and the static readings is
    # seen as either the cameras' or the static poses' own E).
    also: tuple[str, ...] = ()
    # The static poses' up/down pairs shifting together (align.fusion.pairs), when the
    # platform static poses are named and the shift is significant: its cause is then not
    # the triad's creep.
    pairs: PairShift | None = None

    @property
    def angles(self) -> list[tuple[str, float, float]]:
        """(name, d [rad], u [rad]) of the angles beyond ``NAME_SIGMA`` u, largest first."""
        out = [(n, float(d), float(u)) for n, d, u in zip(E_NAMES, self.delta, self.u,
                                                          strict=True)
               if np.isfinite(u) and u > 0 and abs(d) > NAME_SIGMA * u]
        return sorted(out, key=lambda a: -abs(a[1]) / a[2])

    @property
    def rest_consistent(self) -> bool:
        return self.dof_rest <= 0 or special.chdtrc(self.dof_rest, self.chi2_rest) > 1e-3

    def message(self) -> str:
        """One line: the source, the angles and by how much, and the likely cause."""
        ang = self.angles
        names = ", ".join(n for n, _, _ in ang)
        by = ", ".join(f"{d / ARCSEC:+.1f}″ (u {u / ARCSEC:.1f}″)" for _, d, u in ang)
        level = ("platform static" in (self.source, *self.also)
                 and {n for n, _, _ in ang} <= {"E_xZ", "E_yZ"})
        if level:
            hint = "platform not level? (a levelling offset shows in E_xZ, E_yZ only)"
        elif self.pairs is not None:
            # E and creep move an up/down pair's readings oppositely; these moved together.
            shown = f"{self.pairs.text()}; " if self.pairs.shifts else ""
            hint = (f"the static poses' up/down pairs shift together ({shown}"
                    f"chi2 falls by {self.pairs.chi2_drop:.1f} with {self.pairs.dof}), which "
                    "neither another E nor creep does: the base tilted under the gimbal poses "
                    "(not level where they stand), or a bias drifting between the poses; "
                    "level the base, or repeat the poses in the order up, down, down, up")
        else:
            hint = ("the triad moved between the measurements (creep), or a source's set-up "
                    "is not the others'")
        rest = ("the rest then agree" if self.rest_consistent else
                f"the rest still disagree (chi2 {self.chi2_rest:.1f} / {self.dof_rest})")
        me = SAYS.get(self.source, self.source)
        if self.also:
            pair = " and the ".join([me, *(SAYS.get(o, o) for o in self.also)])
            return (f"sources see different E: the {pair} disagree in {names} by {by} (the "
                    f"{me} given their own E: chi2 falls by {self.chi2_drop:.1f} with "
                    f"{self.dof} angles; {rest}; either given its own E makes the rest agree "
                    f"— which one moved, the data cannot tell) — {hint}")
        return (f"sources see different E: the {me} "
                f"disagree with {', '.join(SAYS.get(o, o) for o in self.others)} in {names} "
                f"by {by} (chi2 falls by "
                f"{self.chi2_drop:.1f} with {self.dof} angles of its own; {rest}) — {hint}")

    def to_dict(self) -> dict:
        return {"source": self.source, "others": list(self.others),
                "delta_arcsec": {n: float(d / ARCSEC) for n, d in zip(E_NAMES, self.delta,
                                                                      strict=True)
                                 if np.isfinite(d)},
                "u_arcsec": {n: float(u / ARCSEC) for n, u in zip(E_NAMES, self.u, strict=True)
                             if np.isfinite(u)},
                "angles": [n for n, _, _ in self.angles], "chi2_drop": self.chi2_drop,
                "dof": self.dof, "p_value": self.p_value, "chi2_rest": self.chi2_rest,
                "dof_rest": self.dof_rest, "also": list(self.also), "message": self.message(),
                **({"pairs": self.pairs.to_dict()} if self.pairs is not None else {})}


def disagreement_from_dict(d: dict) -> SourceDisagreement:
    """Back from :meth:`SourceDisagreement.to_dict` (a session result JSON)."""
    delta = np.array([d["delta_arcsec"].get(n, np.nan) for n in E_NAMES]) * ARCSEC
    u = np.array([d["u_arcsec"].get(n, np.nan) for n in E_NAMES]) * ARCSEC
    return SourceDisagreement(str(d["source"]), tuple(d["others"]), delta, u,
                              float(d["chi2_drop"]), int(d["dof"]), float(d["p_value"]),
                              float(d["chi2_rest"]), int(d["dof_rest"]),
                              tuple(d.get("also", ())),
                              pair_shift_from_dict(d["pairs"]) if d.get("pairs") else None)


def with_disagreement(budget: Budget, named: SourceDisagreement) -> Budget:
    """The budget with the disagreement's Type B share (d² in each angle named, the whole
    disagreement: see ``fuse``) added, the fractions and u recomputed."""
    widen = {n: d**2 for n, d, _ in named.angles}
    label = "sources disagree: " + " vs ".join(
        SAYS.get(s, s) for s in (named.source, *(named.also or named.others)))
    return with_type_b(budget, label, widen)


def jacobian(residual, p: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """Central differences of ``residual(p)`` (the fusion's is a few hundred rows by ~15
    parameters: 30 evaluations)."""
    cols = []
    for k in range(len(p)):
        d = np.zeros_like(p)
        d[k] = step
        cols.append((residual(p + d) - residual(p - d)) / (2 * step))
    return np.column_stack(cols)


def leave_one_source_out(residual, params: np.ndarray, rows_of: Sequence[tuple[str, np.ndarray]],
                         J: np.ndarray | None = None) -> list[SourceDisagreement]:
    """Each source given its own six angles (see the module docstring).

    Parameters
    ----------
    residual : whitened residual of the fused solve as a function of all its parameters
        (the six angles first, in ``E_NAMES`` order, [rad]).
    params : the fused solution.
    rows_of : (source name, indices of its rows in the residual), one per source.
    J : its Jacobian at ``params`` if already computed (:func:`jacobian`).
    """
    r = residual(params)
    J = jacobian(residual, params) if J is None else J
    Q = model_span(J)
    chi2 = float(r @ r)
    dof = len(r) - Q.shape[1]
    names = [n for n, _ in rows_of]
    out = []
    for name, idx in rows_of:
        A = np.zeros((len(r), 6))
        A[idx] = J[idx, :6]
        fit = extra_fit(r, Q, A, float(np.abs(J[:, :6]).max()))
        if fit is None:
            continue
        # A column of J moves the residual: the angles that explain it are the negative.
        delta, drop, k = -fit.coef, fit.drop, fit.dof
        # An angle is the source's own when it lies in the row space of what is left.
        u = np.where(fit.own, np.sqrt(np.maximum(np.diag(fit.cov), 0)), np.nan)
        d = np.where(fit.own, delta, np.nan)
        out.append(SourceDisagreement(
            name, tuple(n for n in names if n != name), d, u, drop, k,
            float(special.chdtrc(k, drop)), chi2 - drop, dof - k))
    return out


def name_disagreement(found: Sequence[SourceDisagreement], alpha: float
                      ) -> SourceDisagreement | None:
    """The source whose own E lowers chi2 most, if significantly (``alpha``, Bonferroni over
    the sources) and with at least one angle of its own beyond ``NAME_SIGMA`` u; with
    ``also`` the other sources whose own E makes the rest agree as well (two sources that
    see different E, and nothing else tells which of them moved)."""
    cand = [f for f in found if f.p_value < alpha / max(len(found), 1) and f.angles]
    if not cand:
        return None
    best = max(cand, key=lambda f: f.chi2_drop)
    if not best.rest_consistent:
        return best
    also = tuple(f.source for f in cand if f is not best and f.rest_consistent)
    return replace(best, also=also) if also else best


def with_pairs(named: SourceDisagreement, r: np.ndarray, J: np.ndarray, blocks: Sequence,
               whiten: Sequence[np.ndarray], starts: np.ndarray, alpha: float
               ) -> SourceDisagreement:
    """``named`` (the platform static poses among its sources) with the static poses' up/down
    pairs' common shift (:func:`align.fusion.pairs.pair_shift`) when it is significant at
    ``alpha``: its message then names that, not creep. ``r``, ``J``: the fused solve's
    whitened residual and Jacobian; ``blocks``, ``whiten``, ``starts``: the solve's blocks,
    their whitening and where each one's rows begin in ``r``."""
    for k, b in enumerate(blocks):
        if b.source != "platform static" or not b.row_meta:
            continue
        found = pair_shift(r, J, np.arange(starts[k], starts[k + 1]), b.row_meta, whiten[k])
        if found is not None and found.significant(alpha):
            return replace(named, pairs=found)
    return named
