"""The goniometer pipeline for one counter log (or two, one per direction): ``measure_log``.

One streaming pass (:func:`goniometry.read_revolutions`) gives the revolutions' statistics;
the Earth's rotation is then removed from the latitude when given, else by the
revolution-level loop (:mod:`align.gonio_loop`) when the log shows it, else bounded over the
latitudes in u. A log of the other direction is combined by the plain mean
(:mod:`align.gonio_directions`); the pulse times may replace the counts on a steady table and
one direction's counts that disagree with its pulse times carry the difference in u
(:mod:`align.gonio_timing`). The result, :class:`GonioRun`, owns
its JSON form.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from align.gonio_directions import (
    check_reversed,
    combine_directions,
)
from align.gonio_earth import declared_earth_angles
from align.gonio_latency import apply_direction_model, latency_model
from align.gonio_loop import EARTH, latitude_from_earth_rate, loop_gonio, plausible_earth_rate
from align.gonio_run import GonioRun
from align.gonio_timing import COUNTERS_SOUND, LATENCY, bound_disagreement, with_timing
from axisbase.console import captured_warnings
from axisbase.errors import InputError
from axisbase.units import DEG
from goniometry import (
    FaceAngles,
    face_angles,
    kept_table,
    read_revolutions,
    vertical_earth_rate,
)
from goniometry.angles import METHOD_OFF_PATH, OMEGA_EARTH
from goniometry.reader import source_name

if TYPE_CHECKING:
    pass

log = logging.getLogger("align.gonio")

LOOP_REVOLUTIONS = 20000


def earth_rate_range(latitude_range_rad: tuple[float, float] | None,
                     direction: int) -> tuple[float, float]:
    """Mid-point and half-range [rad/s] of the vertical Earth rate over a latitude range
    [rad] (all latitudes when None)."""
    lo, hi = latitude_range_rad if latitude_range_rad is not None else (-90 * DEG, 90 * DEG)
    r1, r2 = vertical_earth_rate(lo, direction), vertical_earth_rate(hi, direction)
    return (r1 + r2) / 2, abs(r2 - r1) / 2


EARTH_BOUND = "earth_rate (latitude not given: bound over {})"
UNTIMED_EARTH = (
    "the Earth rate's share in the angles (Omega_E·sin(latitude), up to 15.04°/h, times each "
    "face pulse's lead or lag against a steady table) can be neither removed nor bounded "
    "without pulse times and is NOT in u: on a table whose speed varies within a revolution "
    "the angles may be off by more than u; log the times (t column), or give --steady-table "
    "if the table turns at constant speed")
ONE_DIRECTION = (LATENCY, f"no t column: {UNTIMED_EARTH}")
"""How the warnings begin that only one direction's run gives (the other cancels them)."""
UNTIMED_EARTH_STEADY = ("the angles assume the steady table asserted (--steady-table), on "
                        "which the Earth rate cancels in each revolution's fractions")


