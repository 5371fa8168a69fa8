"""A reading that still settles after each turn: found in the samples within the poses,
corrected, carried in u and stated.

An anelastic flexure (or a fluid-damped pendulum, a thermal gradient after handling) leaves
the reading creeping towards its new value after each turn: the samples of pose p carry
c (u_{p-1} - u_p) exp(-(t - t0_p) / tau) [output unit], a fraction c of the change into the
pose still to come, decaying with tau. A pose's mean then keeps part of the previous
attitude, and the fit turns that into the parameters (a scale factor 4 u off with no test
of the means calling for anything: issue 19, user 8).

While the triad is static only such a transient, the triad's wander (a bias or scale drift:
a trend common to the poses, or in proportion to the axis's reading) and noise change its
samples, so the transient is tested where nothing else can mimic it: each axis's block means
of every pose (less their mean) give the pose's amplitude of the transient's shape, and
across the poses these amplitudes are regressed on the change into each pose (c_a), beside a
constant and the pose's reading (a bias drift, a scale drift); an F test of the three c_a
over the amplitudes' scatter about that fit (which carries whatever correlation the noise
within a pose has: a bias walk moves each pose's amplitude, independently of the turn),
Sidak-corrected over the tau grid. Found, the transient's c and tau are estimated from all
block means at once (far better determined than by the poses' amplitudes), each pose's
samples are taken back by it (iterated: the changes u_{p-1} - u_p come from the corrected
means), the correction's uncertainty (the larger of the two estimates' u of c) is added to
each pose's sigma, and the result says so.

Hand-written: two small regressions over a few hundred block means, a few lines of numpy
(no library fits one transient shared by many short records).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special
from scipy.optimize import minimize_scalar

from align.calibration.slopes import MIN_SLOPE_SAMPLES, SLOPE_POINTS

SETTLING_ALPHA = 1e-3
"""Significance at which a transient tied to the previous turn must exceed the block means'
scatter (Sidak over the tau grid): the calibration loop's alpha, so a clean tumble is taken
for settling at most this often."""
TAU_STEP = 2.0
"""Ratio of successive time constants of the grid: from two blocks' length up to half the
shortest pose used (a transient longer than that is a trend of the pose, the wander's)."""
MIN_POSES = 6
MAX_FRACTION = 0.01
"""Largest settling taken as one [fraction of the turn's change]: anelastic creep of a
mount or a sensor leaves 1e-5 to 1e-3 of a change still to come; a transient of more than a
hundredth is the triad still moving within its "poses" (readings from motion, a turn cut
into chunks), which no correction makes static: stated, not corrected."""
"""Fewest poses with a previous pose and enough samples for the test (the amplitudes' fit
has three coefficients per axis: three degrees of freedom left)."""


@dataclass(frozen=True)
class Settling:
    """A settling transient tied to the previous turn.

    Attributes
    ----------
    fraction : numpy.ndarray
        c per axis: the fraction of each turn's change still to come at the pose's first
        sample — dimensionless.
    fraction_u : numpy.ndarray
        Its standard uncertainty per axis — dimensionless.
    tau_s : float
        The transient's time constant [s].
    p : float
        Its significance (F test, Sidak over the tau grid) — dimensionless.
    found : bool
        Whether p < the test's alpha; unit —.
    """

    fraction: np.ndarray
    fraction_u: np.ndarray
    tau_s: float
    p: float
    found: bool

    @property
    def beyond(self) -> bool:
        """Found, but larger than any settling (:data:`MAX_FRACTION`): motion, not corrected."""
        return self.found and bool(np.any(np.abs(self.fraction) > MAX_FRACTION))

    def statement(self) -> str:
        """One line for the warnings (found)."""
        c = ", ".join(f"{1e6 * v:+.0f} ± {1e6 * u:.0f}" for v, u in
                      zip(self.fraction, self.fraction_u, strict=True))
        if self.beyond:
            return (f"calibration: the readings move within the poses after each turn (({c}) "
                    f"ppm of the change into the pose per axis, tau {self.tau_s:.3g} s, p = "
                    f"{self.p:.2g}): beyond any settling ({MAX_FRACTION:.0%} of the change), "
                    "the poses are not static; NOT corrected: hold the triad still in each "
                    "pose")
        return (f"calibration: the samples settle after each turn (a transient of ({c}) ppm "
                f"of the change into the pose per axis, tau {self.tau_s:.3g} s, p = "
                f"{self.p:.2g}): each pose's samples corrected for it, u carries the "
                "correction; hold each pose longer or wait after the turn")

    def to_dict(self) -> dict:
        return {"fraction": self.fraction.tolist(), "fraction_u": self.fraction_u.tolist(),
                "tau_s": self.tau_s, "p": self.p, "found": self.found}


def _blocks(x: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Block means of a pose's samples and times (at most SLOPE_POINTS blocks) and the
    block's length in samples."""
    b = -(-len(x) // SLOPE_POINTS)
    m = len(x) // b
    return (x[:m * b].reshape(m, b, -1).mean(1), t[:m * b].reshape(m, b).mean(1), b)


def _fit(y, shape, level, delta, tau):
    """Per axis: c_a, its variance and the dof of that variance. Each pose's own amplitude
    of the shape exp(-(t - t0)/tau) in its block means (both less their mean), then across
    the poses the amplitudes regressed on (1, the pose's reading ``level``, the change
    ``delta`` into it) — a bias drift gives every pose one amplitude, a scale drift one in
    proportion to its reading — weighted by the shape's energy in the pose, and c_a's
    variance from their scatter about that fit: whatever correlation the noise within a
    pose has (a bias walk), it is in the scatter of the poses' amplitudes, which a walk
    makes independently of the turn."""
    amp, w = [], []
    for s, v in zip(shape, y, strict=True):
        x = _dm(_block_exp(s, tau))
        xx = float(x @ x)
        w.append(xx)
        amp.append((x @ (v - v.mean(0))) / xx if xx > 0 else np.zeros(3))
    amp, w = np.array(amp), np.sqrt(np.array(w))
    lev, d = np.array(level), np.array(delta)
    dof = len(w) - 3
    c, var = np.zeros(3), np.zeros(3)
    for a in range(3):
        X = np.column_stack([np.ones(len(w)), lev[:, a], d[:, a]]) * w[:, None]
        Y = amp[:, a] * w
        coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
        r = Y - X @ coef
        c[a] = coef[2]
        var[a] = float(r @ r) / dof * np.linalg.pinv(X.T @ X)[2, 2]
    return c, var, dof


def _pooled(y, shape, nuis, delta, tau):
    """The estimate: per axis c_a and its variance from all block means at once (each pose
    less its mean; a common bias and scale trend as nuisance), white block-mean noise."""
    c, var = np.zeros(3), np.zeros(3)
    dof = sum(len(v) for v in y) - len(y) - 3
    for a in range(3):
        X = np.concatenate([np.column_stack([d[a] * _dm(_block_exp(s, tau)),
                                             *(_dm(v[:, a]) for v in nu)])
                            for s, d, nu in zip(shape, delta, nuis, strict=True)])
        Y = np.concatenate([_dm(v[:, a]) for v in y])
        coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
        r = Y - X @ coef
        c[a] = coef[0]
        var[a] = float(r @ r) / dof * np.linalg.pinv(X.T @ X)[0, 0]
    return c, var, dof


def _best_tau(fit, taus, args) -> tuple[float, float, np.ndarray, np.ndarray, int]:
    """The tau of ``taus`` with the largest F of ``fit``, refined between its neighbours
    (bounded search on log tau): (F, tau, c, var, dof)."""
    best = None
    for tau in taus:
        c, var, dof = fit(*args, float(tau))
        f = _stat(c, var)
        if best is None or f > best[0]:
            best = (f, float(tau), c, var, dof)
    g = np.log(best[1])
    r = minimize_scalar(lambda x: -_stat(*fit(*args, float(np.exp(x)))[:2]),
                        bounds=(g - np.log(TAU_STEP), g + np.log(TAU_STEP)),
                        method="bounded", options={"xatol": 0.02})
    if -r.fun > best[0]:
        tau = float(np.exp(r.x))
        c, var, dof = fit(*args, tau)
        best = (-float(r.fun), tau, c, var, dof)
    return best


def _block_exp(s: tuple[np.ndarray, int], tau: float) -> np.ndarray:
    """Block means of exp(-(t - t0)/tau) over a pose's samples (``s``: (t - t0, block))."""
    dt, b = s
    m = len(dt) // b
    return np.exp(-dt[:m * b] / tau).reshape(m, b).mean(1)


def _stat(c: np.ndarray, var: np.ndarray) -> float:
    """The F statistic of the three c_a (0 where a variance is not positive: samples
    quantised flat within the blocks say nothing about a transient)."""
    return float(np.sum(c**2 / var)) / 3 if np.all(var > 0) else 0.0


def _dm(v: np.ndarray) -> np.ndarray:
    return v - v.mean()


def settling(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
             alpha: float = SETTLING_ALPHA) -> Settling | None:
    """Test the poses' samples for a transient tied to the previous turn (see the module).

    Parameters
    ----------
    samples : sequence of (n_p, 3) arrays
        Each pose's samples [output unit], the poses in the order held.
    times : sequence of (n_p,) arrays
        Their times [s].
    alpha : float
        The test's significance.

    Returns
    -------
    Settling or None
        None when too few poses have the samples to tell (each needs
        :data:`~align.calibration.slopes.MIN_SLOPE_SAMPLES` and a previous pose).
    """
    order = np.argsort([float(np.mean(t)) for t in times], kind="stable")
    means = np.array([np.asarray(samples[i], float).mean(0) for i in order])
    use = [j for j in range(1, len(order))
           if len(samples[order[j]]) >= MIN_SLOPE_SAMPLES and np.ptp(times[order[j]]) > 0]
    if len(use) < MIN_POSES:
        return None
    y, shape, level, nuis, tb0, lengths = [], [], [], [], [], []
    for j in use:
        x, t = np.asarray(samples[order[j]], float), np.asarray(times[order[j]], float)
        yb, tb, b = _blocks(x, t)
        y.append(yb)
        shape.append((t - t[0], b))
        level.append(means[j])
        tc = tb - tb.mean()
        nuis.append((np.outer(tc, np.ones(3)), np.outer(tc, means[j])))
        tb0.append(b * float(np.median(np.diff(t))) if len(t) > 1 else 0.0)
        lengths.append(float(np.ptp(t)))
    lo, hi = 2 * max(max(tb0), 1e-9), min(lengths) / 2
    if not hi > lo:
        return None
    taus = lo * TAU_STEP ** np.arange(int(np.floor(np.log(hi / lo) / np.log(TAU_STEP))) + 1)
    delta = [means[j - 1] - means[j] for j in use]
    # The test: the amplitudes across the poses (robust to the noise's correlation).
    f, _, _, _, dof = _best_tau(_fit, taus, (y, shape, level, delta))
    p = float(-np.expm1(len(taus) * np.log1p(-min(special.fdtrc(3, dof, f), 1 - 1e-16))))
    if not p < alpha:
        return Settling(np.zeros(3), np.full(3, np.inf), float("nan"), p, False)
    # Found: the transient from every block mean at once (its tau and c determined far
    # better than by the poses' amplitudes); its u the larger of the two estimates'.
    _, tau, c, var, _ = _best_tau(_pooled, taus, (y, shape, nuis, delta))
    _, v_rob, _ = _fit(y, shape, level, delta, tau)
    return Settling(c, np.sqrt(np.maximum(var, v_rob)), tau, p, True)


def settle_samples(samples: Sequence[np.ndarray], times: Sequence[np.ndarray],
                   ordered: bool = True
                   ) -> tuple[list[np.ndarray], np.ndarray | None, Settling | None]:
    """The poses' samples corrected for a settling transient when they show one
    (:func:`settling`; one beyond :data:`MAX_FRACTION` is stated, not corrected), the
    correction's standard uncertainty on each pose's mean (N, 3) [output unit] (None: not
    corrected) and the test (None: not testable). Poses in an unknown order (``ordered``
    false: no previous pose) are not tested."""
    if not ordered:
        return list(samples), None, None
    s = settling(samples, times)
    if s is None or not s.found or s.beyond:
        return list(samples), None, s
    fixed, u = corrected(samples, times, s)
    return fixed, u, s


def corrected(samples: Sequence[np.ndarray], times: Sequence[np.ndarray], s: Settling,
              iterations: int = 3) -> tuple[list[np.ndarray], np.ndarray]:
    """Each pose's samples less the fitted transient (the changes from the corrected means,
    ``iterations`` times) and the correction's standard uncertainty on each pose's mean
    (N, 3) [output unit] from ``s.fraction_u``."""
    order = np.argsort([float(np.mean(t)) for t in times], kind="stable")
    out = [np.asarray(x, float) for x in samples]
    for _ in range(iterations):
        means = np.array([out[i].mean(0) for i in order])
        new = [np.asarray(x, float).copy() for x in samples]
        u = np.zeros((len(samples), 3))
        for j in range(1, len(order)):
            i = order[j]
            t = np.asarray(times[i], float)
            e = np.exp(-(t - t[0]) / s.tau_s)
            d = means[j - 1] - means[j]
            new[i] = new[i] - np.outer(e, s.fraction * d)
            u[i] = np.abs(s.fraction_u * d) * e.mean()
        out = new
    return out, u
