"""A defocus gradient along a mark: the groove's blur changing from one end to the other.

The groove model has one blur for the whole mark. A tilted or curved object plane blurs one
end more than the other (1 px to 3 px along a long mark): the centres of a symmetric groove
stay unbiased, but the model's profile fits no segment well, the noise model estimated from
its residuals swells, and the centres' stated sigma no longer match their scatter (the loop
then sees chi2 far below its dof). Here the gradient is found and named.

Each segment's blur change (one Gauss–Newton step on the blur, the segment's other
parameters free: :func:`imaging.centres.sample_centres`) is regressed on the position along
the mark. The slope's u is taken from the scatter about the line (never below the Fisher u),
widened for lag-1 correlation of that scatter (AR(1): texture correlates neighbouring
segments), and the slope is tested against zero at :data:`ALPHA`. A groove whose shape
differs from the model's everywhere (a V-groove) moves every segment's blur alike: no slope.

A gradient is claimed only when the blur itself differs end to end: the blur of the first
and of the last third of the segments (weighted means, each with its own u, widened like the
slope's) differ beyond their u at :data:`ALPHA`, and by at least :data:`MIN_CHANGE_PX`. A
lens's magnification changing along an off-centre mark changes the groove's width by a few
per cent, which the blur step (the width is not free per segment) reads as a significant
slope of 0.07-0.14 px end to end on the chessboard lens: a "defocus gradient" whose named
ends were the same blur.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

ALPHA = 1e-3
"""Level of the test for a blur gradient along one mark."""

MIN_CHANGE_PX = 0.1
"""Least difference of the end thirds' blur [px] named a gradient: the note names the blur
to 0.1 px; a smaller change names the same blur at both ends (a true defocus gradient of
1 -> 3 px differs by ~1.5 px between the thirds)."""


@dataclass(frozen=True)
class BlurTrend:
    """The blur along one mark: ``slope`` [px of blur per px along the mark] with standard
    uncertainty ``slope_u``, ``p_value`` of no slope, ``found`` (p below :data:`ALPHA`),
    ``ends_px``: the blur at the measured ends [px] (the band's blur plus the fitted trend,
    linearised: indicative).

    Attributes
    ----------
    slope : float
        Change of the blur along the mark [px of blur per px].
    slope_u : float
        Its standard uncertainty [px/px].
    p_value : float
        Of no slope.
    found : bool
        p below :data:`ALPHA`, and the end thirds' blur differ beyond their u and by at
        least :data:`MIN_CHANGE_PX`.
    ends_px : tuple of float
        The blur of the first and last third of the mark [px].
    ends_u_px : tuple of float
        Their standard uncertainties [px].
    """

    slope: float
    slope_u: float
    p_value: float
    found: bool
    ends_px: tuple[float, float]
    ends_u_px: tuple[float, float] = (float("nan"), float("nan"))


def blur_trend(t: np.ndarray, dev: np.ndarray, dev_u: np.ndarray, blur_px: float,
               alpha: float = ALPHA) -> BlurTrend | None:
    """Test the segments' blur changes ``dev`` ± ``dev_u`` [px] at positions ``t`` [px] for a
    linear trend (None: fewer than 10 usable segments)."""
    ok = np.isfinite(dev) & np.isfinite(dev_u) & (dev_u > 0)
    if ok.sum() < 10:
        return None
    t, d, u = t[ok], dev[ok], dev_u[ok]
    order = np.argsort(t)
    t, d, u = t[order], d[order], u[order]
    w = 1.0 / u**2
    tm = float(np.sum(w * t) / np.sum(w))
    X = np.column_stack([np.ones_like(t), t - tm]) * np.sqrt(w)[:, None]
    beta, *_ = np.linalg.lstsq(X, d * np.sqrt(w), rcond=None)
    cov = np.linalg.inv(X.T @ X)
    z = d * np.sqrt(w) - X @ beta
    dof = max(len(d) - 2, 1)
    zc = z - z.mean()
    rho = float(np.clip(zc[1:] @ zc[:-1] / max(zc @ zc, 1e-300), 0.0, 0.9))
    scale = max(1.0, float(z @ z) / dof) * (1 + rho) / (1 - rho)
    slope, slope_u = float(beta[1]), float(np.sqrt(cov[1, 1] * scale))
    p = float(special.chdtrc(1, (slope / slope_u) ** 2))
    third = len(d) // 3
    ends, ends_u = [], []
    for part in (slice(0, third), slice(len(d) - third, None)):
        ends.append(float(blur_px + np.sum(w[part] * d[part]) / np.sum(w[part])))
        ends_u.append(float(np.sqrt(scale / np.sum(w[part]))))
    diff, diff_u = ends[1] - ends[0], float(np.hypot(*ends_u))
    differ = (abs(diff) > -special.ndtri(alpha / 2) * diff_u and abs(diff) >= MIN_CHANGE_PX)
    return BlurTrend(slope, slope_u, p, bool(p < alpha and differ), (ends[0], ends[1]),
                     (ends_u[0], ends_u[1]))


def defocus_note(where: str, trend: BlurTrend | None) -> str | None:
    """The line that names a defocus gradient (None when there is none).

    Parameters
    ----------
    where : str
        The mark, as messages name it (``image.png: mark 1``).
    trend : BlurTrend or None
        The blur's trend along it.

    Returns
    -------
    str or None
        The note; None when no gradient was found.
    """
    if trend is None or not trend.found:
        return None
    a, b = trend.ends_px
    return (f"{where}: defocus gradient along the mark (blur ~{a:.1f} -> ~{b:.1f} px from its "
            f"first to its last third, p = {trend.p_value:.2g}): the groove model's one blur "
            "does not fit it; the centres stay unbiased (symmetric groove), u kept as stated "
            "(never narrowed)")
