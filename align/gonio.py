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

import logging
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from align.errors import InputError
from axisbase.units import ARCSEC
from goniometry import (
    FaceAngles,
    LogSummary,
    face_angles,
    kept_table,
    read_revolutions,
    vertical_earth_rate,
)
from goniometry.angles import OMEGA_EARTH
from goniometry.timing import TimingAngles, timing_angles

if TYPE_CHECKING:
    from align.loop import Candidate, LoopReport, StageFit, Term

log = logging.getLogger("align.gonio")

EARTH = "earth_rate"
LOOP_REVOLUTIONS = 20000
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


class RevolutionStage:
    """N_r = N0 + c * (the counter's quantisation pattern) + sum of effect columns, least
    squares (noise unknown: F-tests). The pattern is part of the declared model: it is how a
    counter of a steadily advancing phase behaves, not an effect."""

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
        self.pattern = None
        if len(self.N) >= 32:
            # Revolution numbers from the times: excluded revolutions leave gaps in the phase.
            Tm = float(np.median(T))
            r_all = np.round((t_end[ok] - t_end[ok][0]) / Tm).astype(np.int64)
            pred, agree, _ = quantisation_pattern(self.N, r_all[2:-2:2])
            if np.ptp(pred) > 0:
                self.pattern, self.pattern_agreement = pred - pred.mean(), agree

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
            # Slope of counts per revolution -> the physical rate (divide by K / 2 pi).
            eff[t.name] = (float(coef[j] * 2 * np.pi / self.K),
                           float(np.sqrt(cov[j, j]) * 2 * np.pi / self.K))
        return StageFit(r, None, A.shape[1], self.regs, "t", eff,
                        {"counts_per_rev": (float(self.K + coef[0]), float(np.sqrt(cov[0, 0])))})


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


@dataclass(frozen=True)
class DirectionTerm:
    """Half the difference between the counter-clockwise and clockwise estimates of each angle
    [rad] (ccw order) with its covariance: what flips with the direction — autocollimator
    latency times a speed change locked to the table, an Earth rate not removed — and which
    the mean of the two directions cancels. chi2 over n - 1 dof (closure) and its p-value."""

    half_difference_rad: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    p_value: float

    @property
    def u_rad(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))


@dataclass(frozen=True)
class GonioRun:
    """A counter log through the goniometer pipeline: the revolution summary, the face angles,
    the revolution-level loop (None when it did not run) and notes for the user. With a log
    of the other direction, ``angles`` is the mean of both, ``reverse`` that run and
    ``direction`` the term the mean cancelled."""

    summary: LogSummary
    angles: FaceAngles
    loop: LoopReport | None
    notes: tuple[str, ...]
    earth_rate_applied: float | None
    reverse: GonioRun | None = None
    direction: DirectionTerm | None = None
    timing: TimingAngles | None = None
    timing_used: bool = False
    warnings: tuple[str, ...] = ()  # options given that this log cannot honour

    def to_dict(self, faces: Sequence[str], nominal: np.ndarray | None = None) -> dict:
        """The run as JSON (the contract of ``align gonio``, also a session's stage);
        angles in degrees, uncertainties in arc-seconds at this edge. ``faces``: their
        names in passing order; ``nominal``: nominal angles [rad] for the deviations."""
        fa, summary, loop = self.angles, self.summary, self.loop
        arcsec = 1.0 / ARCSEC
        effects = [e.to_dict() for e in loop.effects] if loop is not None else []
        if self.direction is not None:
            effects.append(direction_effect(self.direction, faces))
        js = {"faces": list(faces), "angles_deg": np.rad2deg(fa.angles_rad).tolist(),
              "angles_u_arcsec": (fa.u_rad * arcsec).tolist(),
              "revolutions_used": fa.revolutions, "effects": effects,
              "unexplained_structure": bool(loop and loop.unexplained_structure),
              "covariance_arcsec2": (fa.cov * arcsec**2).tolist(),
              "type_a_arcsec": (fa.u_type_a_rad * arcsec).tolist(),
              "type_a_method": fa.type_a_method, "jitter_counts": fa.jitter_counts,
              "type_b_arcsec": (fa.u_type_b_rad * arcsec).tolist(),
              "exclusions": {k: {"count": v, "lines": summary.exclusions.lines[k]}
                             for k, v in summary.exclusions.counts.items()},
              "allan": {"tau_revolutions": fa.allan_tau_rev.tolist(),
                        "adev_arcsec": (fa.allan_dev_rad * arcsec).tolist()},
              "angles_source": "pulse times (steady table)" if self.timing_used else "counts",
              "type_b_terms_arcsec": {k: (v * arcsec).tolist()
                                      for k, v in fa.type_b_terms.items()},
              "faults": {"sigma_counts": summary.sigma_counts,
                         "tolerance_counts": summary.tolerance_counts,
                         "revolutions_excluded": summary.excluded_revolutions,
                         "armed_face": summary.armed_face,
                         "rows_before_first_revolution": summary.incomplete_head,
                         "rows_after_last_revolution": summary.incomplete_tail},
              "notes": list(self.notes)}
        if self.timing is not None:
            ta = self.timing
            js["timing"] = {"angles_deg": np.rad2deg(ta.angles_rad).tolist(),
                            "angles_u_arcsec": (ta.u_rad * arcsec).tolist(),
                            "counts_minus_timing_arcsec": (ta.diff_rad * arcsec).tolist(),
                            "counts_minus_timing_u_arcsec": (ta.diff_u_rad * arcsec).tolist(),
                            "chi2": ta.chi2, "dof": ta.dof, "p_value": ta.p_value,
                            "used": self.timing_used}
        if nominal is not None:
            js["deviation_arcsec"] = ((fa.angles_rad - nominal) * arcsec).tolist()
        return js


