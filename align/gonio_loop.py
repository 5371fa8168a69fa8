"""The residual loop over the goniometer log, at the level where the effects show.

Observations: the counts of each whole revolution, N_r [ring-laser periods]. Declared model:
a constant N (the closure normalisation assumes each revolution is exactly 360 deg of the
table). Candidates (need pulse times):

* ``earth_rate`` — the ring laser counts inertial rotation, so N_r = K (1 + Omega_v T_r / 2 pi)
  with Omega_v = d Omega_E sin(latitude): when the table's period T_r wanders, N_r follows
  it. Its estimate gives Omega_v [rad/s] (and the latitude); the counts are then corrected
  interval by interval, which removes the bias an unsteady table leaves in the face angles.
* ``scale_drift`` — the ring laser's scale factor drifting in time: N_r trends with t.

Why not per interval: an interval's duration carries the autocollimator's timing jitter,
which is also in its count, so any duration regressor there finds the jitter, not the Earth.
A speed ripple locked to the table angle gives the same Earth-rate bias in every revolution:
no residual shows it, which is why the latitude (``--latitude``) is the first-class input
and this loop the fallback. A once-per-revolution error locked to the table is likewise
absorbed by the face angles (only a reversal on the table separates it).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from goniometry.angles import OMEGA_EARTH

if TYPE_CHECKING:
    from align.loop import Candidate, LoopReport, StageFit, Term

EARTH = "earth_rate"
SCALE = "scale_drift"


def quantisation_pattern(N: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The counter's own pattern in counts per revolution, and its fraction of agreement.

    With the ring-laser phase at reference pulse r being phi0 + r F (a steady table: F counts
    per revolution, not an integer), N_r = floor(phi0 + (r + 1) F) - floor(phi0 + r F): the
    floor or the ceiling of F in a deterministic beat that the structure tests rightly see as
    non-random. (phi0, frac F) are found by a coarse-to-fine search over growing prefixes of
    the log (each step keeps the phase error over its span below 0.1 count), the jitter's blur
    of each floor by a search over its width. Returns the expected N_r, the fraction of
    revolutions the sharp pattern predicts exactly, and frac F. With a wandering table the
    pattern dithers and the agreement falls to chance.
    """
    F = float(np.mean(N))
    base = np.floor(F)
    b = N - base
    rr = (r - r[0]).astype(float)
    phis = (np.arange(200) + 0.5) / 200
    lo, hi = F - base - 0.1, F - base + 0.1
    best = (0.0, F - base)
    n_use = 64
    while True:
        n_use = min(n_use, len(b))
        x, y = rr[:n_use], b[:n_use]
        step = 0.1 / (x[-1] + 1)
        fs = np.arange(lo, hi + step, step)
        score = np.empty((len(fs), len(phis)))
        for i, f in enumerate(fs):
            pred = (phis[:, None] + x[None, :] * f) % 1.0 >= 1.0 - (f % 1.0)
            score[i] = (pred == (y[None, :] >= 1)).sum(1)
        i, j = np.unravel_index(int(np.argmax(score)), score.shape)
        best = (phis[j] % 1.0, fs[i])
        if n_use == len(b):
            break
        lo, hi = fs[i] - 3 * step, fs[i] + 3 * step
        # The phase is known to ~1/n_use after a stage: the next searches only near it
        # (the whole 200-point grid at every stage cost 5 s at 25000 revolutions).
        phis = phis[j] + np.arange(-6, 7) * 0.005
        n_use *= 4
    phi, f = best
    a, b_ = phi + rr * f, phi + (rr + 1) * f
    hard = base + np.floor(b_) - np.floor(a)
    # The autocollimator's jitter (sigma, in counts) blurs each floor near its step: the
    # expected floor(x + e) is floor(x) + Phi((frac x - 1) / sigma) - Phi(-frac x / sigma).
    # sigma by a 1-D search on the residual.
    from scipy.special import ndtr  # (the normal CDF; scipy.stats costs 0.8 s to import)

    def soft(sig: float) -> np.ndarray:
        def h(x: np.ndarray) -> np.ndarray:
            fr = x % 1.0
            return ndtr((fr - 1) / sig) - ndtr(-fr / sig)
        return hard + h(b_) - h(a)

    sigmas = np.geomspace(0.005, 0.5, 24)
    rss = [float(np.sum((N - soft(sg)) ** 2)) for sg in sigmas]
    pred = soft(float(sigmas[int(np.argmin(rss))]))
    return pred, float(np.mean(hard == N)), float(f % 1.0)


