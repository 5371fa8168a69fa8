"""One camera's lens as solved from its marks (:func:`align.lens.solve_lens`): the result,
its JSON record, and the variance it adds to each mark's angle."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from align.lens_design import LensRanges, _Design
from imaging.lens import PARAMS


@dataclass(frozen=True)
class LensSolution:
    """The lens of one camera from its marks (see the module docstring).

    Attributes
    ----------
    lam : numpy.ndarray
        The applied lens vector over ``PARAMS`` (zeros where not applied) — dimensionless (pp
        in [px]).
    determined, applied : tuple of bool
        Per parameter; unit —.
    u_lines : numpy.ndarray
        Each parameter's marginal u from the lines (inf: not determined) — dimensionless (pp
        in [px]).
    estimate : numpy.ndarray
        The fitted value of each determined parameter (nan otherwise) — dimensionless (pp in
        [px]).
    cov_applied : numpy.ndarray
        Covariance of the applied parameters [products of their units].
    ranges : LensRanges
        The plausible ranges used; unit —.
    n_lines : int
        Marks that entered the fit — dimensionless.
    chi2_dof : float
        χ²/dof of the lines' fit — dimensionless.
    notes : tuple of str
        What the reader must know (one line each); unit —.
    info : numpy.ndarray
        The lines' information matrix over ``PARAMS`` [1/products of the units].
    confirmed : bool
        The lines confirm the lens applied; unit —.
    bow_chi2 : float
        χ² of the marks' bows about the lens — dimensionless.
    bow_dof : int
        Its degrees of freedom — dimensionless.
    bent_lines : tuple of int
        The line whose bow no lens the other lines agree on explains (left out of the fit,
        a bent mark) — dimensionless.
    free : tuple of bool
        Per parameter: fitted free with the lines, its sign not determined (in ``applied``
        and ``lam``: the angles are read at its estimate and its covariance is in
        ``cov_applied``, the angle marginalised over it; not claimed as the lens: reported
        ``applied: false``, ``estimator: "free"``); unit —.
    """

    lam: np.ndarray
    determined: tuple[bool, ...]
    applied: tuple[bool, ...]
    u_lines: np.ndarray
    estimate: np.ndarray
    cov_applied: np.ndarray
    ranges: LensRanges
    n_lines: int
    chi2_dof: float
    notes: tuple[str, ...] = ()
    info: np.ndarray = field(default_factory=lambda: np.zeros((len(PARAMS), len(PARAMS))))
    confirmed: bool = True
    bow_chi2: float = 0.0
    bow_dof: int = 0
    bent_lines: tuple[int, ...] = ()
    free: tuple[bool, ...] = (False,) * len(PARAMS)

    def estimator(self, j: int) -> str:
        """How parameter ``j`` enters the angles: ``applied`` (the lens, its sign
        determined), ``free`` (fitted with the lines, sign open: the angle marginalised over
        it), ``small`` (determined, sign open, carried as its estimate +- u), ``range``
        (carried uniform over its plausible range) or ``none`` (range 0)."""
        if self.free[j]:
            return "free"
        if self.applied[j]:
            return "applied"
        if self.ranges.vector()[j] <= 0:
            return "none"
        return "small" if self.determined[j] else "range"

    def to_dict(self) -> dict:
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        return {"model": "brown-conrady at the half-diagonal", "lines": self.n_lines,
                "confirmed_by_other_lines": self.confirmed,
                "bow_chi2": float(self.bow_chi2), "bow_dof": self.bow_dof,
                "bent_lines": list(self.bent_lines),
                "chi2_dof": num(self.chi2_dof), "ranges": self.ranges.to_dict(),
                "parameters": {p: {"determined": self.determined[j],
                                   "applied": self.applied[j] and not self.free[j],
                                   "estimator": self.estimator(j),
                                   "value": float(self.lam[j]),
                                   "estimate": num(self.estimate[j]),
                                   "u_from_lines": num(self.u_lines[j])}
                               for j, p in enumerate(PARAMS)},
                "notes": list(self.notes)}


def signed_parts(sol: LensSolution, design: _Design) -> dict[str, np.ndarray]:
    """Each named lens term of one mark's angle as signed components [rad] on the lens's
    own error directions (the same directions for every mark of one solve): see
    :func:`align.lens_terms.angle_terms` (their norms) and
    :func:`align.lens_terms.angle_coupling` (the components)."""
    P = len(PARAMS)
    A = [j for j in range(P) if sol.applied[j]]
    rng = sol.ranges.vector()
    out: dict[str, np.ndarray] = {}
    s = design.s
    if A:
        # The fitted parameters' covariance C = L L^T: s C s^T = |L^T s|^2, and two marks
        # share (L^T s_i) . (L^T s_j) = s_i C s_j^T.
        w, V = np.linalg.eigh(sol.cov_applied)
        L = V * np.sqrt(np.clip(w, 0.0, None))
        out["lens_fit"] = L.T @ s[A]
        if not sol.confirmed:
            # Lens or bend: the angle with the lens applied and without it both stand, and
            # the bow may be part lens, part bend: the truth anywhere between the two
            # readings, uniform (Type B); about the reading given (the lens applied) its
            # standard uncertainty is the difference / sqrt 3 (the difference itself is the
            # bound, not a standard uncertainty).
            out["lens_or_bend"] = np.array([s[A] @ sol.lam[A] / np.sqrt(3)])
    FA = sol.info[np.ix_(A, A)] if A else None
    for j in range(P):
        if sol.applied[j] or rng[j] <= 0:
            continue
        # What the applied parameters absorb of parameter j's bow changes their estimates,
        # hence the angle: the angle's net sensitivity to j.
        seff = float(s[j] - (s[A] @ np.linalg.solve(FA, sol.info[A, j]) if A else 0.0))
        if design.s_pp_var is not None and not sol.determined[j]:
            # Over the principal point's range (uniform) the sensitivity varies about its
            # value at the centre: its mean square, with the sign it has at the centre.
            seff = float(np.copysign(np.sqrt(seff**2 + float(design.s_pp_var[j])), seff))
        if sol.determined[j]:
            # An estimate beyond the range is no lens (a bent mark's bow): the lens itself
            # is within the range.
            e = min(abs(sol.estimate[j]), rng[j]) if np.isfinite(sol.estimate[j]) else 0.0
            out[f"lens_{PARAMS[j]}_small"] = np.array([seff * np.hypot(e, sol.u_lines[j])])
        else:
            out[f"lens_{PARAMS[j]}_range"] = np.array([seff * rng[j] / np.sqrt(3)])
    return out


def lens_angle_var(sol: LensSolution, design: _Design) -> float:
    """The variance [rad^2] the lens adds to one mark's angle: the square sum of its
    :func:`signed_parts` (the solver chooses between estimators by it before any term is
    named)."""
    return float(sum(np.sum(v**2) for v in signed_parts(sol, design).values()))
