"""Static data in named arrays: MATLAB ``.mat`` (scipy.io) and numpy ``.npz`` files.

The arrays become the same :class:`axisbase.table.Table` the CSV reader returns, so every
later check is shared. Which variable is what:

* given by ``--columns``: ``u=NAME`` (an N x 3 or 3 x N array), or ``ux=NAME,uy=...,uz=...``
  (vectors), ``t=NAME``, ``temp=NAME``, ``pose=NAME``;
* else found when unambiguous: the one numeric array with a dimension of 3 is u (4 columns
  whose first increases strictly: t, ux, uy, uz); a vector as long named t/time/timestamp is t.

A ``.mat`` that is really whitespace-separated text (imu_tk's test data) is read as a matrix
of 3 (ux, uy, uz) or 4 (t, ux, uy, uz) columns, and the reader says so.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import numpy as np

from axisbase.errors import InputError
from axisbase.repeats import check_repeats
from axisbase.table import Table, TableSpec

SUFFIXES = (".mat", ".npz")
MEANS_ROWS = 500
"""Without time stamps or a rate, an array of at most this many rows is read as per-pose
means (one row a pose); a longer one needs ``--rate``."""
_TIME = ("t", "time", "timestamp", "t_s", "time_s")
_BY_NAME = {"t": _TIME, "pose": ("pose", "poses", "label", "labels"),
            "temp": ("temp", "temperature", "temp_c")}
"""The variable names found without ``--columns`` (case-insensitive), as the CSV headers'."""


def _load(path: Path) -> tuple[dict[str, np.ndarray], str]:
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as z:
                return {k: np.asarray(z[k]) for k in z.files}, ""
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: not a readable .npz file ({exc})") from None
    import scipy.io as sio

    try:
        d = sio.loadmat(path)
        return {k: np.asarray(v) for k, v in d.items() if not k.startswith("__")}, ""
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (ValueError, TypeError, OSError, NotImplementedError):
        pass
    try:
        m = np.loadtxt(path, ndmin=2)
    except (ValueError, UnicodeDecodeError):
        raise InputError(f"{path}: neither a MATLAB file scipy can read (v4-v7.2; v7.3 is "
                         "HDF5: save with -v7) nor a text matrix") from None
    return {"text": m}, f"{path}: not a MATLAB file but a text matrix; read as such"


def _numeric(v: np.ndarray) -> bool:
    return v.dtype.kind in "fiu" and v.size > 0


