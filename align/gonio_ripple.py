"""What a table whose speed follows its angle makes of the counts' difference from the pulse
times, and what is left for the counters.

On a table whose speed ripples with its angle the pulse-time fractions are not the angles'
fractions: interval k lasts the integral of 1 / speed over it. With 1 / speed = (1 + x(θ)) /
w, x a sum of the revolution's harmonics, the count angles minus the pulse-time angles are

    d_k = -∫_k x dθ - κ ∫_k (x² - <x²>) dθ,

the integrals over each face interval *as the counts measure it* (its faces are not 90° apart:
user 6's polygon deviates by up to 356″, and a 1 % once-a-revolution ripple over those faces
puts 1.3–1.6″ into the counters' alternating pattern, which the harmonic projection, blind to
the faces' spacing, charged to the counters). The first order is determined by the data and
modelled; the second order's coefficient κ is not: it depends on the ripple's kind — 0 for a
1 / speed sinusoidal in the angle, 1 for a speed sinusoidal in the angle (1 / (1 + ε cos θ)),
2 for an angle sinusoidal in time (θ = wt + ε sin wt) — and what it puts in the counters'
pattern no log of n faces tells from a counter.

With n faces, the harmonics below n / 2 take n - 2 of the difference's n - 1 degrees of
freedom: for an even n what is left is the counters' alternating pattern (+, -, +, ...), which
a counter losing or gaining counts at its switches makes — and which the ripple's second
order makes too (:attr:`RippleFit.second_rad`, κ from 0 to :data:`KAPPA_MAX`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KAPPA_MAX = 2.0
"""The largest second-order coefficient taken as a once-a-revolution ripple's: an angle
sinusoidal in time (0: 1 / speed sinusoidal in the angle; 1: the speed)."""
POINTS = 65
"""Points of the trapezoid over each face interval for the second order (its integrand is a
few harmonics: exact to ~1e-5 of that order, far below the first's)."""


@dataclass(frozen=True)
class RippleFit:
    """The ripple model's fit of the counts-minus-pulse-time difference.

    Attributes
    ----------
    harmonics : ndarray
        The fitted cos/sin coefficients of x (1 / speed relative to its mean, minus 1) for
        harmonics 1 ... (n - 1) // 2, interleaved (cos 1, sin 1, cos 2, ...); dimensionless.
    residual_rad : ndarray
        What the first order leaves of the difference [rad] (the counters' pattern with an
        even n).
    counters_rad : float
        The residual's alternating amplitude [rad] (0 with an odd number of faces).
    counters_u_rad : float
        Its standard uncertainty from the difference's covariance [rad].
    second_rad : float
        What the ripple's second order at κ = :data:`KAPPA_MAX` puts in that amplitude [rad]
        (signed; a κ from 0 to the max puts from 0 to this).
    """

    harmonics: np.ndarray
    residual_rad: np.ndarray
    counters_rad: float
    counters_u_rad: float
    second_rad: float

    @property
    def amplitude(self) -> float:
        """The once-a-revolution ripple's relative amplitude ε (of 1 / speed), dimensionless."""
        return float(np.hypot(*self.harmonics[:2])) if len(self.harmonics) >= 2 else 0.0

    def covered(self, sigmas: float = 3.0) -> bool:
        """Whether a ripple's second order (κ from 0 to :data:`KAPPA_MAX`) explains the
        counters' alternating part within ``sigmas`` standard uncertainties and the third
        order (ε times the second: 0.002″ of 18″ at ε = 1 % where κ is 2)."""
        ends = (self.counters_rad, self.counters_rad - self.second_rad)
        tol = sigmas * self.counters_u_rad + self.amplitude * abs(self.second_rad)
        return min(ends) - tol <= 0.0 <= max(ends) + tol

    def to_dict(self) -> dict:
        return {"harmonics": self.harmonics.tolist(),
                "residual_rad": self.residual_rad.tolist(),
                "counters_rad": self.counters_rad, "counters_u_rad": self.counters_u_rad,
                "second_rad": self.second_rad}

    @classmethod
    def from_dict(cls, d: dict) -> RippleFit:
        return cls(np.asarray(d["harmonics"], float), np.asarray(d["residual_rad"], float),
                   float(d["counters_rad"]), float(d["counters_u_rad"]),
                   float(d["second_rad"]))


def fit_ripple(angles_rad: np.ndarray, diff_rad: np.ndarray,
               diff_cov: np.ndarray | None = None) -> RippleFit:
    """Fit the ripple model to one direction's counts-minus-pulse-time difference.

    Parameters
    ----------
    angles_rad : ndarray, shape (n,)
        The count angles [rad] (face k to face k + 1, from the reference face; sum 2π): where
        the faces are on the table.
    diff_rad : ndarray, shape (n,)
        The mean difference, count angles minus pulse-time angles [rad].
    diff_cov : ndarray, shape (n, n), optional
        Its covariance [rad²] (None: no uncertainty, ``counters_u_rad`` 0).

    Returns
    -------
    RippleFit
        The harmonics, the residual, the counters' alternating part, its u and what the
        second order may put there.
    """
    a = np.asarray(angles_rad, float)
    d = np.asarray(diff_rad, float)
    n = len(d)
    th = np.concatenate([[0.0], np.cumsum(a)])
    grid = np.linspace(th[:-1], th[1:], POINTS, axis=1)  # (n, POINTS)
    ms = np.arange(1, (n - 1) // 2 + 1)
    # -∫ cos mθ and -∫ sin mθ over each interval: the first order, linear in the harmonics
    cols = np.column_stack([c for m in ms for c in
                            (-(np.sin(m * th[1:]) - np.sin(m * th[:-1])) / m,
                             (np.cos(m * th[1:]) - np.cos(m * th[:-1])) / m)])

    def second(p: np.ndarray) -> np.ndarray:
        x = sum(p[2 * i] * np.cos(m * grid) + p[2 * i + 1] * np.sin(m * grid)
                for i, m in enumerate(ms))
        x2 = x ** 2
        per = np.sum((x2[:, 1:] + x2[:, :-1]) / 2 * np.diff(grid, axis=1), axis=1)
        return per - a * per.sum() / (2 * np.pi)  # (the mean's share: fractions sum to 1)

    if len(ms) == 0:
        p, q = np.zeros(0), np.zeros(n)
    else:
        p = np.linalg.lstsq(cols, d, rcond=None)[0]
        q = second(p)
    resid = d - (cols @ p if len(ms) else 0.0)
    if n % 2:
        return RippleFit(p, resid, 0.0, 0.0, 0.0)
    pat = (-1.0) ** np.arange(n)
    u = 0.0 if diff_cov is None else float(np.sqrt(max(pat @ diff_cov @ pat, 0.0))) / n
    # d = first order - κ q: the residual's pattern is the counters' plus -κ q's
    return RippleFit(p, resid, float(np.mean(resid * pat)), u,
                     -KAPPA_MAX * float(np.mean(q * pat)))