def measure_log(path: str | Path | object, n_faces: int, latitude_rad: float | None = None,
                direction: int = 1, alpha: float = 1e-3,
                reverse_log: str | Path | object | None = None, apply_loop: bool = True,
                steady_table: bool = False, columns: Mapping[str, str] | None = None,
                latitude_range_rad: tuple[float, float] | None = None,
                on_bytes: Callable[[int], None] | None = None,
                time_unit: str | None = None,
                latency_max_s: float | None = None,
                counters_sound: bool = False) -> GonioRun:
    """Face angles of a log, from one pass over it.

    With times, the Earth rate is removed from the latitude when given, else by the loop
    when the data show it and it is physically possible; when neither determines it, the
    range of its effect over all latitudes (or ``latitude_range_rad``) is carried in u as a
    named Type B term (an unsteady table makes the angles depend on it). ``reverse_log``: a
    log of the same faces with the table turning the other way; the result is then the mean
    of both directions (see :func:`combine_directions`). ``steady_table``: the user asserts
    the table turns at constant speed within a revolution; the angles then come from the
    pulse times (:mod:`goniometry.timing`, jitter-limited) when the counts confirm it and the
    timing estimate is the more precise one; otherwise the counts are used and the reason is
    noted.

    Parameters
    ----------
    path : str, Path, mapping of str to array-like, numpy structured array or pyarrow Table
        The counter log: its file, or its rows already in memory under the log's column
        names (``count``, ``counter``, ``ref``, ``t`` [s], or as ``columns`` maps them).
        Rows go through the same reader and checks as a file; a bad one is named by its
        index (``rows: row k: column: what``) and the exclusions' ``lines`` are row indexes.
    n_faces : int
        Faces of the housing (pulses per revolution).
    latitude_rad : float, optional
        Latitude of the table [rad] (the Earth rate then comes from it).
    direction : int
        +1: the table turns counter-clockwise seen from above; -1: clockwise.
    alpha : float
        Significance level of the loop's and the consistency checks' tests.
    reverse_log : str, Path or rows, optional
        A log of the same faces with the table turning the other way (a file or rows, as
        ``path``).
    apply_loop : bool
        Apply the Earth rate the loop finds (False for each direction of a pair).
    steady_table : bool
        The user asserts a constant speed within a revolution (pulse-time angles).
    columns : mapping of str to str, optional
        Header names of the log's columns (``--columns``), for both logs.
    latitude_range_rad : tuple of float, optional
        Latitudes [rad] the Earth rate's bound is taken over when it is not determined.
    on_bytes : callable, optional
        Called with about how many bytes each chunk held (a progress bar).
    time_unit : str, optional
        The ``t`` column's unit when its header (or its name in rows) says none, for both
        logs (``--time-unit``, the session's ``time_unit``: ``s``, ``ms``, ``us``, ``ns``,
        ``min``, ``h``); a header that says another unit is refused.
    latency_max_s : float, optional
        The autocollimator's latency bound [s] from its specification (``--latency-max-us``,
        the session's ``latency_max_us``; >= 0, 0: no latency). One direction whose table
        speed follows its angle then carries that latency's bias in u and stays ok; None:
        up to 1 ms is carried where its bias stays within u, else the result is not ok
        (:func:`align.gonio_timing.bound_disagreement`). Unused with ``reverse_log`` (the
        two directions cancel a latency).
    counters_sound : bool
        The user declares the counters verified (``--counters-sound``, the session's
        ``counters_sound``: their dead time measured, no counts lost or gained at their
        switches). One direction whose counts and pulse times disagree then carries no
        counters' part in u, and is not ok where the table's speed does not explain the
        disagreement (:func:`align.gonio_timing.bound_disagreement`). Stated in the result
        (``counters_sound``).

    Returns
    -------
    GonioRun
        The summary of the pass, the face angles [rad] with u and covariance, the loop's
        report and the notes and warnings for the user.

    Raises
    ------
    LogError
        A log that cannot be used (naming the file and line).
    InputError
        A reverse log that is not the other direction of the same faces; a latitude beyond
        +-pi/2 (degrees given where radians are taken); a latency bound that is not a finite
        number >= 0.

    Examples
    --------
    A synthetic 50-revolution log of a 4-face table (``synth.gonio``, with its truth):

    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from synth.gonio import GonioSpec, simulate, write_log
    >>> from align import measure_log
    >>> from axisbase.units import DEG
    >>> sim = simulate(GonioSpec(revolutions=50, seed=1))
    >>> log = write_log(sim, pathlib.Path(tempfile.mkdtemp()) / "log.csv")
    >>> run = measure_log(log, 4, latitude_rad=50.45 * DEG)
    >>> z = (run.angles.angles_rad - sim["truth"]["angles_rad"]) / run.angles.u_rad
    >>> bool(np.all(np.abs(z) < 4))
    True

    The same log's rows already in memory (a dict of columns, a numpy structured array or a
    pyarrow Table) give the same angles; a bad row is named by its index:

    >>> rows = {k: np.loadtxt(log, delimiter=",", skiprows=1, usecols=i)
    ...         for i, k in enumerate(["count", "counter", "ref", "t"])}
    >>> same = measure_log(rows, 4, latitude_rad=50.45 * DEG)
    >>> bool(np.array_equal(same.angles.angles_rad, run.angles.angles_rad))
    True
    >>> rows["ref"][7] = 2
    >>> measure_log(rows, 4, latitude_rad=50.45 * DEG)
    Traceback (most recent call last):
    ...
    goniometry.errors.LogError: rows: row 7: ref: must be 0 or 1
    """
    _check_latitudes(latitude_rad, latitude_range_rad)
    _check_latency(latency_max_s)
    if not isinstance(counters_sound, bool | np.bool_):
        raise InputError(f"measure_log counters_sound = {counters_sound!r}: true or false "
                         "(the counters verified sound)")
    counters_sound = bool(counters_sound)
    if reverse_log is not None:
        # Without the latitude the mean of the two directions cancels the Earth rate itself
        # (it flips sign with the direction): no loop estimate is applied to either run.
        fwd = _measured(path, n_faces, latitude_rad, direction, alpha, False, steady_table,
                        columns, latitude_range_rad, on_bytes, time_unit, one_direction=False)
        rev = _measured(reverse_log, n_faces, latitude_rad, -direction, alpha, False,
                        steady_table, columns, latitude_range_rad, on_bytes, time_unit,
                        one_direction=False)
        comb, term = combine_directions(fwd.angles, rev.angles)
        model = (None if fwd.timing_used or rev.timing_used else
                 latency_model(fwd.summary, rev.summary, fwd.angles, rev.angles,
                               latitude_rad is not None))
        comb, unexplained, fitted = apply_direction_model(model, comb, term.half_difference_rad,
                                                          term.cov, alpha)
        check_reversed(fwd.angles, rev.angles, term, source_name(path),
                       source_name(reverse_log), alpha, unexplained)
        notes = [*(n for n in fwd.notes if not n.startswith(LATENCY)),
                 *(f"reverse run: {n}" for n in rev.notes if not n.startswith(LATENCY)),
                 f"both directions combined: the direction-dependent part is "
                 f"{'significant' if term.p_value < alpha else 'not significant'} "
                 f"(chi2 {term.chi2:.1f} / {term.dof}, p {term.p_value:.2g}) and cancelled",
                 *([fitted] if fitted else []),
                 *([f"{COUNTERS_SOUND}: unused with two directions (their reversal check "
                    "judges the counts)"] if counters_sound else [])]
        # (both directions: the latency bias cancels, its one-direction warning does not hold;
        # so does the Earth rate's share a log without times cannot remove)
        warns = (*(w for w in fwd.warnings if not w.startswith(ONE_DIRECTION)),
                 *(f"reverse run: {w}" for w in rev.warnings
                   if not w.startswith(ONE_DIRECTION)))
        return GonioRun(fwd.summary, comb, fwd.loop, tuple(notes), fwd.earth_rate_applied,
                        rev, term, fwd.timing, fwd.timing_used and rev.timing_used,
                        tuple(warns), counters_sound=counters_sound)
    run = _measured(path, n_faces, latitude_rad, direction, alpha, apply_loop, steady_table,
                    columns, latitude_range_rad, on_bytes, time_unit, one_direction=True,
                    latency_max_s=latency_max_s, counters_sound=counters_sound)
    return replace(run, counters_sound=counters_sound)


