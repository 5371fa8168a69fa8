"""Finding the static intervals of a continuous recording: the detection settings (each
checked by its one rule, named as the user set it), the recording's own noise and the
intervals where the moving standard deviation stays below a multiple of it, split where the
mean moves (:func:`detect_static`). Reading the files is :mod:`align.calibration.static`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.ndimage import uniform_filter1d

from axisbase.errors import InputError
from axisbase.units import DEG


@dataclass(frozen=True)
class StaticInterval:
    """A static interval of a recording: times [s], samples, mean, scatter and standard error
    of the mean of u (same unit as u); ``left_out``: (first, last) sample times [s] of the
    disturbances inside it that are not its samples (a tap between two runs of one pose)."""

    start_s: float
    end_s: float
    samples: int
    mean: np.ndarray
    std: np.ndarray
    sem: np.ndarray
    left_out: tuple[tuple[float, float], ...] = ()

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    def mask(self, t: np.ndarray) -> np.ndarray:
        """Which of the recording's samples (times ``t`` [s]) are this interval's."""
        sel = (t >= self.start_s) & (t <= self.end_s)
        for a, b in self.left_out:
            sel &= (t < a) | (t > b)
        return sel


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


DETECT_KEYS = ("window_s", "threshold", "min_duration_s", "margin_s")
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
        degrees) is split (a slow turn the moving window cannot see; smaller moves are
        settling, not a new pose).
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




DEFAULT_SETTINGS = StaticSettings()
"""The detection settings when none are given."""

def rate_flag(settings: StaticSettings) -> str:
    """How the user gives a sample rate: ``--rate HZ`` or ``[calibration] rate_hz = HZ``."""
    name = settings.names["rate_hz"]
    return f"{name} HZ" if name.startswith("--") else f"{name} = HZ"



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
                     f"sample rate with {rate_flag(settings)} (durations are read in seconds)")
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
    pieces: list[list[tuple[int, int]]] = []
    for a, b in zip(starts, ends, strict=True):
        a2 = max(0, a - lo_ext) + cut
        b2 = min(len(u) - 1, b + hi_ext) - cut
        for s, e in _split(u, a2, b2 + 1, noise_mean, floor, n, settings.split_sigma,
                           shortest):
            # A disturbance between two quiet runs (a tap on the fixture, a burst of samples)
            # that leaves the attitude where it was is not a new pose: by the split rule's own
            # test (mean moved by split_sigma standard errors and split_deg), the two runs are
            # one pose — the rule that splits a quiet run also decides when two are one.
            if pieces and not _moved(u, pieces[-1], (s, e), noise_mean, floor, n,
                                     settings.split_sigma):
                pieces[-1].append((s, e))
            else:
                pieces.append([(s, e)])
    out: list[StaticInterval] = []
    for runs in pieces:
        x = np.concatenate([u[s:e] for s, e in runs])
        # (Two runs a change point split apart and the whole-run test joined again touch:
        # no sample between them is left out.)
        gaps = tuple((float(t[e]), float(t[s2 - 1]))
                     for (_, e), (s2, _) in zip(runs[:-1], runs[1:], strict=True) if s2 > e)
        out.append(StaticInterval(float(t[runs[0][0]]), float(t[runs[-1][1] - 1]), len(x),
                                  x.mean(0), x.std(0, ddof=1), _sem(x, max(n, len(x) // 8)),
                                  gaps))
    return StaticDetection(tuple(out), noise, noise_mean, n, limit, rate, ratio, tuple(notes))


def _moved(u: np.ndarray, before: list[tuple[int, int]], after: tuple[int, int],
           noise_mean: np.ndarray, floor: np.ndarray, n: int, z: float) -> bool:
    """Whether the attitude moved from the runs ``before`` (one pose so far) to the quiet run
    ``after``: by the split rule (a channel's mean moved by more than ``z`` standard errors
    and more than ``floor``, see :func:`_split`), or, in between, the samples' mean left the
    pose by more than ``floor`` — a turn that came back (a full revolution about a horizontal
    axis) is motion, while a tap's ringing averages out about the pose it leaves."""
    x = np.concatenate([u[s:e] for s, e in before])
    y = u[after[0]:after[1]]
    step = np.abs(x.mean(0) - y.mean(0))
    se = noise_mean * np.sqrt(n / len(x) + n / len(y))
    gap = u[before[-1][1]:after[0]]
    away = len(gap) > 0 and bool(np.any(np.abs(gap.mean(0) - x.mean(0)) > floor))
    return away or bool(np.any((step > floor) & (step / se > z)))


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
