"""Up/down pose pairs whose readings shift together: what no E does, and no creep.

A static pose with axis a up and its partner with a down (the gimbal poses X up / X down, or
Z up / Z down) read each accelerometer across a with opposite signs: s_i . (±a) = ±E_ia, so
E, and a triad that turned (crept) between the measurements, move the pair's two readings
oppositely. A tilt of the base under the gimbal poses (fixed in the room, seen by both poses
of a pair alike along the gimbal's own axis) or a bias drifting between the poses moves them
together: the pair's common mode. The fused solve's parameters absorb part of it (the
per-axis bias, the table's tilt); the rest is tested here in the whitened residual, as the
leave-one-source-out tests a source's own E (:mod:`align.fusion.diagnosis`): one column per
(pair, accelerometer) that is 1 on both poses' readings, projected off the solve's Jacobian;
the fall in χ² it allows, on rank degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.fusion.projected import extra_fit, model_span
from axisbase.units import ARCSEC


@dataclass(frozen=True)
class PairShift:
    """The up/down pairs' common shifts the data show.

    Attributes
    ----------
    shifts : tuple of (str, str, float, float)
        Per (pair, accelerometer): the pair's axis ("X": X up and X down), the housing, the
        common shift of its two readings [g] and its u [g].
    chi2_drop : float
        The fall in χ² when every pair may shift — dimensionless.
    dof : int
        Its degrees of freedom — dimensionless.
    p_value : float
        The fall's p-value — dimensionless.
    """

    shifts: tuple[tuple[str, str, float, float], ...]
    chi2_drop: float
    dof: int
    p_value: float

    def significant(self, alpha: float) -> bool:
        return self.dof > 0 and self.p_value < alpha

    def text(self) -> str:
        """The shifts as a user reads them: "X up/down y +96.9″ (u 0.5″)" (a shift of g·θ
        is a tilt θ, or that bias change: given in arc-seconds of g)."""
        return ", ".join(f"{a} up/down {h} {v / ARCSEC:+.1f}″ (u {u / ARCSEC:.1f}″)"
                         for a, h, v, u in self.shifts)

    def to_dict(self) -> dict:
        return {"shifts": [{"pair": a, "housing": h, "shift_g": v, "u_g": u}
                           for a, h, v, u in self.shifts],
                "chi2_drop": self.chi2_drop, "dof": self.dof, "p_value": self.p_value}


def pair_columns(meta: Sequence[Mapping[str, str]]) -> tuple[list[tuple[str, str]], np.ndarray]:
    """The common-mode columns of a static block's rows (``meta``: each row's ``up``,
    ``housing``): one per (pair, housing) whose up and down poses are both there, 1 on both
    poses' rows of that housing [g per g of shift]. Returns (their (pair axis, housing)
    names, the (rows, columns) matrix)."""
    ups = {m["up"] for m in meta}
    names, cols = [], []
    for axis in "XYZ":
        if f"+{axis}" not in ups or f"-{axis}" not in ups:
            continue
        for h in sorted({m["housing"] for m in meta if m["up"][1] == axis}):
            names.append((axis, h))
            cols.append([1.0 if m["up"][1] == axis and m["housing"] == h else 0.0
                         for m in meta])
    return names, (np.array(cols).T if cols else np.zeros((len(meta), 0)))


def pair_shift(r: np.ndarray, J: np.ndarray, rows: np.ndarray,
               meta: Sequence[Mapping[str, str]], W: np.ndarray) -> PairShift | None:
    """The pairs' common shifts in the fused solve's whitened residual ``r`` with Jacobian
    ``J`` (every fitted parameter); ``rows``: the static block's rows in ``r``, ``meta``
    theirs and ``W`` their whitening (the inverse Cholesky factor of their covariance, [1/g]).
    None without an up/down pair."""
    names, C = pair_columns(meta)
    if not names:
        return None
    A = np.zeros((len(r), len(names)))
    A[rows] = W @ C
    # The residual is data minus prediction: the shift that explains it is +.
    fit = extra_fit(r, model_span(J), A, float(np.abs(A).max()))
    if fit is None:
        return None
    # A pair's own shift only where its column lies in the row space of what the solve's
    # parameters leave of it; the others are said by the test, not by a value.
    shifts = tuple((a, h, float(d), float(np.sqrt(max(c, 0.0))))
                   for (a, h), d, c, o in zip(names, fit.coef, np.diag(fit.cov), fit.own,
                                              strict=True)
                   if o)
    return PairShift(shifts, fit.drop, fit.dof, float(special.chdtrc(fit.dof, fit.drop)))


def pair_shift_from_dict(d: Mapping) -> PairShift:
    """Back from :meth:`PairShift.to_dict`."""
    return PairShift(tuple((str(s["pair"]), str(s["housing"]), float(s["shift_g"]),
                            float(s["u_g"])) for s in d["shifts"]),
                     float(d["chi2_drop"]), int(d["dof"]), float(d["p_value"]))
