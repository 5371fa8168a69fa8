"""A JPEG mark's centres along its 8x8 blocks: their scatter, its correlation within a block,
and the pattern the blocks repeat along the mark (:mod:`imaging.jpeg` finds the encoder).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def jpeg_centre_scale(z: np.ndarray) -> float:
    """Variance factor (>= 1) on a JPEG mark's centres from its own whitened residuals ``z``
    (in order along the mark): the mean squared neighbour difference over its value for
    white z (2).

    The encoder's quantisation moves each centre by its share of its block's error: the
    centres (4 px apart, two to a block) scatter beyond their Fisher sigma, almost
    independently (lag-1 correlation ~0 at quality 50-90), and the Fisher sigma itself comes
    from a background the encoder smoothed. Neighbour differences take that block-scale
    scatter and hardly any of a bow, a lens or a wiggle of 2 or more blocks' period (a
    smooth effect's difference over 4 px is small), which the loop then still tests for:
    only the blocks' own scatter is taken as known.

    Parameters
    ----------
    z : numpy.ndarray
        Whitened residuals of the straight line fit, in order along the mark [-].

    Returns
    -------
    float
        The factor on the centres' variance [-].
    """
    z = np.asarray(z, float)
    if len(z) < 3:
        return 1.0
    return float(max(1.0, np.mean(np.diff(z) ** 2) / 2))


def jpeg_noise_dof(n: int) -> float:
    """Degrees of freedom of :func:`jpeg_centre_scale`'s estimate from ``n`` centres: the
    mean of squared neighbour differences of n white z has relative variance 3 / (n - 1)
    (neighbouring differences share a term), i.e. 2 (n - 1) / 3 dof."""
    return float(max(n - 1, 1) / 1.5)


@dataclass(frozen=True)
class BlockScatter:
    """A JPEG mark's centres' scatter read with their 8x8 blocks (:func:`block_scatter`).

    Attributes
    ----------
    factor : float
        Variance factor (>= 1) on the centres' sigma that gives the line's angle the
        variance the block-correlated scatter gives it [-].
    rho : float
        Correlation of two centres' errors in one block (0-1) [-].
    dof : float
        Effective degrees of freedom of ``factor`` (:func:`block_factor_dof`): the residual
        loop's tests take the centres' sigma from ``factor`` on these, and ``u_factor`` is
        ``factor`` carried on them [-].
    u_factor : float
        The variance factor the angle's u takes (>= ``factor``): ``factor`` carried with its
        own estimate's uncertainty (:func:`posterior_factor`) [-].
    """

    factor: float
    rho: float
    dof: float
    u_factor: float


def posterior_factor(factor: float, nu: float) -> float:
    """A variance factor estimated on ``nu`` degrees of freedom as the angle's u takes it:
    ``factor`` x nu / (nu - 2) [-] (inf for nu <= 2).

    u from an estimated variance is itself scattered: the error over it is Student's t, of
    variance nu / (nu - 2), not 1 (1 / F-hat averages above 1 / F: a mark read from few
    centres is too often read too quiet). The factor's posterior mean under a
    scale-invariant prior, and what makes the angle's z of unit variance.
    """
    return float(factor * nu / (nu - 2)) if nu > 2 else float("inf")


def block_scatter(z: np.ndarray, block: np.ndarray, h: np.ndarray) -> BlockScatter:
    """The centres' scatter and its correlation within a block, from the whitened residuals
    ``z`` of the straight line (in order along the mark) and each centre's 8x8 block label
    ``block``; what it does to the angle whose weights on the whitened centres are ``h``.

    The encoder's error at the edge is its block's: two centres in one block (4 px apart
    along a near-axis mark: two a block) share a part of it. Model: z_i = s (sqrt(rho) b_k +
    sqrt(1 - rho) w_i), one b_k per block, independent from block to block. A neighbour
    difference across a block boundary has E d^2 = 2 s^2, one within a block 2 s^2 (1 - rho):
    both local, so a bow, a lens or a slow wiggle hardly enters (they stay for the loop).
    The line fitted as if the centres were independent has the angle variance h'h s^2; the
    model gives s^2 h'Rh = s^2 ((1 - rho) h'h + rho sum_k (sum_{i in k} h_i)^2) (R the
    block-diagonal correlation): their ratio is the factor, an effective-sample-size
    correction exact for that fit (the estimate itself is left as it is). rho is taken in
    [0, 1]: an anti-correlation read from a few dozen pairs never narrows u. Without pairs
    across a boundary (fewer than 2) or within one, the plain neighbour-difference reading
    (:func:`jpeg_centre_scale`) stands.

    Parameters
    ----------
    z : numpy.ndarray
        (N,) whitened residuals of the line fit, in order along the mark [-].
    block : numpy.ndarray
        (N,) integer label of each centre's 8x8 block [-].
    h : numpy.ndarray
        (N,) the angle's weights on the whitened centres (a row of the fit's pseudo-inverse)
        [rad].

    Returns
    -------
    BlockScatter
        The variance factor, the within-block correlation and the factor's dof.
    """
    z, block, h = np.asarray(z, float), np.asarray(block), np.asarray(h, float)
    n = len(z)
    if n < 3:
        return BlockScatter(1.0, 0.0, float("inf"), 1.0)
    d2 = np.diff(z) ** 2
    same = block[1:] == block[:-1]
    n_cross, n_same = int((~same).sum()), int(same.sum())
    if n_same < 2 or n_cross < 3:
        f, nu = jpeg_centre_scale(z), jpeg_noise_dof(n)
        raw = float(np.mean(d2) / 2)
        return BlockScatter(f, 0.0, nu, max(f, posterior_factor(raw, nu)))
    _, inv = np.unique(block, return_inverse=True)
    hb = np.bincount(inv, weights=h)
    hh = float(h @ h)
    g = float(hb @ hb) / hh if hh > 0 else 1.0
    (s2,), (rho,), (raw,) = _block_factor(z[None], same, g)
    if not s2 > 0:
        return BlockScatter(1.0, 0.0, float(n_cross), 1.0)
    nu = block_factor_dof(n, same, inv, g, s2, rho)
    factor = float(max(1.0, raw))
    return BlockScatter(factor, rho, nu, float(max(factor, posterior_factor(factor, nu))))


def _block_factor(Z: np.ndarray, same: np.ndarray, g: float):
    """:func:`block_scatter`'s reading of rows of whitened residuals ``Z`` (M, N): the
    scatter s^2 across block boundaries, the within-block correlation rho (in [0, 1]) and
    the angle's variance factor s^2 (1 - rho + rho g) [-], each (M,)."""
    d2 = np.diff(Z, axis=1) ** 2
    s2 = d2[:, ~same].mean(axis=1) / 2
    w = d2[:, same].mean(axis=1) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(s2 > 0, np.clip(1.0 - w / s2, 0.0, 1.0), 0.0)
    return s2, rho, s2 * (1.0 - rho + rho * g)


