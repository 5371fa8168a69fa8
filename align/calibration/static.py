"""Reading static tumble data and finding the static intervals of continuous recordings.

Formats (CSV with a header line):

* ``pose,ux,uy,uz[,t][,temp]`` — samples (several rows per pose) or per-pose means;
* ``t,ux,uy,uz[,temp]`` — a continuous recording; the static intervals are found by a
  moving standard deviation compared with the recording's own noise floor.

Every problem is reported with the file, the line and what is wrong.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d

from align.calibration.model import Poses
from align.errors import InputError

REQUIRED = ("ux", "uy", "uz")


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


def read_table(path: Path) -> tuple[list[str], np.ndarray, list[int], list[str] | None]:
    """Header (lower case), numbers, source line numbers, pose labels in order of appearance."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text CSV file") from None
    rows = list(csv.reader(text.splitlines()))
    lines = [i + 1 for i, r in enumerate(rows) if r and not r[0].startswith("#")]
    rows = [r for r in rows if r and not r[0].startswith("#")]
    if not rows:
        raise InputError(f"{path}: empty file")
    head = [h.strip().lower() for h in rows[0]]
    missing = [c for c in REQUIRED if c not in head]
    if missing:
        raise InputError(f"{path}, line {lines[0]}: header {rows[0]} lacks {missing}; expected "
                         "pose,ux,uy,uz[,t][,temp] or t,ux,uy,uz[,temp]")
    data = np.empty((len(rows) - 1, len(head)))
    for k, (r, ln) in enumerate(zip(rows[1:], lines[1:], strict=True)):
        if len(r) != len(head):
            raise InputError(f"{path}, line {ln}: {len(r)} fields, the header has {len(head)}"
                             + (" (truncated last line?)" if k == len(rows) - 2 else ""))
        for j, v in enumerate(r):
            try:
                data[k, j] = float(v)
            except ValueError:
                if head[j] == "pose":
                    data[k, j] = np.nan  # labels handled below
                else:
                    raise InputError(f"{path}, line {ln}: {head[j]} = {v!r} is not a "
                                     "number") from None
            if head[j] != "pose" and not np.isfinite(data[k, j]):
                raise InputError(f"{path}, line {ln}: {head[j]} is {v!r} (not finite)")
    if "pose" in head:
        j = head.index("pose")
        labels = [r[j].strip() for r in rows[1:]]
        # Keep the poses in the order they first appear.
        first = {lab: i for i, lab in reversed(list(enumerate(labels)))}
        order = sorted(set(labels), key=lambda lab: first[lab])
        data[:, j] = [order.index(lab) for lab in labels]
        head[j] = "pose"
        return head, data, lines[1:], order
    return head, data, lines[1:], None


def _check_values(path: Path, u: np.ndarray, lines: list[int]) -> None:
    for ax in range(3):
        col = u[:, ax]
        top, bottom = col.max(), col.min()
        for v in (top, bottom):
            hits = np.flatnonzero(col == v)
            if len(hits) >= max(5, 0.05 * len(col)) and np.ptp(col) > 0:
                raise InputError(f"{path}, line {lines[hits[0]]}: u{'xyz'[ax]} sits at "
                                 f"{v:g} in {len(hits)} samples: saturated or clipped")


def read_poses(path: str | Path, settings: StaticSettings = StaticSettings(),
               calibration: bool = True) -> tuple[Poses, list[StaticInterval] | None]:
    """Per-pose means from a pose file, or from a continuous recording's static intervals.

    ``calibration``: check that the poses can carry a calibration (units, 3-D spread); off
    for check poses, which may be few.
    """
    path = Path(path)
    head, data, lines, order = read_table(path)
    col = {h: i for i, h in enumerate(head)}
    u = data[:, [col["ux"], col["uy"], col["uz"]]]
    _check_values(path, u, lines)
    t = data[:, col["t"]] if "t" in col else None
    temp = data[:, col["temp"]] if "temp" in col else None
    if "pose" in col:
        ids = data[:, col["pose"]].astype(int)
        n = ids.max() + 1
        count = np.bincount(ids, minlength=n)
        mean = np.array([u[ids == i].mean(0) for i in range(n)])
        sig = None
        if count.min() >= 3:
            sig = np.array([u[ids == i].std(0, ddof=1) / np.sqrt(count[i]) for i in range(n)])
        tt = (np.array([t[ids == i].mean() for i in range(n)]) if t is not None
              else np.arange(n, dtype=float))
        tm = np.array([temp[ids == i].mean() for i in range(n)]) if temp is not None else None
        poses = Poses(mean, tt, tm, sig, count, tuple(order))
        intervals = None
    else:
        if t is None:
            raise InputError(f"{path}: neither a pose column nor a time column t")
        if np.any(np.diff(t) <= 0):
            k = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise InputError(f"{path}, line {lines[k + 1]}: time does not increase")
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
