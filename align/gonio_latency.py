"""Two directions at different speeds: the latency (and an Earth rate not removed) modelled.

The plain mean of both directions cancels what flips with the direction only when both runs
have the same speed profile. An autocollimator latency L moves angle k by L times the change
of the table's speed between its faces (:func:`align.gonio_timing.latency_sensitivity`):
proportional to the speed, so a reverse run at another speed leaves L (s_f + s_r) / 2 in the
mean. An Earth rate not removed (no latitude) moves it by the rate times each run's
sensitivity g (the time spent across each angle): proportional to 1 / speed, likewise left.
Both runs' sensitivities are measured from their own pulse times, so half the difference of
the runs determines L (and the rate), and the mean is corrected by what they leave
(:func:`latency_model`). What the model does not explain is what the reverse check judges.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from align.gonio_timing import latency_sensitivity
from goniometry import FaceAngles, LogSummary, face_angles, kept_table

RATE_STEP = 1e-4
"""Rate [rad/s] of the finite difference that gives an angle's Earth-rate sensitivity
(face_angles is linear in the rate: the step's size does not matter)."""


@dataclass(frozen=True)
class DirectionModel:
    """Sensitivities of the half difference (``h``) and of the mean (``c``) of both runs'
    angles [rad per unit of each parameter], in the first run's (ccw) order; ``names``: the
    parameters (``latency`` [s], ``earth_rate`` [rad/s]); ``speed_ratio``: the reverse run's
    mean speed over the first's."""

    h: np.ndarray
    c: np.ndarray
    names: tuple[str, ...]
    speed_ratio: float


def _speeds(summary: LogSummary) -> tuple[np.ndarray, float] | None:
    counts, dt, _ = kept_table(summary)
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    if ok.sum() < 16:
        return None
    s = latency_sensitivity(counts[ok], dt[ok])
    return s, float(2 * np.pi / np.mean(dt[ok].sum(1)))


def _earth_sensitivity(summary: LogSummary, base: FaceAngles) -> np.ndarray:
    """d angle / d (rate in the counts) [s]: the raw angles carry + rate * g."""
    return -(face_angles(summary, RATE_STEP).angles_rad - base.angles_rad) / RATE_STEP


def latency_model(fwd: LogSummary, rev: LogSummary, fwd_angles: FaceAngles,
                  rev_angles: FaceAngles, earth_removed: bool) -> DirectionModel | None:
    """The direction model of two runs with pulse times (None without them).

    ``fwd_angles``/``rev_angles``: each run's count angles without an Earth rate removed
    (used only for the Earth sensitivity when ``earth_removed`` is False)."""
    if not (fwd.has_time and rev.has_time):
        return None
    a, b = _speeds(fwd), _speeds(rev)
    if a is None or b is None:
        return None
    (s_f, w_f), (s_r, w_r) = a, b
    rho = w_r / w_f
    P = np.eye(len(s_f))[::-1]
    # Raw angles: fwd = A + L s_f + W g_f; the reverse run, its angles in the first's order,
    # = A + L P s_r - W P g_r (its ring laser sees the rate with the other sign).
    h = [(s_f - P @ s_r) / 2]
    c = [(s_f + P @ s_r) / 2]
    names = ["latency"]
    if not earth_removed:
        g_f = _earth_sensitivity(fwd, fwd_angles)
        g_r = _earth_sensitivity(rev, rev_angles)
        h.append((g_f + P @ g_r) / 2)
        c.append((g_f - P @ g_r) / 2)
        names.append("earth_rate")
    return DirectionModel(np.column_stack(h), np.column_stack(c), tuple(names), rho)


def fit_direction_model(model: DirectionModel, half: np.ndarray, cov_half: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares of the half difference [rad] on the model's columns, weighted by its
    covariance (rank n - 1: the closure). Returns the parameters, their covariance and the
    half difference's residual."""
    W = np.linalg.pinv(cov_half, rcond=1e-10)
    X = model.h
    cov_theta = np.linalg.pinv(X.T @ W @ X)
    theta = cov_theta @ X.T @ W @ half
    return theta, cov_theta, half - X @ theta


def apply_direction_model(model: DirectionModel | None, comb: FaceAngles,
                          half: np.ndarray, cov_half: np.ndarray, alpha: float
                          ) -> tuple[FaceAngles, np.ndarray, str | None]:
    """The mean of both runs corrected by what the modelled effects leave; the half
    difference the model does not explain (what a reversal check judges); and a note when
    the correction is not negligible (beyond half the smallest u: speeds that differ, or a
    latency so large that a fraction of a per cent of speed difference matters).

    Without a model the plain mean and the whole half difference are returned. The
    parameters' u enters the mean's covariance: at equal speeds their columns in the mean
    are near zero and so is the correction. A residual of the half difference significant
    at ``alpha`` scales the covariance by its chi2 / dof (Birge ratio): u then covers what
    the model misses.
    """
    if model is None:
        return comb, half, None
    theta, cov_theta, resid = fit_direction_model(model, half, cov_half)
    shift = model.c @ theta
    cov = comb.cov + model.c @ cov_theta @ model.c.T
    dof = len(half) - 1 - len(theta)
    chi2 = float(resid @ np.linalg.pinv(cov_half, rcond=1e-10) @ resid)
    from scipy.special import chdtrc  # (the chi2 survival function)

    birge = chi2 / dof if dof > 0 and chdtrc(dof, chi2) < alpha else 1.0
    cov = cov * birge
    u = np.sqrt(np.diag(cov))
    fixed = replace(comb, angles_rad=comb.angles_rad - shift, cov=cov, u_rad=u)
    if np.max(np.abs(shift)) <= 0.5 * np.min(comb.u_rad) and birge == 1.0:
        return fixed, resid, None
    arcsec = np.rad2deg(1) * 3600
    fitted = ", ".join(
        f"{n} {t * 1e6:.3g} ± {np.sqrt(v) * 1e6:.2g} µs" if n == "latency" else
        f"{n} {t:.3g} ± {np.sqrt(v):.2g} rad/s"
        for n, t, v in zip(model.names, theta, np.diag(cov_theta), strict=True))
    note = (f"the reverse run at {model.speed_ratio:.3g} × the first run's speed: what scales "
            f"with the speed, fitted from the half difference ({fitted}), is cancelled by the "
            f"plain mean only at equal speed profiles; the mean corrected by up to "
            f"{float(np.max(np.abs(shift))) * arcsec:.3g}″"
            + (f", u scaled by {np.sqrt(birge):.2g} (residual chi2 {chi2:.1f} / {dof})"
               if birge > 1 else ""))
    return fixed, resid, note
