"""Reading static tumble data and finding the static intervals of continuous recordings.

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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.ndimage import uniform_filter1d

from align.calibration.arrays import MEANS_ROWS, SUFFIXES, read_arrays
from align.calibration.geometry import SURROUND_RAD, cone_estimate, odd_pose
from align.calibration.known import faces_of, has_six_faces
from align.calibration.saturation import find_saturated
from align.calibration.triad import Poses
from align.calibration.walk import walk_levels
from axisbase.errors import InputError
from axisbase.table import Column, Table, TableSpec, read_table
from axisbase.units import DEG

log = logging.getLogger("align.calibration")


@dataclass(frozen=True)
class StaticInterval:
    """A static interval of a recording: times [s], samples, mean, scatter and standard error
    of the mean of u (same unit as u)."""

    start_s: float
    end_s: float
    samples: int
    mean: np.ndarray
    std: np.ndarray
    sem: np.ndarray

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


CLI_NAMES = {"window_s": "--window", "threshold": "--threshold",
             "min_duration_s": "--min-static", "margin_s": "--margin",
             "split_sigma": "--split-sigma", "split_deg": "--split-deg", "rate_hz": "--rate",
             "columns": "--columns"}
"""How a user of ``align calibrate`` sets each detection setting (its flag)."""

SESSION_KEYS = {"window_s": "window_s", "threshold": "threshold",
                "min_duration_s": "min_static_s", "margin_s": "margin_s",
                "split_sigma": "split_sigma", "split_deg": "split_deg", "rate_hz": "rate_hz",
                "columns": "columns"}
"""The session.toml key of each detection setting (in the file's own section)."""

_RULES = {  # setting -> (lowest, lowest excluded, what it is): the one check of each value
    "window_s": (0.0, True, "the static detection window [s]"),
    "threshold": (1.0, True, "a multiple of the recording's own noise"),
    "min_duration_s": (0.0, True, "the shortest static interval kept [s]"),
    "margin_s": (0.0, False, "the time cut from each end of an interval [s]"),
    "split_sigma": (0.0, True, "a number of standard errors"),
    "split_deg": (0.0, False, "a tilt [°]"),
}
_IN_SI = {"split_deg": ("split_rad", DEG)}
"""A setting given in the user's unit -> (its field, the field's value of one such unit): the
one conversion of the command line's and session.toml's degrees (radians inside)."""


_DETECT_KEYS = ("window_s", "threshold", "min_duration_s", "margin_s")
"""The settings a refusal for too few or no static intervals suggests changing."""


def session_names(section: str) -> dict[str, str]:
    """The names a session user gives the detection settings: ``[calibration] window_s``..."""
    return {k: f"{section} {v}" for k, v in SESSION_KEYS.items()}


@dataclass(frozen=True)
class StaticSettings:
    """Detection settings (see :func:`detect_static`).

    Attributes
    ----------
    window_s : float
        Moving window [s] (at least :data:`MIN_WINDOW` samples).
    threshold : float
        A window is static while its standard deviation stays below this multiple of the
        recording's own noise — dimensionless.
    min_duration_s : float
        Shortest interval kept [s] (1 s poses pass).
    margin_s : float
        Cut from each end [s] (settling).
    split_sigma : float
        An interval whose mean moves by more than this many of its own standard errors ...
        — dimensionless.
    split_rad : float
        ... and by more than this tilt [rad] (``--split-deg``, session key ``split_deg``, in
        degrees) is split (a slow turn the moving window cannot
        see; smaller moves are settling, not a new pose).
    names : Mapping
        How the user set each of them (``--window`` on the command line, ``[calibration]
        window_s`` in session.toml; also ``rate_hz`` and ``columns``): every message about
        a setting names it so — dimensionless.
    """

    window_s: float = 0.25
    threshold: float = 3.0
    min_duration_s: float = 0.5
    margin_s: float = 0.1
    split_sigma: float = 8.0
    split_rad: float = 1.0 * DEG
    names: Mapping[str, str] = field(default_factory=lambda: dict(CLI_NAMES), compare=False,
                                     hash=False)

    @classmethod
    def given(cls, names: Mapping[str, str], **values: object) -> StaticSettings:
        """The settings the user gave (a value None or absent: the default), each checked
        by its one rule; ``InputError`` naming the flag or key (``names``) otherwise. The
        command line and session.toml both come here, with values in the user's units
        (``split_deg`` in degrees: converted here to ``split_rad``)."""
        out: dict[str, float] = {}
        for key, value in values.items():
            if value is None:
                continue
            lo, open_lo, what = _RULES[key]
            name = names[key]
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not np.isfinite(value):
                raise InputError(f"{name} = {value!r}: not a finite number ({what})")
            if value < lo or (open_lo and value == lo):
                raise InputError(f"{name} = {value:g}: must be {'>' if open_lo else '>='} "
                                 f"{lo:g} ({what})")
            field_name, unit = _IN_SI.get(key, (key, 1.0))
            out[field_name] = float(value) * unit
        return cls(**out, names=dict(names))

    def flags(self, *keys: str) -> str:
        """The user's names of ``keys``, for a message: ``--window, --threshold``."""
        return ", ".join(self.names[k] for k in keys)

    def describe(self) -> str:
        """The settings in use, each with the user's name (the ``-v`` log)."""
        def shown(k: str) -> float:
            field_name, unit = _IN_SI.get(k, (k, 1.0))
            return getattr(self, field_name) / unit

        return ", ".join(f"{self.names[k]} {shown(k):g}" for k in _RULES)


_AXES = {ax: (f"a{ax}", f"acc_{ax}", f"accel_{ax}", f"acc{ax}", f"u_{ax}") for ax in "xyz"}
ACCELEROMETER_RATES_HZ = (1.0, 1e5)
"""Plausible sample rates of an accelerometer recording [Hz] (outside: a warning naming the
likely time unit, :func:`axisbase.table.rate_warning`)."""
_T = Column("t", required=False, aliases=("time", "t_s", "time_s", "timestamp"))
_TEMP = Column("temp", required=False, aliases=("temperature", "temp_c", "temperature_c"))
_U = tuple(Column(f"u{ax}", aliases=_AXES[ax]) for ax in "xyz")
STATIC = TableSpec("static-pose file", (
    Column("pose", "label", required=False, aliases=("pose_id", "position", "label")),
    *_U, _T, _TEMP), time="t", distinct_rows=True, rate_hz_range=ACCELEROMETER_RATES_HZ)
"""``pose,ux,uy,uz[,t][,temp]`` (samples or per-pose means) or ``t,ux,uy,uz[,temp]``."""
READINGS = TableSpec("readings file", (*_U, _T, _TEMP), time="t", distinct_rows=True,
                     rate_hz_range=ACCELEROMETER_RATES_HZ)
"""``ux,uy,uz[,t][,temp]``: readings to correct (``align apply``, ``align tilt``)."""


def read_readings(path: str | Path, columns: Mapping[str, str] | None = None,
                  rate_hz: float | None = None) -> Table:
    """Readings ``ux,uy,uz[,t][,temp]`` (see :mod:`axisbase.table` for what is accepted)."""
    return read_table(path, READINGS, columns, rate_hz)


def _check_values(tab: Table, u: np.ndarray) -> None:
    for ax in range(3):
        col = u[:, ax]
        top, bottom = col.max(), col.min()
        for v in (top, bottom):
            hits = np.flatnonzero(col == v)
            if len(hits) >= max(5, 0.05 * len(col)) and np.ptp(col) > 0:
                raise tab.fail(int(hits[0]), f"u{'xyz'[ax]}", f"sits at {v:g} in {len(hits)} "
                               "samples: saturated or clipped")


def _rate(settings: StaticSettings) -> str:
    """How the user gives a sample rate: ``--rate HZ`` or ``[calibration] rate_hz = HZ``."""
    name = settings.names["rate_hz"]
    return f"{name} HZ" if name.startswith("--") else f"{name} = HZ"


def read_poses(path: str | Path, settings: StaticSettings = StaticSettings(),
               calibration: bool = True, columns: Mapping[str, str] | None = None,
               rate_hz: float | None = None, adc_range: tuple[float, float] | None = None,
               warnings: list[str] | None = None
               ) -> tuple[Poses, list[StaticInterval] | None]:
    """Per-pose means from a pose file, or from a continuous recording's static intervals.

    ``calibration``: check that the poses can carry a calibration (units, 3-D spread); off
    for check poses, which may be few. ``columns``, ``rate_hz``: see
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
        tab = read_table(path, STATIC, columns, rate_hz)
        if "pose" not in tab and "t" not in tab and len(tab) <= MEANS_ROWS:
            # ux,uy,uz without pose or time, a few rows: per-pose means (as for arrays).
            labels = np.array([str(i + 1) for i in range(len(tab))], dtype=object)
            tab = replace(tab, data={**tab.data, "pose": labels})
            logging.getLogger("align").warning(
                "%s: %d rows, no pose or time column: each row read as one pose's mean "
                "(a recording needs %s)", path, len(tab), _rate(settings))
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
                             f"column t (give {_rate(settings)} for a recording without time "
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
            tm = np.array([temp[(t >= iv.start_s) & (t <= iv.end_s)].mean() for iv in intervals])
        poses = Poses(mean, tt, tm, sig, count,
                      tuple(f"static@{iv.start_s:.1f}s" for iv in intervals))
        samples = [u[(t >= iv.start_s) & (t <= iv.end_s)] for iv in intervals]
    if t is not None:  # the bias instability the samples within the poses show
        times = ([t[ids == i] for i in range(len(samples))] if intervals is None else
                 [t[(t >= iv.start_s) & (t <= iv.end_s)] for iv in intervals])
        rate, bound = walk_levels(samples, times)
        poses = replace(poses, walk_rate=rate, walk_bound=bound)
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
                                 f" ({settings.flags(*_DETECT_KEYS)})"
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
    rest = Poses(poses.u[keep], poses.t[keep],
                 None if poses.temp is None else poses.temp[keep],
                 None if poses.sigma_u is None else poses.sigma_u[keep], poses.count[keep],
                 tuple(lab for lab, k in zip(poses.labels, keep, strict=True) if k),
                 poses.ordered, poses.walk_rate, poses.walk_bound)
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


@dataclass(frozen=True)
class StaticDetection:
    """What the detector saw: the intervals, and the numbers it decided with.

    ``noise``: per-channel noise of the samples [output units] (from the quietest windows);
    ``noise_mean``: standard deviation of a window mean per channel (the Allan deviation at
    the window length, never below the white-noise value); ``window``: samples per window;
    ``limit``: the moving-std ratio below which a window is static; ``rate_hz`` the sample
    rate from the time stamps; ``ratio``: the moving-std ratio of every sample (for plots);
    ``notes``: what the user should know (e.g. a time column that looks like a row index).
    """

    intervals: tuple[StaticInterval, ...]
    noise: np.ndarray
    noise_mean: np.ndarray
    window: int
    limit: float
    rate_hz: float
    ratio: np.ndarray
    notes: tuple[str, ...] = ()


MIN_WINDOW = 5
"""Fewest samples in a detection window (a standard deviation of fewer means nothing)."""


def _quantum(x: np.ndarray) -> float:
    """The output quantum of one channel (0 for unquantised data): the smallest step between
    distinct values, when the values sit on a grid of it."""
    v = np.unique(x[: 200_000])
    if len(v) < 2 or len(v) > len(x) // 4 + 2:
        return 0.0
    q = float(np.min(np.diff(v)))
    return q if np.allclose(np.diff(v) / q, np.round(np.diff(v) / q), atol=0.02) else 0.0


def noise_levels(u: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel sample noise and window-mean noise from the quietest windows.

    Non-overlapping windows of ``n`` samples; a window's total normalised scatter ranks it,
    and the quietest fifth of the windows gives the noise (its standard deviation, corrected
    for taking the quietest by the chi-square quantile). The mean's noise is the Allan
    deviation at ``n`` samples over adjacent pairs of quiet windows (median form, robust to a
    pair that straddles a small move), never below the white value noise / sqrt(n).
    """
    nb = len(u) // n
    m = u.shape[1]
    if nb < 4:
        sd = u.std(0, ddof=1)
        return np.maximum(sd, 1e-300), np.maximum(sd / np.sqrt(n), 1e-300)
    blocks = u[: nb * n].reshape(nb, n, m)
    sd = blocks.std(1, ddof=1)
    means = blocks.mean(1)
    q = np.array([_quantum(u[:, i]) for i in range(m)])
    # Rank by scatter relative to each channel's median scatter (channels differ in units).
    med = np.maximum(np.median(sd, 0), q / np.sqrt(12) + 1e-300)
    score = np.sqrt(np.mean((sd / med) ** 2, 1))
    quiet = score <= np.percentile(score, 20)
    # The quietest fifth of windows of pure noise sits below the mean scatter: with d = m(n-1)
    # degrees of freedom, E[X | X < q] = d F_{d+2}(q) / F_d(q) for X ~ chi2(d) (white noise;
    # exact enough for a threshold).
    d = m * (n - 1)
    corr = np.sqrt(special.chdtr(d + 2, special.chdtri(d, 0.8)) / 0.2)
    noise = np.sqrt(np.mean(sd[quiet] ** 2, 0)) / corr
    noise = np.maximum(noise, q / np.sqrt(12))
    noise = np.maximum(noise, 1e-12 * np.maximum(np.abs(u).max(0), 1e-300))
    pairs = quiet[:-1] & quiet[1:]
    white = noise / np.sqrt(n)
    if pairs.sum() >= 5:
        d2 = (means[1:][pairs] - means[:-1][pairs]) ** 2
        allan = np.sqrt(np.median(d2, 0) / special.chdtri(1, 0.5) / 2)
        return noise, np.maximum(allan, white)
    return noise, white


def detect_static(t: np.ndarray, u: np.ndarray, settings: StaticSettings = StaticSettings()
                  ) -> StaticDetection:
    """Static intervals of a continuous recording, with thresholds from its own noise.

    1. Noise of each channel from the quietest windows (:func:`noise_levels`).
    2. A sample is *quiet* when the centred moving standard deviation over ``window_s``,
       normalised channel by channel by that noise, stays below ``threshold`` (and never
       below the 1e-4 upper quantile of a static window's chi-square spread).
    3. Every sample of a quiet window belongs to the interval; ``margin_s`` is cut from each
       end (settling), and intervals shorter than ``min_duration_s`` are dropped.
    4. An interval whose mean changes inside it (a slow turn the moving std cannot see) is
       split where the change is largest while the two sides' means differ by more than
       ``split_sigma`` of their noise (binary segmentation), the Allan deviation setting the
       noise of a mean.
    """
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    rate = 1.0 / dt
    notes = []
    if dt == 1.0 and np.all(t == np.round(t)):
        notes.append("the time column steps by exactly 1: if it is a row index, give the "
                     f"sample rate with {_rate(settings)} (durations are read in seconds)")
    n = max(MIN_WINDOW, int(round(settings.window_s * rate)))
    if len(u) < 2 * n:
        return StaticDetection((), np.full(u.shape[1], np.nan), np.full(u.shape[1], np.nan),
                               n, float("nan"), rate, np.zeros(len(u)), tuple(notes))
    noise, noise_mean = noise_levels(u, n)
    # One g in output units per channel, from the spread of window means (half their range):
    # a tilt of split_rad moves a channel by at most sin(split_rad) of it.
    nb = len(u) // n
    wm = u[: nb * n].reshape(nb, n, -1).mean(1)
    g_out = (np.percentile(wm, 99, 0) - np.percentile(wm, 1, 0)) / 2
    floor = np.sin(settings.split_rad) * g_out
    m = uniform_filter1d(u, n, axis=0, mode="nearest")
    m2 = uniform_filter1d(u * u, n, axis=0, mode="nearest")
    var = np.maximum(m2 - m * m, 0) * (n / (n - 1))
    ratio = np.sqrt(np.mean(var / noise**2, axis=1))
    k = u.shape[1] * (n - 1)
    limit = max(settings.threshold, float(np.sqrt(special.chdtri(k, 1e-4) / k)))
    quiet = ratio <= limit
    edges = np.diff(np.concatenate([[0], quiet.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    # uniform_filter1d's window for centre j covers j - n//2 .. j - n//2 + n - 1.
    lo_ext, hi_ext = n // 2, n - 1 - n // 2
    cut = int(round(settings.margin_s * rate))
    shortest = max(n, int(round(settings.min_duration_s * rate)))
    out: list[StaticInterval] = []
    for a, b in zip(starts, ends, strict=True):
        a2 = max(0, a - lo_ext) + cut
        b2 = min(len(u) - 1, b + hi_ext) - cut
        for s, e in _split(u, a2, b2 + 1, noise_mean, floor, n, settings.split_sigma,
                           shortest):
            sel = slice(s, e)
            out.append(StaticInterval(float(t[s]), float(t[e - 1]), e - s, u[sel].mean(0),
                                      u[sel].std(0, ddof=1), _sem(u[sel], max(n, (e - s) // 8))))
    return StaticDetection(tuple(out), noise, noise_mean, n, limit, rate, ratio, tuple(notes))


def _split(u: np.ndarray, s: int, e: int, noise_mean: np.ndarray, floor: np.ndarray, n: int,
           z: float, shortest: int) -> list[tuple[int, int]]:
    """Binary segmentation of samples s..e-1 on a change of mean (see detect_static, 4).

    Hand-written: a two-segment mean-shift search is a few lines of cumulative sums, and
    the change-point libraries (ruptures) would be a dependency for this alone.
    """
    if e - s < shortest:
        return []
    if e - s < 2 * n:
        return [(s, e)]
    L, step, se = _steps(u, s, e, n, noise_mean)
    stat = np.max(np.where(step > floor[None, :], step / se, 0.0), axis=1)
    j = int(np.argmax(stat))
    if stat[j] > z:
        k = s + int(L[j])
        return (_split(u, s, k, noise_mean, floor, n, z, shortest)
                + _split(u, k, e, noise_mean, floor, n, z, shortest))
    # One pose. An end shorter than the shortest interval that differs from the rest is
    # motion or settling at the edge: cut it, however small the move.
    while e - s >= 2 * n:
        edge = (L < shortest) | (e - s - L < shortest)
        zs = np.max(step / se, axis=1)
        if not edge.any() or zs[edge].max() <= z:
            break
        j = int(np.flatnonzero(edge)[np.argmax(zs[edge])])
        s, e = (s + int(L[j]), e) if L[j] < e - s - L[j] else (s, s + int(L[j]))
        if e - s >= 2 * n:
            L, step, se = _steps(u, s, e, n, noise_mean)
    return [(s, e)] if e - s >= shortest else []


def _steps(u: np.ndarray, s: int, e: int, n: int, noise_mean: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every split of samples s..e-1 with both sides at least a window: the left
    length, |mean left - mean right| per channel and its standard error."""
    c = np.cumsum(u[s:e], axis=0)
    total = c[-1]
    L = np.arange(n, e - s - n + 1)
    left = c[L - 1] / L[:, None]
    right = (total - c[L - 1]) / (e - s - L)[:, None]
    # Noise of a mean of L samples from the window-mean noise (white beyond a window).
    se = noise_mean[None, :] * np.sqrt(n / L[:, None] + n / (e - s - L)[:, None])
    return L, np.abs(left - right), se


def find_static(t: np.ndarray, u: np.ndarray, settings: StaticSettings = StaticSettings()
                ) -> list[StaticInterval]:
    """Static intervals of a recording (see :func:`detect_static`)."""
    return list(detect_static(t, u, settings).intervals)


def _sem(x: np.ndarray, block: int) -> np.ndarray:
    """Standard error of the mean that survives correlated (non-white) noise.

    From the scatter of block means (blocks of the detection window or an eighth of the
    interval, the longer), never below the white-noise value: real sensors' samples are
    filtered and wander at low frequency, which short blocks would not see.
    """
    white = x.std(0, ddof=1) / np.sqrt(len(x))
    nb = len(x) // block
    if nb < 3:
        return white
    means = x[:nb * block].reshape(nb, block, -1).mean(1)
    return np.maximum(white, means.std(0, ddof=1) / np.sqrt(nb))
