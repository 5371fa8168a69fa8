"""Angles from pulse times on a steady table, and the latency a one-direction run cannot tell.

``steady_table``: the user asserts the table turns at constant speed within a revolution; the
pulse-time angles (:mod:`goniometry.timing`) replace the count angles when the counts confirm
it and they are the more precise. Either way, a table whose speed is locked to its angle makes
any autocollimator latency bias one direction's angles: a warning names the bias per µs.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from goniometry import kept_table
from goniometry.timing import timing_angles

if TYPE_CHECKING:
    from align.gonio_run import GonioRun
    from goniometry.timing import TimingAngles


LATENCY = "one direction only, on a table whose speed varies with its angle"


def latency_sensitivity(counts: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Change of each angle [rad] per second of autocollimator latency, from the table's
    speed at each face: a pulse late by L reads the face L * speed further on, so angle k
    moves by L * (speed at face k+1 - speed at face k).

    The pulse times give each interval's mean speed (angle over duration); the speed at a
    face, half an interval before the centre of the interval it starts, is found per
    harmonic of the revolution (the band-limited interpolation of the n means: harmonic m
    shifted by half an interval and divided by sinc(m / n), the mean's attenuation). The mean
    of the two intervals either side, used before, attenuates a once-per-revolution ripple by
    cos(pi / n) sinc(1 / n) (0.64 with 4 faces): latencies fitted with it came out 1.57 x
    too large and their corrections did not cancel what they should.
    """
    a = counts / counts.sum(1, keepdims=True) * 2 * np.pi
    w = np.mean(a / dt, axis=0)  # mean speed over each interval [rad/s]
    n = len(w)
    m = np.arange(n // 2 + 1)
    # (the Nyquist harmonic of an even n is zero at the faces: irfft keeps its real part, 0)
    at_face = np.fft.irfft(np.fft.rfft(w) * np.exp(-1j * np.pi * m / n) / np.sinc(m / n), n)
    return np.roll(at_face, -1) - at_face


def count_floors_explain(counts: np.ndarray, ta: TimingAngles) -> bool:
    """Whether the counts' own floors explain how the pulse-time and count fractions differ:
    a locked ring laser (a whole number of counts a revolution) floors each interval at the
    same phase every revolution, so its fractions barely scatter (below half the dithered
    q/√6) and keep an error of up to one count q for good, which no average removes. A
    difference within q (+ 3 u of the timing) is then no sign of a speed that varies with
    the angle (and a ripple that small, ~1e-5 of the speed, moves an angle by ~1e-8 rad per
    100 µs of latency); beyond it, or with dithered counts, the χ² decides."""
    n_rev = counts.sum(1)
    q = 2 * np.pi / float(n_rev.mean())  # one count [rad]
    a_c = 2 * np.pi * counts / n_rev[:, None]
    locked = bool(np.all(a_c.std(0) < 0.5 * q / np.sqrt(6)))
    return locked and bool(np.all(np.abs(ta.diff_rad) <= q + 3 * ta.diff_u_rad))


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
    if ta.p_value >= alpha or ta.stamp_limited or count_floors_explain(counts[ok], ta):
        return run
    per_us = float(np.max(np.abs(latency_sensitivity(counts[ok], dt[ok])))) * 1e-6
    arcsec = np.rad2deg(1) * 3600
    why = (f"{LATENCY} (pulse-time and count fractions differ, p {ta.p_value:.2g}): each µs "
           f"of autocollimator latency biases an angle by up to {per_us * arcsec:.3g}″ (u is "
           f"{float(np.max(run.angles.u_rad)) * arcsec:.3g}″), and the log cannot tell the "
           "latency; measure the other direction too (--reverse-log) to cancel it")
    return replace(run, notes=(*run.notes, why), warnings=(*run.warnings, why))


def with_timing(run: GonioRun, steady_table: bool, alpha: float) -> GonioRun:
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