SEQUENCE_ABOVE_COUNTS = 1.0
"""Residual RMS [counts] of the declared fit above which the order tests (runs, Ljung-Box,
periodogram) apply to the revolution counts. Below it the residual is the counter's
quantisation (a count difference of two floors: at most ±1, RMS 1/sqrt(6) = 0.41) where
the pattern misses it — a wandering table dithers the beat, and the ±1 flips then come in
stretches wherever the fractional phase lingers near an integer (slowly: by frac F a
revolution). Such stretches are how the counter works, not noise in order: on clean logs
(120 revolutions, 2 % ripple, 1 % wander, no --latitude) the order tests flagged 20 of 300
(docs/decisions.md). The effects' F-tests and the residual's correlation with time and
period (the regressor tests) still apply."""


class RevolutionStage:
    """N_r = N0 + c * (the counter's quantisation pattern) + sum of effect columns, least
    squares (noise unknown: F-tests). The pattern is part of the declared model: it is how a
    counter of a steadily advancing phase behaves, not an effect. When the declared fit's
    residual is within the quantisation (:data:`SEQUENCE_ABOVE_COUNTS`), the structure tests
    leave out those on the residuals' order."""

    def __init__(self, counts: np.ndarray, dt: np.ndarray, t_end: np.ndarray):
        ok = np.all(np.isfinite(dt), axis=1)
        N = counts[ok].sum(1)
        T = dt[ok].sum(1)
        # The period regressor must not share a pulse with the revolution it explains: the
        # reference pulses' jitter moves N_r and T_r together (slope omega, not the Earth's
        # rate). Revolutions r-2 and r+2 share none; the wander is slow enough to follow.
        # Every other revolution: consecutive ones share a reference pulse, whose quantisation
        # and jitter make their counts anti-correlated (lag-1 r = -0.3 to -0.5) by
        # construction, which is not an effect.
        self.N = N[2:-2:2]
        self.T = ((T[:-4] + T[4:]) / 2)[::2]
        # The slope on this proxy is the slope on T_r times lam = cov(T_r, proxy) /
        # var(proxy): 1.04-1.08 on a table wandering over ~20 revolutions (the Earth rate
        # read 4-8 % high, 4-8 u over 300 revolutions). lam is measured from the periods
        # themselves (T_r's own pulse jitter is independent of the proxy's, so it does not
        # bias lam) and divided out in fit(): one correction for the loop and the
        # declared-latitude check alike.
        self.measured_attenuation = float("nan")
        if len(self.N) >= 3 and np.var(self.T) > 0:
            self.measured_attenuation = float(np.cov(T[2:-2:2], self.T)[0, 1]
                                              / np.var(self.T, ddof=1))
        lam = self.measured_attenuation
        # (not measurable — a steady table, whose proxy does not follow T_r — none applied)
        self.attenuation = lam if np.isfinite(lam) and lam > 0 else 1.0
        self.t = (t_end[ok] - T / 2)[2:-2:2]
        self.K = float(self.N.mean()) if len(self.N) else 0.0
        self.regs = {"t": self.t, "period": self.T}
        self.pattern = None
        if len(self.N) >= 32:
            # Revolution numbers from the times: excluded revolutions leave gaps in the phase.
            Tm = float(np.median(T))
            r_all = np.round((t_end[ok] - t_end[ok][0]) / Tm).astype(np.int64)
            pred, agree, _ = quantisation_pattern(self.N, r_all[2:-2:2])
            if np.ptp(pred) > 0:
                self.pattern, self.pattern_agreement = pred - pred.mean(), agree
        self.sequence = True
        if len(self.N) > 2:
            declared = self.fit(())
            self.sequence = declared.rms > SEQUENCE_ABOVE_COUNTS

    def fit(self, terms: Sequence[Term]) -> StageFit:
        from align.loop import StageFit

        y = self.N - self.K
        base = [np.ones_like(y)] + ([self.pattern] if self.pattern is not None else [])
        cols = base + [np.asarray(t.columns, float).ravel() for t in terms]
        A = np.column_stack(cols)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ coef
        dof = max(len(y) - A.shape[1], 1)
        cov = np.linalg.pinv(A.T @ A) * (r @ r / dof)
        eff = {}
        for j, t in enumerate(terms, start=len(base)):
            # Slope of counts per revolution -> the physical quantity: against the period,
            # the rate (N = K (1 + rate T / 2 pi): divide by K / 2 pi); against time, the
            # scale factor's relative drift (N = K (1 + kappa t): divide by K).
            per = (2 * np.pi / self.K / self.attenuation if t.name == EARTH
                   else 1.0 / self.K)
            eff[t.name] = (float(coef[j] * per), float(np.sqrt(cov[j, j]) * per))
        return StageFit(r, None, A.shape[1], self.regs, "t", eff,
                        {"counts_per_rev": (float(self.K + coef[0]), float(np.sqrt(cov[0, 0])))},
                        sequence=self.sequence)


