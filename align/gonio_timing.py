"""Angles from pulse times on a steady table, and the latency a one-direction run cannot tell.

``steady_table``: the user asserts the table turns at constant speed within a revolution; the
pulse-time angles (:mod:`goniometry.timing`) replace the count angles when the counts confirm
it and they are the more precise. Otherwise, counts and pulse-time fractions that disagree
beyond noise in one direction's log (a counter losing counts, or a table whose speed is locked
to its angle, where any autocollimator latency biases the angles) are carried in its u as a
Type B term (with, on a table whose speed follows its angle, a latency up to the bound the
user declares, always carried in u; undeclared, up to :data:`LATENCY_BOUND_S`, or the result
is not ok where that bound's bias exceeds u: :func:`bound_disagreement`). The counters' part
is what a ripple's first order, modelled over the faces (:mod:`align.gonio_ripple`), leaves in
their alternating pattern; counters the user declares sound carry none, and the result is not
ok where a ripple's second order does not explain that pattern.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from align.gonio_ripple import RippleFit, fit_ripple
from goniometry import kept_table
from goniometry.timing import timing_angles

if TYPE_CHECKING:
    from align.gonio_run import GonioRun
    from goniometry import FaceAngles
    from goniometry.timing import TimingAngles


LATENCY = "one direction only: the counts and the pulse-time fractions disagree"
"""How the warning begins that one direction's counts and pulse times disagree."""
DISAGREEMENT = "counts vs pulse times (a counter losing counts, or latency on an unsteady table)"
"""The Type B term that carries that disagreement in one direction's u."""
LATENCY_TERM = "autocollimator latency (up to its bound) on a table whose speed varies"
"""The Type B term of a latency up to the bound (declared, else :data:`LATENCY_BOUND_S`) on a
table whose speed follows its angle."""
LATENCY_BOUND_S = 1e-3
"""Latency [s] of the autocollimator's face pulse assumed as the bound when one direction's
table speed is seen to follow its angle: a photoelectric trigger is µs, an imaging
autocollimator's frame up to ~1 ms. Where it could bias an angle beyond u the result is not
ok (the other direction cancels any latency) unless the user declares the autocollimator's
latency bound (:data:`DECLARE`)."""
DECLARE = ("declare the autocollimator's latency bound (--latency-max-us, or latency_max_us in "
           "[goniometer]) or measure the other direction (--reverse-log)")
"""What a user does when one direction's latency is undetermined and undeclared."""


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


def disagreement(run: GonioRun, alpha: float) -> TimingAngles | None:
    """The pulse-time angles when they and the counts disagree beyond noise (p < ``alpha``)
    for a reason other than the stamps' resolution or a locked ring laser's own floors (see
    :func:`count_floors_explain`); None otherwise, with the pulse-time angles in use, or
    without times (or with fewer than 16 timed revolutions)."""
    if not run.summary.has_time or run.timing_used:
        return None
    counts, dt, _ = kept_table(run.summary)
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    if ok.sum() < 16:
        return None
    ta = run.timing if run.timing is not None else timing_angles(run.summary)
    if ta.p_value >= alpha or ta.stamp_limited or count_floors_explain(counts[ok], ta):
        return None
    return ta


def beyond_counters(ta: TimingAngles) -> tuple[np.ndarray, float]:
    """The part of the counts' difference from the pulse-time angles [rad] that no counter
    can make, and its p-value.

    The two counters alternate row by row, so with an even number of faces each interval is
    always counted by the same one: a counter that loses (or gains) counts at its switches
    moves the angles by the alternating pattern (+, -, +, ...) only. With an odd number each
    interval alternates counters from one revolution to the next and the loss is the same in
    every interval (it cancels in the fractions). What is left once that pattern is fitted
    (weighted by the difference's u) is a speed that follows the angle; its chi2 over n - 2
    degrees of freedom (the closure, the pattern) gives the p-value."""
    from scipy.special import chdtrc  # (the chi2 survival function)

    d, du = ta.diff_rad, ta.diff_u_rad
    n = len(d)
    w = 1 / du ** 2
    if n % 2 == 0:
        pat = (-1.0) ** np.arange(n)
        rest = d - pat * float(np.sum(w * d * pat) / np.sum(w * pat ** 2))
        dof = n - 2
    else:
        rest, dof = d, n - 1
    chi2 = float(np.sum(w * rest ** 2))
    return rest, float(chdtrc(dof, chi2)) if dof > 0 else 1.0


COUNTERS_SOUND = "counters declared sound (--counters-sound, or counters_sound in [goniometer])"
"""How the note begins that states the user's declaration that the counters lose no counts."""