def combine_directions(fwd: FaceAngles, rev: FaceAngles) -> tuple[FaceAngles, DirectionTerm]:
    """Mean of a run and a run in the other direction, angles in the first run's order.

    The other direction brings the faces in reverse order (0, n-1, ..., 1): its angle m is the
    first run's angle n-1-m. Equal weights on purpose: only the plain mean cancels what flips
    sign with the direction.
    """
    n = len(fwd.angles_rad)
    if len(rev.angles_rad) != n:
        raise InputError(f"the two directions have {n} and {len(rev.angles_rad)} faces")
    P = np.eye(n)[::-1]
    a_rev = P @ rev.angles_rad
    c_rev = P @ rev.cov @ P.T
    mean = (fwd.angles_rad + a_rev) / 2
    cov = (fwd.cov + c_rev) / 4
    half = (fwd.angles_rad - a_rev) / 2
    chi2 = float(half @ np.linalg.pinv(cov, rcond=1e-10) @ half)
    from scipy.special import chdtrc  # (the chi2 survival function)

    term = DirectionTerm(half, cov, chi2, n - 1, float(chdtrc(n - 1, chi2)))
    comb = replace(
        fwd, angles_rad=mean, u_rad=np.sqrt(np.diag(cov)), cov=cov,
        u_type_a_rad=np.sqrt(fwd.u_type_a_rad**2 + (P @ rev.u_type_a_rad) ** 2) / 2,
        u_type_b_rad=np.sqrt(fwd.u_type_b_rad**2 + (P @ rev.u_type_b_rad) ** 2) / 2,
        revolutions=fwd.revolutions + rev.revolutions,
        quantisation_locked=fwd.quantisation_locked & (P @ rev.quantisation_locked > 0))
    return comb, term


DIRECTION_LIMIT_ARCSEC = 10.0
"""The largest direction-dependent part of a face angle a real reversal leaves [″]. What
flips with the direction — the autocollimator's latency times the change of the table's
speed between faces (5 µs x a 2 % ripple at 1 rev/s: 0.13″), a tilted detector slit over
pyramidal errors (10″ x tan 1°: 0.17″) — stays under a second of arc; a 'reverse' log whose
reversed angles differ from the forward run's by more is not the other direction of the same
faces (the same direction read reversed differs by the faces' deviations from equal spacing:
arc-minutes)."""


def check_reversed(fwd: FaceAngles, rev: FaceAngles, term: DirectionTerm, path,
                   reverse_log, alpha: float) -> None:
    """Refuse a reverse log that is not the forward run's faces turning the other way (its
    direction-dependent part far beyond what a reversal leaves: see
    ``DIRECTION_LIMIT_ARCSEC``), saying whether it matches the forward run unreversed."""
    worst = float(np.max(np.abs(term.half_difference_rad))) / ARCSEC
    if worst <= DIRECTION_LIMIT_ARCSEC or term.p_value >= alpha:
        return
    same = float(np.max(np.abs(fwd.angles_rad - rev.angles_rad))) / ARCSEC
    why = (f"its angles read unreversed match {Path(path).name}'s within {same:.2g}″: the "
           "table turned the same way in both runs" if same <= DIRECTION_LIMIT_ARCSEC else
           "nor do they match it unreversed (another table, or other faces)")
    raise InputError(
        f"--reverse-log {reverse_log}: reversed, its face angles differ from {path}'s by up to "
        f"{2 * worst:.3g}″ (direction-dependent part {worst:.3g}″, beyond the "
        f"{DIRECTION_LIMIT_ARCSEC:g}″ a latency or a slit tilt leaves) — it is not a run in "
        f"the other direction; {why}. Measure each log alone, or give a log of the table "
        "turning the other way")


