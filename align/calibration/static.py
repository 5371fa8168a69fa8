"""Reading static tumble data and finding the static intervals of continuous recordings.

Formats (CSV with a header line):

* ``pose,ux,uy,uz[,t][,temp]`` — samples (several rows per pose) or per-pose means;
* ``t,ux,uy,uz[,temp]`` — a continuous recording; the static intervals are found by a
  moving standard deviation compared with the recording's own noise floor.

Both are read by the tool's one table reader (:mod:`axisbase.table`); every problem is
reported as ``file:line: column: what is wrong``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d

from align.calibration.model import Poses
from axisbase.errors import InputError
from axisbase.table import Column, Table, TableSpec, read_table


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


@dataclass(frozen=True)
class StaticSettings:
    """Detection settings: moving window [s], threshold as a multiple of the noise floor
    (the 10th percentile of the moving standard deviation), shortest interval [s], and the
    margin cut from each end of an interval [s] (settling)."""

    window_s: float = 1.0
    threshold: float = 3.0
    min_duration_s: float = 2.0
    margin_s: float = 0.5


_AXES = {ax: (f"a{ax}", f"acc_{ax}", f"accel_{ax}", f"acc{ax}", f"u_{ax}") for ax in "xyz"}
_T = Column("t", required=False, aliases=("time", "t_s", "time_s", "timestamp"))
_TEMP = Column("temp", required=False, aliases=("temperature", "temp_c", "temperature_c"))
_U = tuple(Column(f"u{ax}", aliases=_AXES[ax]) for ax in "xyz")
STATIC = TableSpec("static-pose file", (
    Column("pose", "label", required=False, aliases=("pose_id", "position", "label")),
    *_U, _T, _TEMP), time="t", distinct_rows=True)
"""``pose,ux,uy,uz[,t][,temp]`` (samples or per-pose means) or ``t,ux,uy,uz[,temp]``."""
READINGS = TableSpec("readings file", (*_U, _T, _TEMP), time="t", distinct_rows=True)
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


def read_poses(path: str | Path, settings: StaticSettings = StaticSettings(),
               calibration: bool = True, columns: Mapping[str, str] | None = None,
               rate_hz: float | None = None) -> tuple[Poses, list[StaticInterval] | None]:
    """Per-pose means from a pose file, or from a continuous recording's static intervals.

    ``calibration``: check that the poses can carry a calibration (units, 3-D spread); off
    for check poses, which may be few. ``columns``, ``rate_hz``: see
    :func:`axisbase.table.read_table`.
    """
    path = Path(path)
    tab = read_table(path, STATIC, columns, rate_hz)
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    _check_values(tab, u)
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
        mean = np.array([u[ids == i].mean(0) for i in range(n)])
        sig = None
        if count.min() >= 3:
            sig = np.array([u[ids == i].std(0, ddof=1) / np.sqrt(count[i]) for i in range(n)])
        tt = (np.array([t[ids == i].mean() for i in range(n)]) if t is not None
              else np.arange(n, dtype=float))
        tm = np.array([temp[ids == i].mean() for i in range(n)]) if temp is not None else None
        poses = Poses(mean, tt, tm, sig, count, order)
        intervals = None
    else:
        if t is None:
            raise InputError(f"{path}: neither a pose column nor a time column t (give "
                             "--rate HZ for a recording without time stamps)")
        intervals = find_static(t, u, settings)
        if not intervals:
            raise InputError(f"{path}: no static interval found (window {settings.window_s} s,"
                             f" threshold {settings.threshold} x noise floor, at least "
                             f"{settings.min_duration_s} s)")
        mean = np.array([iv.mean for iv in intervals])
        count = np.array([iv.samples for iv in intervals])
        sig = np.array([iv.sem for iv in intervals])
        tt = np.array([(iv.start_s + iv.end_s) / 2 for iv in intervals])
        tm = None
        if temp is not None:
            tm = np.array([temp[(t >= iv.start_s) & (t <= iv.end_s)].mean() for iv in intervals])
        poses = Poses(mean, tt, tm, sig, count,
                      tuple(f"static@{iv.start_s:.1f}s" for iv in intervals))
    if calibration:
        _check_geometry(path, poses)
    return poses, intervals


def _check_geometry(path: Path, poses: Poses) -> None:
    u = poses.u
    norms = np.linalg.norm(u - np.median(u, 0), axis=1)
    med = np.median(norms)
    odd = np.flatnonzero((norms > 3 * med) | (norms < med / 3))
    if odd.size and len(u) > 3:
        raise InputError(f"{path}: pose {poses.labels[odd[0]]} has |u - median| = "
                         f"{norms[odd[0]]:.4g} against a typical {med:.4g}: mixed units?")
    if len(u) >= 3:
        s = np.linalg.svd(u - u.mean(0), compute_uv=False)
        if s[-1] < 1e-3 * s[0]:
            raise InputError(f"{path}: the {len(u)} poses lie in a plane (degenerate "
                             "geometry): tilt the unit out of that plane")


def find_static(t: np.ndarray, u: np.ndarray, settings: StaticSettings
                ) -> list[StaticInterval]:
    """Static intervals: moving std of every axis below threshold x the noise floor."""
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(settings.window_s / dt)))
    m = uniform_filter1d(u, w, axis=0, mode="nearest")
    m2 = uniform_filter1d(u * u, w, axis=0, mode="nearest")
    sd = np.sqrt(np.maximum(m2 - m * m, 0)).max(axis=1)
    floor = float(np.percentile(sd, 10))
    quiet = sd <= settings.threshold * max(floor, 1e-12)
    edges = np.diff(np.concatenate([[0], quiet.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    out = []
    for a, b in zip(starts, ends, strict=True):
        ta, tb = t[a] + settings.margin_s + dt * w / 2, t[b] - settings.margin_s - dt * w / 2
        if tb - ta < settings.min_duration_s:
            continue
        sel = (t >= ta) & (t <= tb)
        out.append(StaticInterval(float(ta), float(tb), int(sel.sum()), u[sel].mean(0),
                                  u[sel].std(0, ddof=1), _sem(u[sel], w)))
    return out


def _sem(x: np.ndarray, block: int) -> np.ndarray:
    """Standard error of the mean that survives correlated (non-white) noise.

    From the scatter of block means (blocks of the detection window), never below the
    white-noise value: real sensors' samples are filtered and wander at low frequency.
    """
    white = x.std(0, ddof=1) / np.sqrt(len(x))
    nb = len(x) // block
    if nb < 3:
        return white
    means = x[:nb * block].reshape(nb, block, -1).mean(1)
    return np.maximum(white, means.std(0, ddof=1) / np.sqrt(nb))