def counters_part(run: GonioRun, ta: TimingAngles) -> RippleFit:
    """What a table whose speed follows its angle leaves of the counts' difference from the
    pulse-time angles in the counters' alternating pattern (:func:`align.gonio_ripple.
    fit_ripple`, over the faces where the counts put them).

    The harmonic projection on +, -, +, ... used before, blind to the faces' spacing, charged
    to the counters what a once-a-revolution ripple makes over faces that are not equally
    spaced: 1.3-1.6″ on user 6's 1 % ripple and 356″ polygon (u 0.094″ -> 0.77″ for sound
    counters). What the first order leaves there is the counters' part: a counter's, or the
    ripple's second order, which one log does not tell apart."""
    return fit_ripple(run.angles.angles_rad, ta.diff_rad, ta.diff_cov)


def bound_disagreement(run: GonioRun, alpha: float, latency_max_s: float | None = None,
                       counters_sound: bool = False) -> GonioRun:
    """One direction's result when its counts and pulse times disagree beyond noise: the
    difference carried in u (Type B, :data:`DISAGREEMENT`) when a counter could make it, or
    the result not ok when the table's speed follows its angle; a warning names the causes.

    Two measures of the same angles that differ far beyond their noise mean one of them is
    wrong, and the log cannot say which: a counter that loses or gains counts at each switch
    (the counts are then off by the difference), or a table whose speed follows its angle (the
    pulse times' fractions are then not the angles', and any autocollimator latency L biases
    the counts' angles by L times the speed's change between faces, which only the other
    direction cancels). A difference in the counters' own pattern (:func:`beyond_counters`)
    is carried in u: d_k / sqrt(3) per angle puts both candidates, the counts' angle and the
    pulse times', within u's 2-sigma interval (the interval between them taken as uniform),
    correlated along the difference's own pattern (its sum is zero: the closure is kept); it
    also covers a latency on whatever ripple the difference allows up to |d_k / s_k| (s: the
    bias per second of latency). A difference beyond that pattern is a speed that follows
    the angle: the ripple is modelled over the faces (:func:`counters_part`) and what its
    first order leaves in the counters' pattern is carried; and the
    latency's bias has no bound in one direction's log: a bound the user declares
    (``latency_max_s``, from the autocollimator's specification; 0: no latency, no term) is
    always carried in u (with the counters' pattern's part), however wide; undeclared,
    up to :data:`LATENCY_BOUND_S` it is carried in u where it stays within u, and beyond u the
    result is not ok (its u left as it is). A clean log has neither.

    Counters the user declares sound (``counters_sound``: their dead time verified) carry no
    counters' part: the whole difference is then the table's speed, and the ripple model must
    explain it — what the first order leaves in the counters' pattern must be what its second
    order can put there, within 3 u (:meth:`align.gonio_ripple.RippleFit.covered`); beyond,
    the result is not ok (a counter losing counts after all, or a ripple n / 2 times a
    revolution the model does not have).

    Parameters
    ----------
    run : GonioRun
        One direction's run.
    alpha : float
        Significance level of the disagreement's tests.
    latency_max_s : float, optional
        The autocollimator's latency bound [s] the user declares (>= 0); None: undeclared.
    counters_sound : bool
        The user declares the counters lose and gain no counts at their switches.
    """
    ta = disagreement(run, alpha)
    arcsec = np.rad2deg(1) * 3600
    if ta is None:
        if not counters_sound:
            return run
        note = (f"{COUNTERS_SOUND}: the counts and the pulse times agree "
                "within noise or do not test them; nothing to carry for the counters")
        return replace(run, notes=(*run.notes, note))
    counts, dt, _ = kept_table(run.summary)
    ok = np.all(np.isfinite(dt), axis=1) & np.all(dt > 0, axis=1)
    sens = latency_sensitivity(counts[ok], dt[ok])
    d = ta.diff_rad
    rest, p_rest = beyond_counters(ta)
    head = (f"{LATENCY} (by up to {float(np.max(np.abs(d))) * arcsec:.3g}″, p "
            f"{ta.p_value:.2g}): one of them is wrong")
    per_us = float(np.max(np.abs(sens))) * 1e-6 * arcsec
    fa = run.angles
    if counters_sound or p_rest < alpha:
        rf = counters_part(run, ta)
        left = (f"the ripple modelled over the faces leaves {rf.counters_rad * arcsec:.3g} ± "
                f"{rf.counters_u_rad * arcsec:.2g}″ in the counters' pattern (its second order "
                f"puts 0 to {rf.second_rad * arcsec:.2g}″ there)")
        if counters_sound and not rf.covered():
            why = (f"{head} — {COUNTERS_SOUND}, but {left}, beyond what "
                   "the table's speed explains: a counter losing or gaining counts at its "
                   "switches, or a ripple the model does not have (n/2 times a revolution): "
                   "NOT ok; check the counters' dead time, or do not declare them sound")
            return replace(run, notes=(*run.notes, why), warnings=(*run.warnings, why),
                           problems=(*run.problems, why))
        pat = (-1.0) ** np.arange(len(d)) if len(d) % 2 == 0 else np.zeros(len(d))
        counters = (np.zeros(len(d)) if counters_sound else
                    pat * abs(rf.counters_rad))
        bound = LATENCY_BOUND_S if latency_max_s is None else latency_max_s
        bias = bound * sens  # each angle's bias at the latency bound [rad]
        cause = (f"{head} — the table's speed follows its angle (a ripple of "
                 f"{rf.amplitude:.2g} of its speed; {left}), so each µs of autocollimator "
                 f"latency biases an angle by up to {per_us:.3g}″, which one direction cannot "
                 "tell")
        if latency_max_s is None and not np.all(np.abs(bias) <= fa.u_rad):
            why = (f"{cause}: at a latency of {bound * 1e3:g} ms up to "
                   f"{float(np.max(np.abs(bias))) * arcsec:.3g}″, beyond u "
                   f"({float(np.max(fa.u_rad)) * arcsec:.3g}″): NOT ok; {DECLARE}")
            return replace(run, notes=(*run.notes, why), warnings=(*run.warnings, why),
                           problems=(*run.problems, why))
        shifts = {**({DISAGREEMENT: counters} if np.any(counters) else {}),
                  **({LATENCY_TERM: bias} if bound > 0 else {})}
        widened = _with_terms(fa, shifts)
        said = ("assumed (undeclared)" if latency_max_s is None else "declared")
        latency = (f"at a latency up to {bound * 1e6:g} µs ({said}) at most "
                   f"{float(np.max(np.abs(bias))) * arcsec:.3g}″, carried in u"
                   if bound > 0 else "no latency (declared 0)")
        part = (f"; {COUNTERS_SOUND}: no counters' part" if counters_sound
                else ", with the part a counter could make" if np.any(counters) else "")
        why = (f"{cause}: {latency}{part} (Type B, u "
               f"{float(np.max(fa.u_rad)) * arcsec:.3g}″ -> "
               f"{float(np.max(widened.u_rad)) * arcsec:.3g}″); a longer latency: "
               + (DECLARE if latency_max_s is None else
                  "measure the other direction (--reverse-log)"))
        return replace(run, angles=widened, notes=(*run.notes, why),
                       warnings=(*run.warnings, why))
    widened = _with_terms(fa, {DISAGREEMENT: d})
    big = np.abs(sens) > 0
    latency_s = float(np.min(np.abs(d[big] / sens[big]))) if big.any() else np.inf
    face_s = float(np.mean(dt[ok]))  # (a latency is far shorter than the time between faces)
    covered = (f"a latency up to {latency_s * 1e3:.3g} ms" if latency_s < face_s else
               f"any latency shorter than the time between faces, {face_s * 1e3:.3g} ms")
    why = (f"{head} — a counter losing or gaining counts at its switches (the difference is in "
           "the counters' alternating pattern), or a table whose speed follows its angle in "
           f"that pattern (each µs of autocollimator latency: up to {per_us:.3g}″) — and the "
           f"log cannot tell which: u carries the difference (Type B, u "
           f"{float(np.max(fa.u_rad)) * arcsec:.3g}″ -> "
           f"{float(np.max(widened.u_rad)) * arcsec:.3g}″; covers {covered}); check the "
           "counters' dead time")
    return replace(run, angles=widened, notes=(*run.notes, why), warnings=(*run.warnings, why))


