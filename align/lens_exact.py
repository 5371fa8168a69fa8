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
from imaging.lens import PARAMS


def plausible_exact(cache, lam0: np.ndarray, applied: Sequence[bool], rng: np.ndarray,
                    start: np.ndarray | None = None) -> tuple[float, float, np.ndarray]:
    """The linearised plausibility test of :func:`align.lens.solve_lens` without its
    linearisation: the lens that best explains the lines' bows with every parameter within
    its range (bounded least squares, the parameters not applied held to their ranges by the
    same prior), and the p-value of what is left on the same dof.

    The linearised test reads the others' bows at the applied lens: far from zero (k1 -0.30
    fitted about the centre, the true principal point (10, -6) px, k2 -0.02, p1 3e-4, all
    within their ranges) those bows are not linear, and four straight marks left chi2 28065
    on 4 dof there — one named a bent mark — where the lens itself leaves 4.3.

    Parameters
    ----------
    cache : align.lens_design._DesignCache
        The solver's lines (``lines``; ``search(lam)``, their bows all at once,
        :mod:`align.lens_search`; ``bow_jacobian``).
    lam0 : (P,) array
        The solver's lens vector (the start unless ``start`` is given) [PARAMS' units].
    applied : sequence of bool
        Which parameters the solver applied (no prior on them; the dof lose one each).
    rng : (P,) array
        The ranges searched (the fit bounded by them, the prior's standard deviation).
    start : (P,) array, optional
        A nearer start (the fit of all the lines for a leave-one-out: a step or two from
        its own, where the solver's lens took twice as many). The bows' slopes are
        analytic (:meth:`~align.lens_design._DesignCache.bow_jacobian`): one reading of
        the lines per step, where finite differences made eight.

    Returns
    -------
    tuple
        (p, the penalised chi2, the lens vector found)."""
    free = np.flatnonzero(rng > 0)
    prior = np.array([j for j in free if not applied[j]], int)
    n = len(cache.lines)

    def lens(x: np.ndarray) -> np.ndarray:
        lam = np.zeros(len(PARAMS))
        lam[free] = x
        return lam

    def left(x: np.ndarray) -> np.ndarray:
        lam = lens(x)
        try:
            bz = cache.search(lam).bow_z
        except LensFolds:  # (a lens that folds the image explains nothing)
            return np.full(n + len(prior), 1e6)
        return np.concatenate([bz, lam[prior] / rng[prior]])

    def slope(x: np.ndarray) -> np.ndarray:
        out = np.zeros((n + len(prior), len(free)))
        out[n + np.arange(len(prior)), np.searchsorted(free, prior)] = 1 / rng[prior]
        try:
            out[:n] = cache.bow_jacobian(lens(x), free)
        except LensFolds:  # (left's 1e6 there: the step is refused, its slope not read)
            pass
        return out

    x0 = np.clip((lam0 if start is None else start)[free], -0.99 * rng[free], 0.99 * rng[free])
    fit = optimize.least_squares(left, x0, slope, bounds=(-rng[free], rng[free]),
                                 x_scale=rng[free])
    dof = n - int(sum(applied))
    chi2 = 2 * float(fit.cost)
    return (float(special.chdtrc(dof, chi2)) if dof > 0 else 1.0), chi2, lens(fit.x)
