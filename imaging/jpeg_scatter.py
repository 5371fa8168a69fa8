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
        Degrees of freedom of the scatter's amplitude read across block boundaries (the
        residual loop's tests take the centres' sigma from ``factor`` on these) [-].
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
    s2 = float(np.mean(d2[~same]) / 2)
    w = float(np.mean(d2[same]) / 2)
    rho = float(np.clip(1.0 - w / s2, 0.0, 1.0)) if s2 > 0 else 0.0
    _, inv = np.unique(block, return_inverse=True)
    hb = np.bincount(inv, weights=h)
    hh = float(h @ h)
    ratio = ((1.0 - rho) * hh + rho * float(hb @ hb)) / hh if hh > 0 else 1.0
    g = float(hb @ hb) / hh if hh > 0 else 1.0
    raw = s2 * ratio
    # The cross-boundary differences carry s^2; with two centres a block they share no term
    # (one chi2_1 each), and the within-block ones add rho's own spread: their count is
    # the dof of the amplitude the loop's tests take (at most n/2 for a near-axis mark).
    # The angle's u takes the factor s2 g - w (g - 1) with both estimates' spread: its
    # Welch-Satterthwaite dof (s2 on n_cross, w on n_same chi2_1 terms), and never beyond
    # what rho = 1 (the model's most) gives with s2's own spread. A short mark's rho, read
    # from a dozen pairs, is most of its factor's uncertainty: on the quality-75 crop
    # sweep's marks saved as files, 12 pairs read rho 0 (clipped from -0.44) where the
    # error was 4.15 u.
    var = 2.0 * (g * s2) ** 2 / n_cross + 2.0 * ((g - 1.0) * w) ** 2 / n_same
    nu = 2.0 * raw**2 / var if var > 0 else float("inf")
    bound = posterior_factor(max(1.0, s2 * g), n_cross)
    factor = float(max(1.0, raw))
    return BlockScatter(factor, rho, float(n_cross),
                        float(max(factor, min(posterior_factor(raw, nu), bound))))


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