def earth_rate_range(latitude_range_deg: tuple[float, float] | None,
                     direction: int) -> tuple[float, float]:
    """Mid-point and half-range [rad/s] of the vertical Earth rate over a latitude range
    [deg] (all latitudes when None)."""
    lo, hi = latitude_range_deg if latitude_range_deg is not None else (-90.0, 90.0)
    r1, r2 = vertical_earth_rate(lo, direction), vertical_earth_rate(hi, direction)
    return (r1 + r2) / 2, abs(r2 - r1) / 2


EARTH_BOUND = "earth_rate (latitude not given: bound over {})"


def measure_log(path: str | Path, n_faces: int, latitude_deg: float | None = None,
                direction: int = 1, alpha: float = 1e-3,
                reverse_log: str | Path | None = None, apply_loop: bool = True,
                steady_table: bool = False, columns: Mapping[str, str] | None = None,
                latitude_range_deg: tuple[float, float] | None = None,
                on_bytes: Callable[[int], None] | None = None) -> GonioRun:
    """Face angles of a log, from one pass over it.

    With times, the Earth rate is removed from the latitude when given, else by the loop
    when the data show it and it is physically possible; when neither determines it, the
    range of its effect over all latitudes (or ``latitude_range_deg``) is carried in u as a
    named Type B term (an unsteady table makes the angles depend on it). ``reverse_log``: a
    log of the same faces with the table turning the other way; the result is then the mean
    of both directions (see :func:`combine_directions`). ``steady_table``: the user asserts
    the table turns at constant speed within a revolution; the angles then come from the
    pulse times (:mod:`goniometry.timing`, jitter-limited) when the counts confirm it and the
    timing estimate is the more precise one; otherwise the counts are used and the reason is
    noted. ``columns``: header names of the log's columns (``--columns``), for both logs.

    Raises ``LogError`` / ``ValueError`` on logs that cannot be used.

    Examples
    --------
    A synthetic 50-revolution log of a 4-face table (``synth.gonio``, with its truth):

    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from synth.gonio import GonioSpec, simulate, write_log
    >>> from align import measure_log
    >>> sim = simulate(GonioSpec(revolutions=50, seed=1))
    >>> log = write_log(sim, pathlib.Path(tempfile.mkdtemp()) / "log.csv")
    >>> run = measure_log(log, 4, latitude_deg=50.45)
    >>> z = (run.angles.angles_rad - sim["truth"]["angles_rad"]) / run.angles.u_rad
    >>> bool(np.all(np.abs(z) < 4))
    True
    """
    if reverse_log is not None:
        # Without the latitude the mean of the two directions cancels the Earth rate itself
        # (it flips sign with the direction): no loop estimate is applied to either run.
        fwd = measure_log(path, n_faces, latitude_deg, direction, alpha, apply_loop=False,
                          steady_table=steady_table, columns=columns, on_bytes=on_bytes)
        rev = measure_log(reverse_log, n_faces, latitude_deg, -direction, alpha,
                          apply_loop=False, steady_table=steady_table, columns=columns,
                          on_bytes=on_bytes)
        comb, term = combine_directions(fwd.angles, rev.angles)
        check_reversed(fwd.angles, rev.angles, term, path, reverse_log, alpha)
        notes = [*(n for n in fwd.notes if not n.startswith(LATENCY)),
                 *(f"reverse run: {n}" for n in rev.notes if not n.startswith(LATENCY)),
                 f"both directions combined: the direction-dependent part is "
                 f"{'significant' if term.p_value < alpha else 'not significant'} "
                 f"(chi2 {term.chi2:.1f} / {term.dof}, p {term.p_value:.2g}) and cancelled"]
        # (both directions: the latency bias cancels, its one-direction warning does not hold)
        warns = (*(w for w in fwd.warnings if not w.startswith(LATENCY)),
                 *(f"reverse run: {w}" for w in rev.warnings if not w.startswith(LATENCY)))
        return GonioRun(fwd.summary, comb, fwd.loop, tuple(notes), fwd.earth_rate_applied,
                        rev, term, fwd.timing, fwd.timing_used and rev.timing_used,
                        tuple(warns))
    notes: list[str] = []
    loop = None
    if "align.loop" not in sys.modules:
        # The loop's modules (scipy.special: ~0.3 s; the loop, the warnings and the report
        # need them) load during the pass, whose parser threads release the GIL.
        import threading
        from importlib import import_module

        threading.Thread(target=import_module, args=("align.loop",), daemon=True).start()
    early = {}
    hook = None
    if latitude_deg is None:
        def hook(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None) -> None:
            # The loop sees only the head of the log: it runs while the rest is read. (A
            # shorter log hands over at its end, not yet checked: the loop runs after.)
            if dt is not None and len(counts) >= LOOP_REVOLUTIONS:
                from concurrent.futures import ThreadPoolExecutor

                pool = ThreadPoolExecutor(1, thread_name_prefix="loop")
                early["loop"] = pool.submit(loop_gonio, counts, dt, t_end, alpha)
                pool.shutdown(wait=False)
    start = time.perf_counter()
    summary = read_revolutions(path, n_faces, columns=columns, on_kept=hook,
                               on_kept_at=LOOP_REVOLUTIONS, on_bytes=on_bytes)
    log.debug("gonio %s: one pass in %.2f s: %d rows, %d revolutions excluded "
              "(%s), times %s", Path(path).name, time.perf_counter() - start, summary.rows,
              summary.excluded_revolutions,
              ", ".join(f"{n} x {r}" for r, n in summary.exclusions.counts.items()) or "none",
              "present" if summary.has_time else "absent")
    if summary.armed_face:
        notes.append(f"log armed on face {summary.armed_face}: the first "
                     f"{summary.incomplete_head} rows are a partial revolution, not used")
    elif summary.incomplete_head:
        # Not a fault: the arming pulse fits no face (armed between faces).
        notes.append(f"lead-in: the first {summary.incomplete_head} rows, from the arming "
                     "pulse to the first complete revolution, are not used")
    if latitude_deg is not None and summary.has_time:
        rate = vertical_earth_rate(latitude_deg, direction)
        return _with_timing(GonioRun(summary, face_angles(summary, rate), None, tuple(notes),
                                     rate), steady_table, alpha)
    if latitude_deg is not None:
        why = ("latitude given, but the log has no t column: the Earth-rate correction needs "
               "pulse times; NOT applied (nor can a table speed that follows its angle be "
               "seen, which with autocollimator latency biases one direction: measure both)")
        notes.append(why)
        return _with_timing(GonioRun(summary, face_angles(summary), None, tuple(notes), None,
                                     warnings=(why,)), steady_table, alpha)
    if not summary.has_time:
        notes.append("no t column: the Earth rate on an unsteady table can be neither removed "
                     "nor bounded without pulse times; the angles assume a steady table")
        return _with_timing(GonioRun(summary, face_angles(summary), None, tuple(notes), None),
                            steady_table, alpha)
    # The loop sees the first LOOP_REVOLUTIONS (it fits a handful of revolution-level terms:
    # 10^4 revolutions pin the Earth rate to ~1e-6 rad/s; more only cost time), started by
    # the pass as soon as it had them.
    if "loop" in early:
        loop = early["loop"].result()
    else:
        counts, dt, t_end = kept_table(summary)
        m = LOOP_REVOLUTIONS
        loop = loop_gonio(counts[:m], dt[:m], t_end[:m], alpha=alpha)
    earth = [e for e in loop.effects if e.name == EARTH]
    log.debug("gonio: Earth rate from the loop: %s (plausible if |rate| <= %.4g rad/s + 3 u)",
              f"{earth[0].estimate:.4g} ± {earth[0].u:.2g} rad/s" if earth else "not seen",
              OMEGA_EARTH)
    if earth and not plausible_earth_rate(earth[0].estimate, earth[0].u):
        notes.append(f"counts per revolution follow the period with a slope of "
                     f"{earth[0].estimate:.3g} rad/s: not the Earth's rotation; NOT applied")
    elif earth and not apply_loop:
        notes.append(f"Earth rate seen ({earth[0].estimate:.3g} ± {earth[0].u:.2g} rad/s), "
                     "not applied: the other direction cancels it")
        return _with_timing(GonioRun(summary, face_angles(summary), loop, tuple(notes), None),
                            steady_table, alpha)
    elif earth and loop.unexplained_structure:
        notes.append(f"Earth rate seen ({earth[0].estimate:.3g} ± {earth[0].u:.2g} rad/s) but "
                     "structure remains that the loop does not explain: not taken as "
                     "determined")
    elif earth:
        rate, rate_u = earth[0].estimate, earth[0].u
        lat, ulat = latitude_from_earth_rate(rate, rate_u, direction)
        notes.append(f"implied latitude {np.rad2deg(lat):.1f} ± {np.rad2deg(ulat):.1f}°; "
                     "its uncertainty is carried into the angles")
        return _with_timing(GonioRun(summary, face_angles(summary, rate, rate_u), loop,
                                     tuple(notes), rate), steady_table, alpha)
    if not apply_loop:
        return _with_timing(GonioRun(summary, face_angles(summary), loop, tuple(notes), None),
                            steady_table, alpha)
    # Not determined by the log: its bound over the latitudes enters u (Type B), named.
    mid, half = earth_rate_range(latitude_range_deg, direction)
    where = ("all latitudes" if latitude_range_deg is None else
             f"latitudes {latitude_range_deg[0]:g}..{latitude_range_deg[1]:g}°")
    name = EARTH_BOUND.format(where)
    fa = face_angles(summary, mid, type_b={name: half})
    worst = float(np.max(fa.type_b_terms[name])) * np.rad2deg(1) * 3600
    notes.append(f"Earth rate not determined by this log and no --latitude: its effect over "
                 f"{where} (up to {worst:.3g}″ per angle) is carried in u as a Type B term")
    return _with_timing(GonioRun(summary, fa, loop, tuple(notes), mid or None), steady_table,
                        alpha)


