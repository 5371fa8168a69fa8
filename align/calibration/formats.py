"""Readers for published third-party accelerometer recordings (read in place, never copied).

Each returns (t [s], u (N, 3)) in the recording's own units, or pose means for files that
hold only means. Used by the real-data tests and benchmarks/real_calibration.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from align.calibration.triad import poses_from_samples
from align.errors import InputError


def xsens_text(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """imu_tk test data: whitespace text 't ax ay az' (raw ADC counts), despite '.mat'."""
    d = np.loadtxt(path)
    return d[:, 0], d[:, 1:4]


def openaxes(path: str | Path, sensor: str = "ADXL355") -> tuple[np.ndarray, np.ndarray]:
    """OpenAXES log (';'-separated): the on-device INDEX is the 100 Hz sample clock.

    Only the four columns used are converted (``np.loadtxt``'s ``usecols``: the same
    numbers as reading every column with inferred types, at a fifth of the CPU)."""
    with open(path, encoding="ascii") as f:
        names = next(f).strip().split(";")
    cols = [f"ACCEL_{sensor}_{k}" for k in range(3)]
    if any(c not in names for c in ["INDEX", *cols]):
        raise InputError(f"{path}: no columns {cols}")
    raw = np.loadtxt(path, delimiter=";", skiprows=1, encoding="ascii", ndmin=2,
                     usecols=[names.index(c) for c in ["INDEX", *cols]])
    n = np.unwrap(np.ascontiguousarray(raw[:, 0]), period=65536)
    return (n - n[0]) / 100.0, np.ascontiguousarray(raw[:, 1:])


def mpu6050(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """tomisuarez2 ImuCalibration CSV: 4 meta lines (Fs first), a header, int16 counts."""
    with open(path) as f:
        meta = dict(next(f).strip().split(",", 1) for _ in range(4))
    d = np.loadtxt(path, delimiter=",", skiprows=5)
    fs = float(meta["Fs"])
    return np.arange(len(d)) / fs, d[:, 0:3]


def mat_pose_means(path: str | Path) -> np.ndarray:
    """A MATLAB file holding one 3xN or Nx3 array of pose means."""
    import scipy.io as sio

    d = sio.loadmat(path)
    v = d[[k for k in d if not k.startswith("__")][0]]
    return v.T if v.shape[0] == 3 else v


FERRARIS_FACES = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
"""imucal's names of the six faces (+x, -x, ... up) in a Ferraris session list."""


def ferraris_session(folder: str | Path, rate_hz: float = 102.4):
    """imucal's example Ferraris session (``example_ferraris_session.csv`` and its
    ``_list.json`` of sections): the six faces as :class:`Poses` (accelerometer, m/s²; the
    turns are for the gyroscope and are left out), the raw columns and the sections."""
    import json

    folder = Path(folder)
    d = np.genfromtxt(folder / "example_ferraris_session.csv", delimiter=",", names=True)
    u = np.column_stack([d["acc_x"], d["acc_y"], d["acc_z"]])
    sec = json.loads((folder / "example_ferraris_session_list.json").read_text())
    ids = np.full(len(u), -1)
    for i, n in enumerate(FERRARIS_FACES):
        ids[sec[n]["start"]:sec[n]["end"]] = i
    sel = ids >= 0
    poses = poses_from_samples(ids[sel], u[sel], np.arange(len(u))[sel] / rate_hz,
                               list(FERRARIS_FACES))
    return poses, d, sec


def imucal_ferraris(d: np.ndarray, sec: dict, rate_hz: float = 102.4):
    """imucal's own ``FerrarisCalibration`` of that session (the peer the tests and
    benchmarks compare with; needs the optional ``bench`` extra): (its CalibrationInfo, its g
    [m/s²])."""
    import imucal
    import pandas as pd

    df = pd.DataFrame({k: d[k] for k in ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y",
                                         "gyr_z")})
    parts = []
    for k, v in sec.items():
        x = df.iloc[v["start"]:v["end"]].copy()
        x["part"] = k
        parts.append(x)
    regions = imucal.ferraris_regions_from_df(pd.concat(parts).set_index("part"))
    fc = imucal.FerrarisCalibration()
    return fc.compute(regions, rate_hz, "m/s^2", "deg/s"), fc.grav