def _check_latency(latency_max_s: float | None) -> None:
    """A declared latency bound is a finite number >= 0 [s]."""
    if latency_max_s is None:
        return
    if (isinstance(latency_max_s, bool) or not isinstance(latency_max_s, int | float)
            or not np.isfinite(latency_max_s) or latency_max_s < 0):
        raise InputError(f"measure_log latency_max_s = {latency_max_s!r}: the "
                         "autocollimator's latency bound is a finite number >= 0 [s]")


def _measured(path: str | Path | object, n_faces: int, latitude_rad: float | None,
              direction: int, alpha: float, apply_loop: bool, steady_table: bool,
              columns: Mapping[str, str] | None,
              latitude_range_rad: tuple[float, float] | None,
              on_bytes: Callable[[int], None] | None, time_unit: str | None, *,
              one_direction: bool, latency_max_s: float | None = None,
              counters_sound: bool = False) -> GonioRun:
    """One log's run with the reader's warnings; ``one_direction``: the result stands alone
    (not one of a pair), so its counts' disagreement with its pulse times is carried in u
    (two directions cancel a latency, and the reversal check judges what is left)."""
    with captured_warnings() as logged:  # how the log was read (the table reader's
        run = _one_direction(path, n_faces, latitude_rad, direction, alpha, apply_loop,
                             steady_table, columns, latitude_range_rad, on_bytes, time_unit)
    if one_direction:
        run = bound_disagreement(run, alpha, latency_max_s, counters_sound)
    return replace(run, warnings=(*dict.fromkeys(logged), *run.warnings))  # warnings too