LATENCY = "one direction only, on a table whose speed varies with its angle"


def latency_sensitivity(counts: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Change of each angle [rad] per second of autocollimator latency, from the table's mean
    speed at each face (the mean of the intervals either side of it, angle over duration):
    a pulse late by L reads the face L * speed further on, so angle k moves by
    L * (speed at face k+1 - speed at face k)."""
    a = counts / counts.sum(1, keepdims=True) * 2 * np.pi
    w = np.mean(a / dt, axis=0)  # mean speed over each interval [rad/s]
    at_face = (np.roll(w, 1) + w) / 2  # face k: between interval k-1 and interval k
    return np.roll(at_face, -1) - at_face


def _latency_check(run: GonioRun, alpha: float) -> GonioRun:
    """Warn when the table's speed is locked to its angle (the pulse-time fractions differ
    from the count fractions): then any latency of the autocollimator biases one direction's
    angles, which only the other direction cancels (--reverse-log); the log cannot tell the
    latency. Stated per microsecond of it."""
    if not run.summary.has_time or run.timing_used:
        return run
    counts, dt, _ = kept_table(run.summary)
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    if ok.sum() < 16:
        return run
    ta = run.timing if run.timing is not None else timing_angles(run.summary)
    if ta.p_value >= alpha or ta.stamp_limited:
        return run
    per_us = float(np.max(np.abs(latency_sensitivity(counts[ok], dt[ok])))) * 1e-6
    arcsec = np.rad2deg(1) * 3600
    why = (f"{LATENCY} (pulse-time and count fractions differ, p {ta.p_value:.2g}): each µs "
           f"of autocollimator latency biases an angle by up to {per_us * arcsec:.3g}″ (u is "
           f"{float(np.max(run.angles.u_rad)) * arcsec:.3g}″), and the log cannot tell the "
           "latency; measure the other direction too (--reverse-log) to cancel it")
    return replace(run, notes=(*run.notes, why), warnings=(*run.warnings, why))


def _with_timing(run: GonioRun, steady_table: bool, alpha: float) -> GonioRun:
    """Replace the count angles by the timing angles when asked, confirmed and better; warn
    of a latency bias the log cannot determine (see _latency_check)."""
    return _latency_check(_timing_choice(run, steady_table, alpha), alpha)


def _timing_choice(run: GonioRun, steady_table: bool, alpha: float) -> GonioRun:
    if not steady_table:
        return run
    if not run.summary.has_time:
        why = ("steady table asked, but the log has no t column (pulse times): the angles are "
               "from the counts")
        return replace(run, notes=(*run.notes, why), warnings=(*run.warnings, why))
    ta = timing_angles(run.summary)
    arcsec = np.rad2deg(1) * 3600
    worst = float(np.max(np.abs(ta.diff_rad))) * arcsec
    if ta.p_value < alpha:
        why = ("a speed ripple locked to the table" if not ta.stamp_limited else
               f"time stamps too coarse ({ta.stamp_resolution_s:.2g} s, locked to the table's "
               "period) or a speed ripple locked to the table")
        note = (f"steady table NOT confirmed: the counts differ from the pulse-time fractions by "
                f"up to {worst:.3f}″ (chi2 {ta.chi2:.1f} / {ta.dof}, p {ta.p_value:.2g}) — "
                f"{why}; counts used")
        return replace(run, timing=ta, notes=(*run.notes, note))
    if np.all(ta.u_rad >= run.angles.u_rad) and ta.stamp_limited:
        note = (f"steady table confirmed, but the time stamps' resolution "
                f"({ta.stamp_resolution_s:.2g} s) limits the pulse-time angles to "
                f"±{float(np.max(ta.u_rad)) * arcsec:.3f}″: counts used")
        return replace(run, timing=ta, notes=(*run.notes, note))
    if np.all(ta.u_rad >= run.angles.u_rad):
        note = ("steady table confirmed, but the pulse times are the noisier estimate (speed "
                "wander within revolutions): counts used")
        return replace(run, timing=ta, notes=(*run.notes, note))
    fa = replace(run.angles, angles_rad=ta.angles_rad, u_rad=ta.u_rad, cov=ta.cov)
    note = (f"angles from pulse times (steady table, confirmed by the counts to "
            f"±{float(np.max(ta.diff_u_rad)) * arcsec:.3f}″ per angle, chi2 {ta.chi2:.1f} / "
            f"{ta.dof}); a locked ripple below that is not excluded")
    return replace(run, angles=fa, timing=ta, timing_used=True, notes=(*run.notes, note))


def direction_effect(term: DirectionTerm, faces: Sequence[str]) -> dict:
    """The direction-dependent term as an entry of the JSON ``effects`` list: per angle the
    half difference ccw - cw [rad]; the most significant one is the estimate; after the mean
    of both directions it is cancelled (rms_after 0)."""
    n = len(faces)
    k = int(np.argmax(np.abs(term.half_difference_rad) / term.u_rad))
    return {"name": "direction_dependent", "estimate": float(term.half_difference_rad[k]),
            "u": float(term.u_rad[k]), "unit": "rad",
            "rms_before": float(np.sqrt(np.mean(term.half_difference_rad**2))),
            "rms_after": 0.0, "p_value": term.p_value, "chi2": term.chi2, "dof": term.dof,
            "components": [{"axis": f"{faces[i]}->{faces[(i + 1) % n]}",
                            "estimate": float(term.half_difference_rad[i]),
                            "u": float(term.u_rad[i])} for i in range(n)]}


# A housing's faces are made to arc-seconds or arc-minutes of their nominal angles; a
# deviation beyond a degree is no face error but a nominal that does not describe these
# faces (a typo, names or nominal in another order, the wrong --direction). An absolute
# limit, not one in u: u is ~0.1″ here, so real face errors of tens of arc-seconds are
# hundreds of u and must not be flagged.
NOMINAL_LIMIT_RAD = np.deg2rad(1.0)


def nominal_mismatch(angles_rad: np.ndarray, nominal_rad: np.ndarray,
                     faces: Sequence[str]) -> list[str]:
    """Warnings for the angles [rad] farther than NOMINAL_LIMIT_RAD from their nominal."""
    n = len(faces)
    dev = np.asarray(angles_rad) - np.asarray(nominal_rad)
    bad = np.flatnonzero(np.abs(dev) > NOMINAL_LIMIT_RAD)
    if not bad.size:
        return []
    what = ", ".join(f"{faces[i]}->{faces[(i + 1) % n]} {np.rad2deg(angles_rad[i]):.4f}° vs "
                     f"{np.rad2deg(nominal_rad[i]):g}°" for i in bad)
    return [f"the nominal angles do not describe these faces (measured vs nominal: {what}; "
            f"more than {np.rad2deg(NOMINAL_LIMIT_RAD):g}° off, far beyond any face error): "
            "check the order of the faces and of the nominal, and --direction"]
