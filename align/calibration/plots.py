"""The static-detection figure: the recording, the moving-std ratio against its limit, and
the intervals found shaded on both (``align calibrate --plot``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from align.calibration.static import STATIC, StaticSettings, detect_static
from align.figures import pyplot, write_png
from axisbase.table import read_table


def fig_static(t: np.ndarray, u: np.ndarray, settings: StaticSettings):
    det = detect_static(t, u, settings)
    plt = pyplot()
    fig, ax = plt.subplots(2, 1, figsize=(12, 6), sharex=True)
    for i, name in enumerate("xyz"):
        ax[0].plot(t, u[:, i], lw=0.6, label=f"u{name}")
    ax[1].semilogy(t, np.maximum(det.ratio, 1e-3), lw=0.6, color="k")
    ax[1].axhline(det.limit, color="r", lw=0.8, label=f"limit {det.limit:.2g}")
    for iv in det.intervals:
        for a in ax:
            a.axvspan(iv.start_s, iv.end_s, color="g", alpha=0.2, lw=0)
    ax[0].set_ylabel("output")
    ax[0].legend(loc="upper right")
    ax[0].set_title(f"{len(det.intervals)} static intervals (shaded); window {det.window} "
                    f"samples at {det.rate_hz:.4g} Hz")
    ax[1].set_ylabel("moving std / noise")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right")
    fig.tight_layout()
    return fig


def plot_static(path: str | Path, settings: StaticSettings,
                columns: Mapping[str, str] | None, rate_hz: float | None, folder: Path,
                time_unit: str | None = None) -> Path:
    """Write the detection figure of the recording ``path`` into ``folder`` (a new PNG)."""
    tab = read_table(path, STATIC, columns, rate_hz, time_unit)
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    return write_png(fig_static(tab["t"], u, settings), folder, "static_intervals")