def read_arrays(path: str | Path, spec: TableSpec, columns: Mapping[str, str] | None = None,
                rate_hz: float | None = None, names: Mapping[str, str] | None = None
                ) -> tuple[Table, list[str]]:
    """The table in a .mat/.npz file, and notes on how it was read (for the terminal).
    ``names``: how the user gave ``rate_hz`` and ``columns`` (default the flags ``--rate``,
    ``--columns``; a session's keys), for the messages."""
    rate_name = (names or {}).get("rate_hz", "--rate")
    cols_name = (names or {}).get("columns", "--columns")
    path = Path(path)
    arrays, note = _load(path)
    notes = [note] if note else []
    cols = dict(columns or {})
    data: dict[str, np.ndarray] = {}

    def get(name: str, flag: str) -> np.ndarray:
        if name not in arrays:
            raise InputError(f"{cols_name} {flag}={name}: {path} has no variable {name!r} "
                             f"(it has {', '.join(sorted(arrays)) or 'none'})")
        return np.asarray(arrays[name])

    if "u" in cols:
        u = get(cols.pop("u"), "u")
    elif all(f"u{a}" in cols for a in "xyz"):
        u = np.column_stack([get(cols.pop(f"u{a}"), f"u{a}").ravel() for a in "xyz"])
    else:
        cands = {k: v for k, v in arrays.items()
                 if _numeric(v) and v.ndim == 2 and (3 in v.shape or 4 in v.shape)}
        if len(cands) != 1:
            raise InputError(f"{path}: {'no' if not cands else 'several'} N x 3 arrays "
                             f"({', '.join(sorted(cands)) or 'none'} of "
                             f"{', '.join(sorted(arrays)) or 'none'}): name the outputs with "
                             f"{cols_name} u=NAME")
        name, u = next(iter(cands.items()))
        notes.append(f"{path}: outputs from variable {name!r} {u.shape}")
    u = np.asarray(u, float)
    if u.ndim != 2 or 3 not in u.shape and 4 not in u.shape:
        raise InputError(f"{path}: outputs {u.shape}: expected N x 3 (or 3 x N)")
    if u.shape[1] not in (3, 4) and u.shape[0] in (3, 4):
        u = u.T
    if u.shape[1] == 4:
        if np.all(np.diff(u[:, 0]) > 0):
            data["t"] = u[:, 0].copy()
            u = u[:, 1:]
            notes.append(f"{path}: 4 columns, the first increasing: read as t, ux, uy, uz")
        else:
            raise InputError(f"{path}: a 4-column array whose first column is not a time; "
                             f"name the variables with {cols_name}")
    for i, a in enumerate("xyz"):
        data[f"u{a}"] = np.ascontiguousarray(u[:, i])
    n = len(u)
    for canon in ("t", "temp", "pose"):
        if canon in cols:
            v = get(cols.pop(canon), canon).ravel()
            data[canon] = v if canon == "pose" else v.astype(float)
        elif canon not in data:
            hits = [k for k, v in arrays.items() if k.lower() in _BY_NAME[canon]]
            if len(hits) > 1:
                raise InputError(f"{path}: variables {', '.join(sorted(hits))} could each be "
                                 f"{canon}: name one with {cols_name} {canon}=NAME")
            if hits:
                v = np.asarray(arrays[hits[0]]).ravel()
                if v.size != n:
                    raise InputError(f"{path}: variable {hits[0]!r} ({canon}) has {v.size} "
                                     f"values, the outputs {n}")
                data[canon] = v if canon == "pose" else v.astype(float)
                if canon != "t":
                    notes.append(f"{path}: {canon} from variable {hits[0]!r}")
    if cols:
        raise InputError(f"{cols_name}: {', '.join(sorted(cols))} not a column of a {spec.what}")
    for k, v in data.items():
        if len(v) != n:
            raise InputError(f"{path}: {k} has {len(v)} values, the outputs {n}")
        if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
            raise InputError(f"{path}: {k}: value {int(np.flatnonzero(~np.isfinite(v))[0])} "
                             "is not a finite number")
    if "pose" in data:
        data["pose"] = np.array([str(x) for x in data["pose"]], dtype=object)
    if rate_hz is not None:
        if "t" in data:
            raise InputError(f"{rate_name} {rate_hz:g}: {path} has its own time; give one or "
                             "the other")
        data["t"] = np.arange(n, dtype=float) / rate_hz
    elif "t" not in data and "pose" not in data:
        if n > MEANS_ROWS:
            raise InputError(f"{path}: {n} rows and no time: give the sample rate with "
                             f"{rate_name} (or name the time variable with {cols_name} "
                             "t=NAME)")
        data["pose"] = np.array([str(i + 1) for i in range(n)], dtype=object)
        notes.append(f"{path}: {n} rows, no time: each row read as one pose's mean")
    table = Table(path, spec, data, 0, time_from_rate=rate_hz is not None)
    if spec.distinct_rows:  # (rows named by their index, as below: no lines in an array)
        check_repeats(replace(table, in_memory=True))
    if "t" in data and not np.all(np.diff(data["t"]) > 0):
        k = int(np.flatnonzero(np.diff(data["t"]) <= 0)[0]) + 1
        raise InputError(f"{path}: t: value {k} does not increase (duplicated or unsorted?)")
    return table, notes