FACTOR_DRAWS = 500
"""Draws of the block model :func:`block_factor_dof` reads its factor's spread from (the
mean of F / F-hat to ~1.5 %, its dof within ~15 % at nu ~ 6: a few ms a mark)."""


def block_factor_dof(n: int, same: np.ndarray, inv: np.ndarray, g: float, s2: float,
                     rho: float) -> float:
    """Effective degrees of freedom of :func:`block_scatter`'s variance factor F-hat on a
    mark of ``n`` centres (``same``: the neighbour pairs within one block; ``inv``: each
    centre's block index; ``g``: the angle's block gain), the one the angle's u and the
    residual loop's tests both take: nu with nu / (nu - 2) = E[F / max(1, F-hat)], the mean
    the angle's z^2 has over the estimate (inf where it is <= 1).

    F-hat = s^2 (1 - rho + rho g) is read from two neighbour-difference means that share
    centres (a within-block and a cross-boundary difference correlate by (1 - rho) / 4 in
    their squares) with rho clipped to [0, 1]: no chi-square, and a Welch-Satterthwaite dof
    of the unclipped combination takes rho's spread where rho ~ 0 at its full width (the
    clip removes half of it): u ~sqrt(2) too wide there, and too short near rho ~ 1 where
    it was bounded by the cross-boundary count. So its distribution is taken as it is:
    the block model (z_i = s (sqrt(rho) b_k + sqrt(1 - rho) w_i)) drawn at the mark's own
    (s^2, rho) with its blocks, read as the mark was, and E[F / F-hat] taken over the
    draws (fixed seed: the same mark gives the same u).
    """
    k = int(inv.max()) + 1

    def mean_ratio(r: float) -> tuple[float, float]:
        rng = np.random.default_rng(0)
        Z = np.sqrt(s2) * (np.sqrt(r) * rng.standard_normal((FACTOR_DRAWS, k))[:, inv]
                           + np.sqrt(1.0 - r) * rng.standard_normal((FACTOR_DRAWS, n)))
        _, rr, f = _block_factor(Z, same, g)
        return float(np.mean(s2 * (1.0 - r + r * g) / np.maximum(1.0, f))), float(rr.std())

    c, sd = mean_ratio(rho)
    # rho read from a dozen pairs is often clipped to 0 (or short) where it is 0.3-0.6,
    # where the mean ratio is largest: the reading one of its own sigma above stands too.
    c = max(c, mean_ratio(min(1.0, rho + sd))[0])
    return 2.0 * c / (c - 1.0) if c > 1.0 else float("inf")


