"""Whether a lens within every plausible range explains all the lines' bows, exactly.

:func:`align.lens.solve_lens` first tests the lines' bows linearised about the lens it
applied; far from zero (k1 near its range's edge, the principal point off the centre) those
bows are not linear in the other parameters, and straight marks were named bent. This is the
same test by a bounded fit (``cache``: the solver's designs per lens vector, its ``lines``
and ``all(lam)``)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import (
    optimize,  # (least_squares, bounded)
    special,  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
)

from align.lens_design import LensFolds
from align.lens_solution import LensSolution
from imaging.lens import PARAMS

DISAGREE = "the lines' bows disagree with one lens"
"""How the linearised test's note begins (align.lens)."""


def plausible_exact(cache, sol: LensSolution, rng: np.ndarray | None = None
                    ) -> tuple[float, float, np.ndarray]:
    """The linearised plausibility test of :func:`align.lens.solve_lens` without its
    linearisation: the lens that best explains the lines' bows with every parameter within
    its range (bounded least squares from the applied lens, the parameters not applied held
    to their ranges by the same prior), and the p-value of what is left on the same dof.

    The linearised test reads the others' bows at the applied lens: far from zero (k1 -0.30
    fitted about the centre, the true principal point (10, -6) px, k2 -0.02, p1 3e-4, all
    within their ranges) those bows are not linear, and four straight marks left chi2 28065
    on 4 dof there — one named a bent mark — where the lens itself leaves 4.3.
    ``cache``: the solver's designs (``lines``, ``all(lam)``); ``sol``: its solution (the
    start, which parameters it applied, the ranges); ``rng``: the ranges searched (default
    the solution's). Returns (p, the penalised chi2,
    the lens vector found)."""
    rng = sol.ranges.vector() if rng is None else rng
    free = np.flatnonzero(rng > 0)
    prior = np.array([j for j in free if not sol.applied[j]], int)
    n = len(cache.lines)

    def left(x: np.ndarray) -> np.ndarray:
        lam = np.zeros(len(PARAMS))
        lam[free] = x
        try:
            bz = [d.bow_z for d in cache.all(lam)]
        except LensFolds:  # (a lens that folds the image explains nothing)
            return np.full(n + len(prior), 1e6)
        return np.concatenate([bz, lam[prior] / rng[prior]])

    x0 = np.clip(sol.lam[free], -0.99 * rng[free], 0.99 * rng[free])
    fit = optimize.least_squares(left, x0, bounds=(-rng[free], rng[free]), x_scale=rng[free])
    dof = n - int(sum(sol.applied))
    lam = np.zeros(len(PARAMS))
    lam[free] = fit.x
    chi2 = 2 * float(fit.cost)
    return (float(special.chdtrc(dof, chi2)) if dof > 0 else 1.0), chi2, lam


def exact_notes(notes: Sequence[str], exact: tuple[float, float, np.ndarray], alpha: float
                ) -> tuple[str, ...]:
    """``notes`` with the linearised test's disagreement (":data:`DISAGREE` ...: a bent
    mark") corrected when the exact test (:func:`plausible_exact`'s result) finds a lens
    within every range for all the lines: no mark is bent (u still covers the lens and no
    lens, as the linearised test left it: a note never narrows u)."""
    p, chi2, lam = exact
    if p < alpha:
        return tuple(notes)
    return tuple(n.replace(": a bent mark;", f" (linearised about the lens fitted), but a lens "
                           f"within every plausible range explains them all (chi2 {chi2:.1f}, "
                           f"p {p:.2g}; k1 {lam[0]:+.3f}, principal point ({lam[5]:+.0f}, "
                           f"{lam[6]:+.0f}) px): no mark is bent;")
                 if n.startswith(DISAGREE) else n for n in notes)
