"""Readers for published third-party accelerometer recordings (read in place, never copied).

Each returns (t [s], u (N, 3)) in the recording's own units, or pose means for files that
hold only means. Used by the real-data tests and benchmarks/real_calibration.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from align.errors import InputError


def xsens_text(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """imu_tk test data: whitespace text 't ax ay az' (raw ADC counts), despite '.mat'."""
    d = np.loadtxt(path)
    return d[:, 0], d[:, 1:4]


def openaxes(path: str | Path, sensor: str = "ADXL355") -> tuple[np.ndarray, np.ndarray]:
    """OpenAXES log (';'-separated): the on-device INDEX is the 100 Hz sample clock."""
    raw = np.genfromtxt(path, delimiter=";", names=True, dtype=None, encoding="ascii")
    n = np.unwrap(raw["INDEX"].astype(float), period=65536)
    cols = [f"ACCEL_{sensor}_{k}" for k in range(3)]
    if any(c not in raw.dtype.names for c in cols):
        raise InputError(f"{path}: no columns {cols}")
    return (n - n[0]) / 100.0, np.column_stack([raw[c] for c in cols]).astype(float)


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