def _with_terms(fa: FaceAngles, shifts: dict[str, np.ndarray]) -> FaceAngles:
    """``fa`` with Type B terms, each a pattern of shifts [rad] the angles may carry together:
    taken as uniform between -shift and +shift (u: shift / sqrt(3)), correlated along the
    pattern (a pattern that sums to zero keeps the closure)."""
    cov = fa.cov.copy()
    terms = dict(fa.type_b_terms)
    ub2 = fa.u_type_b_rad ** 2
    for name, shift in shifts.items():
        cov = cov + np.outer(shift, shift) / 3
        terms[name] = np.abs(shift) / np.sqrt(3)
        ub2 = ub2 + terms[name] ** 2
    return replace(fa, cov=cov, u_rad=np.sqrt(np.diag(cov)), u_type_b_rad=np.sqrt(ub2),
                   type_b_terms=terms)


def with_timing(run: GonioRun, steady_table: bool, alpha: float) -> GonioRun:
    """Replace the count angles by the timing angles when asked, confirmed and better (the
    counts' disagreement with the pulse times is bounded for one direction's result by
    :func:`bound_disagreement`)."""
    return _timing_choice(run, steady_table, alpha)


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
        why = ("a speed ripple locked to the table or a counter losing counts"
               if not ta.stamp_limited else
               f"time stamps too coarse ({ta.stamp_resolution_s:.2g} s, locked to the table's "
               "period), a speed ripple locked to the table or a counter losing counts")
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
