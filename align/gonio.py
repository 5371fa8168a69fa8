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
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from align.loop import Candidate, LoopReport, StageFit, Term, run_loop
from goniometry import (
    FaceAngles,
    LogSummary,
    earth_rate_counts,
    face_angles,
    kept_table,
    read_revolutions,
    vertical_earth_rate,
)
from goniometry.angles import OMEGA_EARTH

EARTH = "earth_rate"
SCALE = "scale_drift"


class RevolutionStage:
    """N_r = N0 + sum of effect columns, least squares (noise unknown: F-tests)."""

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
        self.t = (t_end[ok] - T / 2)[2:-2:2]
        self.K = float(self.N.mean()) if len(self.N) else 0.0
        self.regs = {"t": self.t, "period": self.T}

    def fit(self, terms: Sequence[Term]) -> StageFit:
        y = self.N - self.K
        cols = [np.ones_like(y)] + [np.asarray(t.columns, float).ravel() for t in terms]
        A = np.column_stack(cols)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ coef
        dof = max(len(y) - A.shape[1], 1)
        cov = np.linalg.pinv(A.T @ A) * (r @ r / dof)
        eff = {}
        for j, t in enumerate(terms, start=1):
            # Slope of counts per revolution -> the physical rate (divide by K / 2 pi).
            eff[t.name] = (float(coef[j] * 2 * np.pi / self.K),
                           float(np.sqrt(cov[j, j]) * 2 * np.pi / self.K))
        return StageFit(r, None, A.shape[1], self.regs, "t", eff,
                        {"counts_per_rev": (float(self.K + coef[0]), float(np.sqrt(cov[0, 0])))})


def candidates(stage: RevolutionStage) -> tuple[Candidate, ...]:
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


@dataclass(frozen=True)
class GonioRun:
    """A counter log through the goniometer pipeline: the revolution summary, the face angles,
    the revolution-level loop (None when it did not run) and notes for the user."""

    summary: LogSummary
    angles: FaceAngles
    loop: LoopReport | None
    notes: tuple[str, ...]
    earth_rate_applied: float | None


def measure_log(path: str | Path, n_faces: int, latitude_deg: float | None = None,
                direction: int = 1, alpha: float = 1e-3) -> GonioRun:
    """Face angles of a log; with times, the Earth rate is removed from the latitude when given,
    else by the loop when the data show it and it is physically possible.

    Raises ``LogError`` / ``ValueError`` on logs that cannot be used.
    """
    notes: list[str] = []
    loop = None
    rate_used = None
    summary = read_revolutions(path, n_faces)
    if latitude_deg is not None and summary.has_time:
        rate_used = vertical_earth_rate(latitude_deg, direction)
    elif latitude_deg is not None:
        notes.append("no t column: the Earth-rate correction needs pulse times; not applied")
    elif summary.has_time:
        counts, dt, t_end = kept_table(summary)
        loop = loop_gonio(counts, dt, t_end, alpha=alpha)
        earth = [e for e in loop.effects if e.name == EARTH]
        if earth and not plausible_earth_rate(earth[0].estimate, earth[0].u):
            notes.append(f"counts per revolution follow the period with a slope of "
                         f"{earth[0].estimate:.3g} rad/s: not the Earth's rotation; NOT applied")
        elif earth:
            rate_used = earth[0].estimate
            lat, ulat = latitude_from_earth_rate(earth[0].estimate, earth[0].u, direction)
            notes.append(f"implied latitude {np.rad2deg(lat):.1f} ± {np.rad2deg(ulat):.1f}°")
    if rate_used is not None:
        rate = rate_used
        summary = read_revolutions(path, n_faces,
                                   correct=lambda c, dt: earth_rate_counts(c, dt, rate))
    return GonioRun(summary, face_angles(summary), loop, tuple(notes), rate_used)
