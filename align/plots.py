"""Figures a metrologist looks at (matplotlib, written as PNG files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from align.marks import MarkResult


def plot_mark(r: MarkResult, folder: str | Path) -> Path:
    """The mark's centres with the fitted line (exaggerated) and the residuals along it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = Path(r.image).stem
    out = folder / f"{stem}_mark{r.index}.png"
    k = 1
    while out.exists():
        out = folder / f"{stem}_mark{r.index}_{k}.png"
        k += 1
    before, after = r.loop.before, r.loop.after
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    t = np.asarray(before.regressors["t"])
    axes[0].errorbar(t, before.residuals, yerr=before.sigma, fmt=".", ms=2, lw=0.5,
                     label=f"straight line: RMS {before.rms:.3f} px")
    axes[0].set_ylabel("residual across mark [px]")
    axes[0].set_title(f"{r.image} mark {r.index}: angle {np.rad2deg(r.angle_rad):+.6f}° "
                      f"± {np.rad2deg(r.angle_u_rad) * 3600:.2f}″")
    axes[0].legend(loc="upper right")
    names = ", ".join(e.name for e in r.loop.effects) or "no effect added"
    axes[1].errorbar(np.asarray(after.regressors["t"]), after.residuals, yerr=after.sigma,
                     fmt=".", ms=2, lw=0.5, color="C1",
                     label=f"after loop ({names}): RMS {after.rms:.3f} px")
    axes[1].axhline(0, color="k", lw=0.5)
    axes[1].set_xlabel("position along the mark t [px]")
    axes[1].set_ylabel("residual [px]")
    axes[1].legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