def _one_direction(path: str | Path | object, n_faces: int, latitude_rad: float | None,
                   direction: int, alpha: float, apply_loop: bool, steady_table: bool,
                   columns: Mapping[str, str] | None,
                   latitude_range_rad: tuple[float, float] | None,
                   on_bytes: Callable[[int], None] | None, time_unit: str | None
                   ) -> GonioRun:
    """One direction's run of :func:`measure_log` (its parameters)."""
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
    if latitude_rad is None:
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
                               on_kept_at=LOOP_REVOLUTIONS, on_bytes=on_bytes,
                               time_unit=time_unit)
    log.debug("gonio %s: one pass in %.2f s: %d rows, %d revolutions excluded "
              "(%s), times %s", Path(source_name(path)).name, time.perf_counter() - start,
              summary.rows,
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
    if latitude_rad is not None and summary.has_time:
        fa, rate, why = declared_earth_angles(summary, latitude_rad, direction, alpha,
                                              LOOP_REVOLUTIONS)
        return with_timing(GonioRun(summary, fa, None, tuple(notes), rate,
                                     warnings=(why,) if why else ()), steady_table, alpha)
    if latitude_rad is not None:
        why = ("latitude given, but the log has no t column: the Earth-rate correction needs "
               "pulse times; NOT applied (nor can a table speed that follows its angle be "
               "seen, which with autocollimator latency biases one direction: measure both)")
        notes.append(why)
        fa = face_angles(summary)
        return with_timing(GonioRun(summary, fa, None, (*notes, *_untimed_notes(fa)), None,
                                     warnings=(why,)), steady_table, alpha)
    if not summary.has_time:
        fa = face_angles(summary)
        if steady_table:
            # The user asserts a constant speed: the Earth rate then adds to every interval in
            # proportion to its angle and cancels in the fractions of the revolution.
            notes.append(f"no t column: {UNTIMED_EARTH_STEADY}")
            return with_timing(GonioRun(summary, fa, None, (*notes, *_untimed_notes(fa)),
                                        None), steady_table, alpha)
        # Not a note: a term that can be neither removed nor bounded is not in u, so the
        # angles cannot be fully trusted (at 0.1 rev/s with a 15 % ripple it is ~4″, 30 u).
        why = f"no t column: {UNTIMED_EARTH}"
        notes.append(why)
        return with_timing(GonioRun(summary, fa, None, (*notes, *_untimed_notes(fa)), None,
                                    warnings=(why,), problems=(why,)), steady_table, alpha)
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
        return with_timing(GonioRun(summary, face_angles(summary), loop, tuple(notes), None),
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
        return with_timing(GonioRun(summary, face_angles(summary, rate, rate_u), loop,
                                     tuple(notes), rate), steady_table, alpha)
    if not apply_loop:
        return with_timing(GonioRun(summary, face_angles(summary), loop, tuple(notes), None),
                            steady_table, alpha)
    # Not determined by the log: its bound over the latitudes enters u (Type B), named.
    mid, half = earth_rate_range(latitude_range_rad, direction)
    where = ("all latitudes" if latitude_range_rad is None else
             f"latitudes {latitude_range_rad[0] / DEG:g}..{latitude_range_rad[1] / DEG:g}°")
    name = EARTH_BOUND.format(where)
    fa = face_angles(summary, mid, type_b={name: half})
    worst = float(np.max(fa.type_b_terms[name])) * np.rad2deg(1) * 3600
    notes.append(f"Earth rate not determined by this log and no --latitude: its effect over "
                 f"{where} (up to {worst:.3g}″ per angle) is carried in u as a Type B term")
    return with_timing(GonioRun(summary, fa, loop, tuple(notes), mid or None), steady_table,
                        alpha)


def _untimed_notes(fa: FaceAngles) -> tuple[str, ...]:
    """What a log without times cannot show about drop-outs (docs/goniometer-dropouts.md)."""
    notes = ["no t column: a drop-out of a whole number of revolutions keeps the faces' "
             "sequence and cannot be seen; the revolution across it (genuine intervals) is used"]
    if fa.type_a_method == METHOD_OFF_PATH:
        notes.append("the counters' floors do not follow one phase path: a wandering table "
                     "speed or whole revolutions lost (without times neither can be told apart "
                     "nor located); u from batch means, which bound both")
    return tuple(notes)


def _check_latitudes(latitude_rad: float | None,
                     latitude_range_rad: tuple[float, float] | None) -> None:
    """Latitudes are radians here (degrees only at the flags and keys): a value beyond pi/2
    is degrees passed by mistake, which would remove a wrong Earth rate without a word."""
    given = ([] if latitude_rad is None else [("latitude_rad", latitude_rad)]) + (
        [] if latitude_range_rad is None else
        [("latitude_range_rad", v) for v in latitude_range_rad])
    for name, v in given:
        if not (np.isfinite(v) and abs(v) <= np.pi / 2):
            raise InputError(f"measure_log {name} = {v:g}: a latitude in radians is within "
                             "+-pi/2 (degrees? multiply by axisbase.units.DEG)")


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
