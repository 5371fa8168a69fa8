"""Reading static tumble data: per-pose files, and continuous recordings cut into their
static intervals (found by :mod:`align.calibration.detect`).

Formats (CSV with a header line):

* ``pose,ux,uy,uz[,t][,temp]`` — samples (several rows per pose) or per-pose means;
* ``t,ux,uy,uz[,temp]`` — a continuous recording; the static intervals are found by a
  moving standard deviation compared with the recording's own noise floor.

Both are read by the tool's one table reader (:mod:`axisbase.table`); every problem is
reported as ``file:line: column: what is wrong``.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import numpy as np

from align.calibration.arrays import MEANS_ROWS, SUFFIXES, read_arrays
from align.calibration.detect import (  # (re-exported: the package's API since before)
    CLI_NAMES,
    DEFAULT_SETTINGS,
    DETECT_KEYS,
    MIN_WINDOW,
    SESSION_KEYS,
    StaticDetection,
    StaticInterval,
    StaticSettings,
    detect_static,
    find_static,
    noise_levels,
    rate_flag,
    session_names,
)
from align.calibration.geometry import SURROUND_RAD, cone_estimate, odd_pose
from align.calibration.known import faces_of, has_six_faces
from align.calibration.saturation import find_saturated
from align.calibration.settling import settle_samples
from align.calibration.slopes import pose_slopes
from align.calibration.steps import interior_steps, pose_steps
from align.calibration.triad import Poses
from align.calibration.walk import walk_levels
from axisbase.errors import InputError
from axisbase.table import Column, Table, TableSpec, read_table

log = logging.getLogger("align.calibration")

_AXES = {ax: (f"a{ax}", f"acc_{ax}", f"accel_{ax}", f"acc{ax}", f"u_{ax}") for ax in "xyz"}
ACCELEROMETER_RATES_HZ = (1.0, 1e5)
"""Plausible sample rates of an accelerometer recording [Hz] (outside: a warning naming the
likely time unit, :func:`axisbase.table.rate_warning`)."""
_T = Column("t", required=False, aliases=("time", "t_s", "time_s", "timestamp"))
_TEMP = Column("temp", required=False, aliases=("temperature", "temp_c", "temperature_c"))
_U = tuple(Column(f"u{ax}", aliases=_AXES[ax]) for ax in "xyz")
STATIC = TableSpec("static-pose file", (
    Column("pose", "label", required=False, aliases=("pose_id", "position", "label")),
    *_U, _T, _TEMP), time="t", distinct_rows=True, rate_hz_range=ACCELEROMETER_RATES_HZ,
    temperature="temp")
"""``pose,ux,uy,uz[,t][,temp]`` (samples or per-pose means) or ``t,ux,uy,uz[,temp]``."""
READINGS = TableSpec("readings file", (*_U, _T, _TEMP), time="t", distinct_rows=True,
                     rate_hz_range=ACCELEROMETER_RATES_HZ, temperature="temp")
"""``ux,uy,uz[,t][,temp]``: readings to correct (``align apply``, ``align tilt``)."""


def read_readings(path: str | Path, columns: Mapping[str, str] | None = None,
                  rate_hz: float | None = None, time_unit: str | None = None) -> Table:
    """Readings ``ux,uy,uz[,t][,temp]`` (see :mod:`axisbase.table` for what is accepted;
    ``time_unit``: the time column's unit when its header says none)."""
    return read_table(path, READINGS, columns, rate_hz, time_unit)


def _check_values(tab: Table, u: np.ndarray) -> None:
    for ax in range(3):
        col = u[:, ax]
        top, bottom = col.max(), col.min()
        for v in (top, bottom):
            hits = np.flatnonzero(col == v)
            if len(hits) >= max(5, 0.05 * len(col)) and np.ptp(col) > 0:
                raise tab.fail(int(hits[0]), f"u{'xyz'[ax]}", f"sits at {v:g} in {len(hits)} "
                               "samples: saturated or clipped")



def read_poses(path: str | Path, settings: StaticSettings = DEFAULT_SETTINGS,
               calibration: bool = True, columns: Mapping[str, str] | None = None,
               rate_hz: float | None = None, adc_range: tuple[float, float] | None = None,
               warnings: list[str] | None = None, time_unit: str | None = None
               ) -> tuple[Poses, list[StaticInterval] | None]:
    """Per-pose means from a pose file, or from a continuous recording's static intervals.

    ``calibration``: check that the poses can carry a calibration (units, 3-D spread); off
    for check poses, which may be few. ``columns``, ``rate_hz``, ``time_unit``: see
    :func:`axisbase.table.read_table`. ``adc_range``: the ADC's rails (LO, HI) [output
    units], when declared. A pose saturated on an axis (:mod:`align.calibration.saturation`)
    is left out with a warning (appended to ``warnings``, else logged) when the others still
    determine the calibration, else refused naming it.
    """
    path = Path(path)
    if path.suffix.lower() in SUFFIXES:
        tab, notes = read_arrays(path, STATIC, columns, rate_hz, names=settings.names)
        for note in notes:
            logging.getLogger("align").warning("%s", note)
    else:
        tab = read_table(path, STATIC, columns, rate_hz, time_unit)
        if "pose" not in tab and "t" not in tab and len(tab) <= MEANS_ROWS:
            # ux,uy,uz without pose or time, a few rows: per-pose means (as for arrays).
            labels = np.array([str(i + 1) for i in range(len(tab))], dtype=object)
            tab = replace(tab, data={**tab.data, "pose": labels})
            logging.getLogger("align").warning(
                "%s: %d rows, no pose or time column: each row read as one pose's mean "
                "(a recording needs %s)", path, len(tab), rate_flag(settings))
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    t = tab.get("t")
    temp = tab.get("temp")
    if "pose" in tab:
        labels = tab["pose"]
        # Keep the poses in the order they first appear.
        order, first, ids = np.unique(np.char.strip(labels.astype(str)), return_index=True,
                                      return_inverse=True)
        rank = np.argsort(np.argsort(first))
        ids = rank[ids]
        order = tuple(str(x) for x in order[np.argsort(first)])
        n = len(order)
        count = np.bincount(ids, minlength=n)
        if calibration:  # check poses use only their means
            _check_counts(path, tab, order, count, first[np.argsort(first)],
                          path.suffix.lower() in SUFFIXES)
        if count.max() < MIN_SAMPLES:
            _check_values(tab, u)  # per-pose means: no pose's samples to judge
        samples = [u[ids == i] for i in range(n)]
        mean = np.array([u[ids == i].mean(0) for i in range(n)])
        sig = None
        if count.min() >= MIN_SAMPLES:
            sd = np.array([u[ids == i].std(0, ddof=1) for i in range(n)])
            _check_one_pose(path, tab, order, ids, mean, sd, path.suffix.lower() in SUFFIXES)
            sig = sd / np.sqrt(count)[:, None]
        tt = (np.array([t[ids == i].mean() for i in range(n)]) if t is not None
              else np.arange(n, dtype=float))
        tm = np.array([temp[ids == i].mean() for i in range(n)]) if temp is not None else None
        poses = Poses(mean, tt, tm, sig, count, order, ordered=t is not None)
        intervals = None
    else:
        if t is None:
            raise InputError(f"{path}: {len(u)} rows and neither a pose column nor a time "
                             f"column t (give {rate_flag(settings)} for a recording without time "
                             "stamps)")
        log.debug("%s: static detection: %s", path, settings.describe())
        det = detect_static(t, u, settings)
        log.debug("%s: %d static intervals (window %d samples at %.4g Hz, static below %.3g "
                  "x the noise); the recording's noise %s (its unit)", path,
                  len(det.intervals), det.window, det.rate_hz, det.limit,
                  " ".join(f"{v:.3g}" for v in det.noise))
        for note in det.notes:
            logging.getLogger("align").warning("WARNING: %s: %s", path, note)
        intervals = list(det.intervals)
        if not intervals:
            raise InputError(f"{path}: no static interval found "
                             f"({settings.names['window_s']} {settings.window_s:g} s, "
                             f"{settings.names['threshold']} {settings.threshold:g} x the "
                             "recording's noise, "
                             f"{settings.names['min_duration_s']} {settings.min_duration_s:g}"
                             f" s){_notes(det)}")
        mean = np.array([iv.mean for iv in intervals])
        count = np.array([iv.samples for iv in intervals])
        sig = np.array([iv.sem for iv in intervals])
        tt = np.array([(iv.start_s + iv.end_s) / 2 for iv in intervals])
        tm = None
        if temp is not None:
            tm = np.array([temp[iv.mask(t)].mean() for iv in intervals])
        poses = Poses(mean, tt, tm, sig, count,
                      tuple(f"static@{iv.start_s:.1f}s" for iv in intervals))
        samples = [u[iv.mask(t)] for iv in intervals]
    if t is not None:  # the bias instability the samples within the poses show
        times = ([t[ids == i] for i in range(len(samples))] if intervals is None else
                 [t[iv.mask(t)] for iv in intervals])
        samples, du, settled = settle_samples(samples, times, poses.ordered)
        if du is not None:  # each pose's mean from its corrected samples, u carries it
            poses = replace(poses, u=np.array([x.mean(0) for x in samples]),
                            sigma_u=None if poses.sigma_u is None else
                            np.sqrt(poses.sigma_u**2 + du**2))
        # A pose whose samples stepped is left out of the walk's level (one event, not a
        # process every pose shows); the calibration judges the step (steps.step_problem),
        # in a detected static interval only away from its ends: an edge may hold the end
        # of the turn (synth's recordings: 5-8.5 mg "steps" within 0.2 s of an edge).
        steps = pose_steps(samples, times, poses.labels)
        rate, bound = walk_levels(samples, times, [s.pose for s in steps])
        trend = pose_slopes(samples, times, rate)
        poses = replace(poses, settling=settled, walk_rate=rate, walk_bound=bound,
                        steps=steps if intervals is None else interior_steps(steps, times),
                        slope=None if trend is None else trend[0],
                        slope_u=None if trend is None else trend[1])
    poses = _drop_saturated(path, poses, samples, adc_range, calibration, warnings)
    if calibration:
        try:
            _check_geometry(path, poses)
        except InputError as exc:
            if intervals is None:
                raise
            raise InputError(f"{exc}\n{_listing(intervals)}") from None
        if intervals is not None and len(intervals) < 9:
            if not has_six_faces(faces_of(poses)):
                raise InputError(f"{path}: too few poses: {len(intervals)} static intervals "
                                 "found, the ellipsoid needs 9 (or the six faces for the "
                                 "known-pose method); the detection settings may be too strict"
                                 f" ({settings.flags(*DETECT_KEYS)})"
                                 f"{_notes(det)}\n{_listing(intervals)}")
    return poses, intervals


def _drop_saturated(path: Path, poses: Poses, samples: list[np.ndarray],
                    adc_range: tuple[float, float] | None, calibration: bool,
                    warnings: list[str] | None) -> Poses:
    """The poses without those saturated on an axis; refused (naming them) when the rest no
    longer determine the calibration: the six faces when all poses are faces, else nine
    poses or the six faces."""
    sat = find_saturated(samples, poses.labels, adc_range)
    if not sat:
        return poses
    keep = np.ones(len(poses.u), bool)
    keep[[s.index for s in sat]] = False
    def kept(x: np.ndarray | None) -> np.ndarray | None:
        return None if x is None else x[keep]

    rest = replace(poses, u=poses.u[keep], t=poses.t[keep], temp=kept(poses.temp),
                   sigma_u=kept(poses.sigma_u), count=poses.count[keep],
                   labels=tuple(lab for lab, k in zip(poses.labels, keep, strict=True) if k),
                   slope=kept(poses.slope), slope_u=kept(poses.slope_u))
    what = "; ".join(s.text() for s in sat)
    if calibration:
        faces = faces_of(rest)
        if all(f is not None for f in faces_of(poses)):
            enough = has_six_faces(faces)
        else:
            enough = len(rest.u) >= 9 or has_six_faces(faces)
        if not enough:
            raise InputError(f"{path}: {what}; without {'it' if len(sat) == 1 else 'them'} "
                             f"the remaining {len(rest.u)} poses do not determine the "
                             "calibration (the six faces, or nine poses all round): repeat "
                             "the pose within the sensor's range")
    msg = (f"{path}: {what}: left out; the calculation uses the remaining {len(rest.u)} "
           "poses")
    if warnings is None:
        logging.getLogger("align").warning("WARNING: %s", msg)
    else:
        warnings.append(msg)
    return rest


MIN_SAMPLES = 3
"""Fewest samples of a pose whose own scatter gives its noise (ddof = 1 leaves 2 dof)."""


def _check_counts(path: Path, tab: Table, labels: tuple[str, ...], count: np.ndarray,
                  first_row: np.ndarray, arrays: bool) -> None:
    """Refuse a pose of one or two samples among poses of samples. Its noise cannot come from
    its own scatter, so the file would drop to 'per-pose means only' (noise unknown, no chi2
    test, a different fit); taking it with the others' noise or leaving it out would both
    guess what the row is — a stray row, a mistyped label, a pose cut short. Only the user
    knows: the file, line and label are named."""
    few = np.flatnonzero(count < MIN_SAMPLES)
    if not few.size or count.max() < MIN_SAMPLES:
        return  # all poses of samples, or per-pose means (one or two rows per pose)
    i = int(few[np.argmin(first_row[few])])
    many = count[count >= MIN_SAMPLES]
    what = (f"{labels[i]!r} has {count[i]} sample{'s' if count[i] > 1 else ''} while "
            f"{len(many)} other poses have {many.min()}" + (f"-{many.max()}" if many.max()
                                                            > many.min() else "")
            + f"{f' (and {few.size - 1} more such poses)' if few.size > 1 else ''}: a stray "
            f"row or a mistyped label? A pose needs {MIN_SAMPLES} samples or more for its "
            "noise (or give one row per pose: per-pose means, noise unknown)")
    if arrays:
        raise InputError(f"{path}: pose {what}")
    raise tab.fail(int(first_row[i]), "pose", what)


MIXED_NOISE_RATIO = 10.0
"""A pose's sample scatter beyond this many times the typical pose's (per channel) is not
noise: the poses of one file share one sensor and one sampling, and a sample standard
deviation of >= 3 samples exceeds ten times its sigma with probability < exp(-50)."""


def _check_one_pose(path: Path, tab: Table, labels: tuple[str, ...], ids: np.ndarray,
                    mean: np.ndarray, sd: np.ndarray, arrays: bool) -> None:
    """Refuse a pose whose samples are not one static pose — a mistyped label joining two
    orientations, or a pose that moved. Both of: its scatter is far beyond the others' noise
    (:data:`MIXED_NOISE_RATIO`) and it is a change of attitude, more than the 1° tilt (of the
    file's full scale, half its poses' widest range) by which the static-interval detector
    splits one interval into two poses (``StaticSettings.split_rad``). Its mean would be a
    direction no pose had; the file, the label and its line ranges are named."""
    if len(labels) < 3:
        return  # no typical noise to compare with
    typical = np.median(sd, axis=0)
    scale = np.max(np.ptp(mean, axis=0)) / 2
    ratio = np.max(sd / np.where(typical > 0, typical, np.inf), axis=1)
    moved = np.linalg.norm(sd, axis=1) > np.sin(StaticSettings.split_rad) * scale
    bad = np.flatnonzero((ratio > MIXED_NOISE_RATIO) & moved)
    if not bad.size:
        return
    i = int(bad[0])
    j = int(np.argmax(sd[i] / np.where(typical > 0, typical, np.inf)))
    rows = np.flatnonzero(ids == i)
    cut = np.flatnonzero(np.diff(rows) > 1)
    runs = list(zip(rows[np.r_[0, cut + 1]], rows[np.r_[cut, len(rows) - 1]], strict=True))
    where = ("rows " if arrays else "lines ") + ", ".join(
        (f"{a + 1}-{b + 1}" if arrays else f"{tab.line(int(a))}-{tab.line(int(b))}")
        for a, b in runs[:4])
    more = f" (and {len(bad) - 1} more such poses)" if len(bad) > 1 else ""
    raise InputError(
        f"{path}: pose {labels[i]}: its samples are not one static pose (scatter "
        f"{sd[i, j]:.3g} on u{'xyz'[j]} against a typical {typical[j]:.3g} of the other poses; "
        f"{where}{', ...' if len(runs) > 4 else ''}){more}: two poses under one label (a "
        "mistyped label) or a pose that moved")


def _notes(det: StaticDetection) -> str:
    return "".join(f"; {n}" for n in det.notes)


def _listing(intervals) -> str:
    """Every interval found (start, end, mean) for a refusal message."""
    return "\n".join(f"  interval {i + 1}: {iv.start_s:.2f}-{iv.end_s:.2f} s, mean "
                     + " ".join(f"{v:.6g}" for v in iv.mean)
                     for i, iv in enumerate(intervals)) or "  (none)"


def _check_geometry(path: Path, poses: Poses) -> None:
    u = poses.u
    if len(u) >= 3:
        s = np.linalg.svd(u - u.mean(0), compute_uv=False)
        if s[-1] < 1e-3 * s[0]:
            raise InputError(f"{path}: geometry: the {len(u)} poses lie in a plane "
                             "(degenerate): tilt the unit out of that plane")
    # A pose in another unit is far off the sphere through the others (geometry.odd_pose);
    # that sphere is determined only when the poses surround its centre: poses clustered
    # in a narrow cone are judged after the fit (pipeline._cone_notes), not called mixed units.
    odd = odd_pose(u) if len(u) > 3 else None
    if odd is not None:
        i, rho = odd
        if not cone_estimate(np.delete(u, i, 0)) < SURROUND_RAD:
            raise InputError(f"{path}: pose {poses.labels[i]} is {rho:.3g} radii from the "
                             "centre of the sphere through the other poses (one sensor in "
                             "one unit: 1 within a few %): mixed units?")


__all__ = ["CLI_NAMES", "MIN_WINDOW", "READINGS", "SESSION_KEYS", "STATIC", "StaticDetection",
           "StaticInterval", "StaticSettings", "detect_static", "find_static", "noise_levels",
           "read_poses", "read_readings", "session_names"]