BLOCK_HARMONICS = 3
"""Harmonics of the 8 px block period modelled along the mark (periods 8, 4 and 8/3 px)."""


def block_phase_columns(along_px: np.ndarray) -> np.ndarray:
    """Design columns for the blocks' pattern along a mark: a function of each centre's
    place in its 8x8 block along the axis the mark runs with (``along_px``, the raw pixel
    coordinate x or y of each centre [px]) — the same in every block it crosses.

    The encoder's error at an edge depends on where in the block the edge's profile lies,
    so along a mark the centres repeat a pattern of period 8 px in that coordinate (at 4 px
    spacing: alternating signs, the lag-1 'structure' of a near-axis mark at quality 50).
    Modelled as harmonics of 8 px (:data:`BLOCK_HARMONICS`), mean-free, reduced to the
    combinations the centres' phases determine (a sampling that hits two phases leaves
    one column) and to the harmonics that change fast from centre to centre (an alias of a
    slow pattern would tilt with the line: none). The blocks' *slow* drift (the edge crossing
    block rows along the other axis) is no column: it is the angle's own shape, carried by
    ``jpeg_blocks``.

    Parameters
    ----------
    along_px : numpy.ndarray
        (N,) raw pixel coordinate of each centre along the mark's axis [px].

    Returns
    -------
    numpy.ndarray
        (N, k) columns, k = 0..2 :data:`BLOCK_HARMONICS`, each of unit RMS [-].
    """
    x = np.asarray(along_px, float)
    n = len(x)
    step = float(np.median(np.abs(np.diff(np.sort(x))))) if n > 1 else 0.0
    # Only harmonics the centres' spacing sees as fast (at least a quarter turn of phase
    # from one centre to the next): an alias of a slow pattern (period 8/3 px at 2.8 px
    # spacing) drifts along the mark like a tilt and would take the angle with it.
    fast = [j for j in range(1, BLOCK_HARMONICS + 1)
            if abs((2 * np.pi * j * step / 8 + np.pi) % (2 * np.pi) - np.pi) >= np.pi / 2]
    if not fast or n < 8 * len(fast):
        return np.zeros((n, 0))
    cols = [f(2 * np.pi * j * x / 8) for j in fast for f in (np.cos, np.sin)]
    A = np.column_stack(cols)
    A = A - A.mean(axis=0)
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    # Only directions the phases pin down: a singular value below a tenth of the column
    # norm is a pattern the sampling does not see (and would only cost conditioning).
    keep = s > 0.1 * np.sqrt(n / 2)
    return U[:, keep] * np.sqrt(n)
