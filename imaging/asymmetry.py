"""The groove's asymmetry segment by segment: a profile deeper on one side along part of it.

Paint worn from one side of a groove over part of the mark (independent user 18: one half
3 % shallower over 40 % of the length, invisible by eye) makes the profile asymmetric
there. The centres fit the symmetric model, and an odd departure moves each centre
towards the deeper side by a fraction of the width; where only part of the mark is worn,
the centres step there and the fitted line tilts (user 18: +56" at u 12", z 4.6).
:mod:`imaging.shape` pools the *even* departure over all segments; the odd one varies
along the mark, so it is measured per segment.

Each segment's residuals r (after its own fit, whose centre absorbed part of the odd
departure) are fitted with one odd column, a one-sided depth change
h = A P(e) sign(e) / 2 (A the contrast, P the model's pixel-integrated profile, e the
pixel's distance from the centre) made orthogonal to the segment's own columns J:
eps_k = h_perp' W r / h_perp' W h_perp, with var 1 / h_perp' W h_perp. The fitted
centre absorbed shift_k = [N_k^-1 J' W h]_0 eps_k of it (one Gauss–Newton step; the
correction :func:`imaging.shape.shape_shift` reads is its negative). A constant asymmetry
moves every centre alike (the offset, not the angle); one that changes along the mark
tilts the line by b = g . shift (g the straight line's slope weights), known to sigma_b.

The test (:func:`asymmetry_angle`): the tilt b against sigma_b, two-sided at alpha 1e-3
(one test a mark: a change that does not tilt the line does not move the angle). When it
rejects, the Type B term ``groove_asymmetry`` carries sqrt(b^2 + sigma_b^2) on the angle's
u; otherwise the term is 0. The shift is read through an assumed shape (one side's depth
changed, its edge at the centre blurred with the groove), so it is carried, not removed:
the shape decides the ratio of the part the centre absorbed to the part left in the
residuals. On user 18's wear (one Gaussian side scaled before the blur) it read the tilt
~2.7x too large (a hard-edged side read it ~3x too small); z = b / sigma_b does not depend
on that ratio.

What it cannot see: at 3 % wear over 40 % of a 260 px mark z is ~2.8-4.6, at the edge of
the test (see the changelog for the seeds' counts); a wear that runs the whole length
moves the offset only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erf, ndtr

ALPHA = 1e-3
"""The test's false-alarm rate on a clean mark (one test a mark)."""


@dataclass(frozen=True)
class SegmentAsymmetry:
    """Each segment's odd (one-sided depth) departure and the centre shift it makes.

    Attributes
    ----------
    eps : ndarray
        (nseg,) one side's depth change [fraction of the contrast] (0 where not measured).
    eps_var : ndarray
        (nseg,) its variance (inf where not measured).
    shift_per_eps : ndarray
        (nseg,) the fitted centre's shift per unit eps [px] (its bias).
    """

    eps: np.ndarray
    eps_var: np.ndarray
    shift_per_eps: np.ndarray


def segment_asymmetry(e: np.ndarray, prof: np.ndarray, r: np.ndarray, amp: np.ndarray,
                      wgt: np.ndarray, J: list[np.ndarray], cov: np.ndarray, ok: np.ndarray,
                      seg: np.ndarray, blur: float = 0.0) -> SegmentAsymmetry:
    """Each segment's odd departure from its residuals.

    Parameters
    ----------
    e : ndarray
        Each pixel's distance from its segment's centre [px].
    prof : ndarray
        The model's profile at ``e`` (1 at the groove's full depth) [1].
    r : ndarray
        Its residual [DN].
    amp : ndarray
        Its segment's contrast [DN].
    wgt : ndarray
        Its weight [1/DN^2].
    J : list of ndarray
        The segment fit's columns at each pixel (centre first).
    cov : ndarray
        (nseg, k, k) the segments' inverse normal matrices.
    ok : ndarray
        (nseg,) segments whose fit is valid.
    seg : ndarray
        Each pixel's segment.
    blur : float
        The groove's blur (Gaussian sigma) [px]: the worn side's edge is blurred with it.

    Returns
    -------
    SegmentAsymmetry
    """
    nseg = len(ok)
    # (the side's edge at the centre is blurred with the groove: a hard sign's corner, which
    # the data do not hold, read a third of user 18's wear)
    side = np.sign(e) if blur <= 0 else erf(e / (np.sqrt(2.0) * blur))
    h = amp * prof * side * 0.5
    hw = h * wgt
    # G_k = J' W h per segment, then h's part the segment's own fit does not absorb.
    G = np.stack([np.bincount(seg, hw * j, nseg) for j in J], axis=1)
    c = np.where(ok[:, None, None], cov, 0.0)
    coef = np.einsum("nij,nj->ni", c, G)
    hp = h - sum(coef[seg, i] * J[i] for i in range(len(J)))
    den = np.bincount(seg, wgt * hp * hp, nseg)
    num = np.bincount(seg, wgt * hp * r, nseg)
    good = ok & (den > 0)
    eps = np.where(good, num / np.where(good, den, 1.0), 0.0)
    var = np.where(good, 1.0 / np.where(good, den, 1.0), np.inf)
    return SegmentAsymmetry(eps, var, np.where(good, coef[:, 0], 0.0))


@dataclass(frozen=True)
class AsymmetryTest:
    """What the asymmetry changing along the mark does to its angle.

    Attributes
    ----------
    tilt_rad, tilt_u_rad : float
        The line's tilt by the asymmetry's shifts and its u [rad].
    p_tilt : float
        The test's p-value (the tilt against 0, two-sided).
    found : bool
        p_tilt < alpha.
    u_rad : float
        The Type B term ``groove_asymmetry`` [rad] (0 when not found).
    """

    tilt_rad: float
    tilt_u_rad: float
    p_tilt: float
    found: bool
    u_rad: float


def asymmetry_angle(a: SegmentAsymmetry, use: np.ndarray, t: np.ndarray, sigma: np.ndarray,
                    alpha: float = ALPHA) -> AsymmetryTest:
    """The test for the profile's asymmetry changing along the mark, and its term.

    Parameters
    ----------
    a : SegmentAsymmetry
        The segments' odd departures.
    use : ndarray
        The segments the line uses (bool or index).
    t : ndarray
        Their positions along the line [px].
    sigma : ndarray
        Their u across it [px] (the line fit's).
    alpha : float
        The test's false-alarm rate on a mark whose asymmetry does not change.

    Returns
    -------
    AsymmetryTest
    """
    eps, var, k = a.eps[use], a.eps_var[use], a.shift_per_eps[use]
    fin = np.isfinite(var)
    w = 1.0 / sigma ** 2
    dt = t - np.sum(w * t) / np.sum(w)
    g = w * dt / np.sum(w * dt ** 2)
    shift = np.where(fin, k * eps, 0.0)
    b = float(g @ shift)
    sb = float(np.sqrt(np.sum(np.where(fin, (g * k) ** 2 * var, 0.0))))
    p_tilt = float(2 * ndtr(-abs(b) / sb)) if sb > 0 else 1.0
    found = p_tilt < alpha
    u = float(np.hypot(b, sb)) if found else 0.0
    return AsymmetryTest(b, sb, p_tilt, found, u)