def candidates(stage: RevolutionStage) -> tuple[Candidate, ...]:
    from align.loop import Candidate, Term

    T = stage.T - stage.T.mean()
    t = stage.t - stage.t.mean()
    return (
        Candidate(EARTH, "rad/s", "Earth's rotation: counts per revolution follow its period",
                  lambda fit: Term(EARTH, "rad/s", T[:, None]) if np.ptp(T) > 0 else None),
        Candidate(SCALE, "1/s", "ring-laser scale factor drifting in time",
                  lambda fit: Term(SCALE, "1/s", t[:, None]) if np.ptp(t) > 0 else None),
    )


def loop_gonio(counts: np.ndarray, dt: np.ndarray, t_end: np.ndarray,
               alpha: float = 1e-3) -> LoopReport:
    from align.loop import run_loop

    stage = RevolutionStage(counts, dt, t_end)
    return run_loop(stage, candidates(stage), alpha=alpha)


def plausible_earth_rate(rate: float, u: float) -> bool:
    """Whether a fitted vertical rate can be the Earth's (|rate| <= Omega_E within 3 u)."""
    return abs(rate) <= OMEGA_EARTH + 3 * u


def latitude_from_earth_rate(rate: float, u: float, direction: int) -> tuple[float, float]:
    """Latitude [rad] and its u implied by a fitted vertical Earth rate [rad/s]."""
    s = np.clip(rate / (direction * OMEGA_EARTH), -1, 1)
    lat = float(np.arcsin(s))
    return lat, float(u / OMEGA_EARTH / max(np.cos(lat), 1e-6))


def seen_earth_rate(counts: np.ndarray, dt: np.ndarray, t_end: np.ndarray
                    ) -> tuple[float, float] | None:
    """The vertical rate [rad/s] the log's counts per revolution show against their period,
    and its u, fitted whether significant or not (with a scale drift in time beside it, so
    a trend in both is not taken for the Earth), scaled from the proxy period to the
    revolution's own. None when the period does not vary enough
    to carry it (a steady table) or the log is too short."""
    from align.loop import Term

    # The rate shows as counts per revolution that follow the period: the largest Earth rate
    # over the period's spread must move them by a count (their quantum) for the log to
    # carry it; a steady table's periods differ by pulse jitter only, and the fit on them
    # returned nonsense (15 rad/s at u 1e-14 on a clean log, a false warning). The raw
    # periods spread at least as far as the stage's averaged ones: tested first, they spare
    # a steady table's log the stage (its quantisation pattern is most of its cost).
    ok = np.all(np.isfinite(dt), axis=1)
    per_count = OMEGA_EARTH * float(counts[ok].sum(1).mean()) / (2 * np.pi) if ok.any() else 0.0
    if ok.sum() < 36 or per_count * np.ptp(dt[ok].sum(1)) < 1.0:
        return None
    stage = RevolutionStage(counts, dt, t_end)
    if len(stage.N) < 16 or OMEGA_EARTH * np.ptp(stage.T) * stage.K / (2 * np.pi) < 1.0:
        return None
    T = stage.T - stage.T.mean()
    t = stage.t - stage.t.mean()
    terms = [Term(EARTH, "rad/s", T[:, None])]
    if np.ptp(t) > 0:
        terms.append(Term(SCALE, "1/s", t[:, None]))
    est, u = stage.fit(terms).effects[EARTH]  # (the proxy's attenuation divided out)
    if not (np.isfinite(u) and u > 0 and stage.measured_attenuation > 0):
        return None
    return est, u
