"""Figures a metrologist looks at (matplotlib): ``fig_*`` build them, ``plot_*`` write new PNG
files, ``png_bytes`` gives the PNG for embedding in a report."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from align.calibration import delta_g
from align.figures import PNG, jpeg_bytes, png_bytes, tight
from align.figures import new_png as _new_png
from align.figures import pyplot as _plt
from align.figures import write_png as _write
from align.marks import MarkResult

__all__ = ["PNG", "png_bytes", "jpeg_bytes", "plot_mark", "fig_mark", "plot_calibration",
           "fig_calibration", "plot_gonio", "fig_gonio", "fig_fusion", "_new_png", "_plt",
           "_write"]


def plot_mark(r: MarkResult, folder: str | Path, image: np.ndarray | None = None) -> Path:
    return _write(fig_mark(r, image), Path(folder), f"{Path(r.image).stem}_mark{r.index}")


def fig_mark(r: MarkResult, image: np.ndarray | None = None):
    """The mark in its image with the measured centres and the fitted line (when ``image`` is
    given), and its residuals across the straight line before and after the loop."""
    plt = _plt()
    before, after = r.loop.before, r.loop.after
    if image is None:
        fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    else:
        fig = plt.figure(figsize=(9, 10))
        gs = fig.add_gridspec(3, 1, height_ratios=(1.6, 1, 1))
        ax_img = fig.add_subplot(gs[0])
        axes = [fig.add_subplot(gs[1]), None]
        axes[1] = fig.add_subplot(gs[2], sharex=axes[0])
        _mark_on_image(ax_img, r, image)
    t = np.asarray(before.regressors["t"])
    axes[0].errorbar(t, before.residuals, yerr=before.sigma, fmt=".", ms=2, lw=0.5,
                     label=f"straight line: RMS {before.rms:.3f} px")
    axes[0].set_ylabel("residual across mark [px]")
    axes[0].set_title(f"{Path(r.image).name} mark {r.index}: angle "
                      f"{np.rad2deg(r.angle_rad):+.6f}° ± {np.rad2deg(r.angle_u_rad) * 3600:.2f}″")
    axes[0].legend(loc="upper right")
    names = ", ".join(e.name for e in r.loop.effects) or "no effect added"
    axes[1].errorbar(np.asarray(after.regressors["t"]), after.residuals, yerr=after.sigma,
                     fmt=".", ms=2, lw=0.5, color="C1",
                     label=f"after loop ({names}): RMS {after.rms:.3f} px")
    axes[1].axhline(0, color="k", lw=0.5)
    axes[1].set_xlabel("position along the mark t [px]")
    axes[1].set_ylabel("residual [px]")
    axes[1].legend(loc="upper right")
    return tight(fig)


def fig_mark_thumb(r: MarkResult, image: np.ndarray):
    """A thumbnail of the mark in its image with the fitted line (for a table row)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(2.0, 1.4))
    _mark_on_image(ax, r, image, legend=False)
    fig.subplots_adjust(0, 0, 1, 1)
    return fig


def fig_mark_residuals(r: MarkResult):
    """The residuals across the mark in one panel: the straight line's (grey) and the loop's
    final model's (colour) with its ±1σ band — one plot per mark, the image being in its
    thumbnail. (A band, not an error bar per point: drawn in a tenth of the time.)"""
    plt = _plt()
    before, after = r.loop.before, r.loop.after
    fig, ax = plt.subplots(figsize=(8, 2.6))
    fig.subplots_adjust(left=0.09, right=0.99, bottom=0.18, top=0.9)  # tight_layout: 2x slower
    ax.plot(np.asarray(before.regressors["t"]), before.residuals, ".", ms=2, color="0.6",
            label=f"straight line: RMS {before.rms:.3f} px")
    t = np.asarray(after.regressors["t"])
    order = np.argsort(t)
    sigma = np.broadcast_to(np.asarray(after.sigma, float), t.shape)[order]
    ax.fill_between(t[order], -sigma, sigma, color="C1", alpha=0.2, lw=0, label="±1σ")
    names = ", ".join(e.name for e in r.loop.effects) or "no effect added"
    ax.plot(t, after.residuals, ".", ms=2, color="C1",
            label=f"after loop ({names}): RMS {after.rms:.3f} px")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("position along the mark t [px]")
    ax.set_ylabel("residual across mark [px]")
    ax.set_title(f"{Path(r.image).name} mark {r.index}: angle "
                 f"{np.rad2deg(r.angle_rad):+.6f}° ± {np.rad2deg(r.angle_u_rad) * 3600:.2f}″",
                 fontsize=9)
    ax.legend(loc="upper right", fontsize=7)
    return fig


def _mark_on_image(ax, r: MarkResult, image: np.ndarray, legend: bool = True) -> None:
    """Image (contrast-stretched) with the centres used and the fitted line drawn over it."""
    img = np.asarray(image, float)
    if img.ndim == 3:
        img = img.mean(2)
    h, w = img.shape
    lo, hi = np.percentile(img, (1, 99))
    ax.imshow(img, cmap="gray", vmin=lo, vmax=hi)
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    a = r.angle_rad
    n = np.array([np.sin(a), np.cos(a)])
    d = np.array([np.cos(a), -np.sin(a)])
    if r.measurement is not None:
        pts = r.measurement.points + c
        ax.plot(pts[:, 0], pts[:, 1], ".", ms=1.5, color="C1", label="centres used")
        s = (r.measurement.points - r.offset_px * n) @ d
        t0, t1 = float(s.min()), float(s.max())
    else:
        t0, t1 = -r.length_px / 2, r.length_px / 2
    p0 = c + r.offset_px * n
    ends = np.array([p0 + t0 * d, p0 + t1 * d])
    ax.plot(ends[:, 0], ends[:, 1], "-", lw=0.8, color="C3", label="fitted line")
    ax.set_xlim(0, w - 1)
    ax.set_ylim(h - 1, 0)
    if legend:
        ax.legend(loc="lower right", fontsize=7)
    ax.set_xticks([])
    ax.set_yticks([])


def plot_calibration(cal, poses, check, folder: Path) -> Path:
    return _write(fig_calibration(cal, poses, check), folder, "calibration")


def fig_calibration(cal, poses, check):
    """Δg per pose (calibration and check poses) and the residual against orientation."""

    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    dg0 = delta_g(cal.algebraic, poses) * 1e6
    dg1 = delta_g(cal.model, poses) * 1e6
    x = np.arange(len(dg0))
    ax[0].plot(x, dg0, "o", label="algebraic (paper)")
    ax[0].plot(x, dg1, "s", label="after ML + loop")
    if check is not None:
        xc = np.arange(len(dg0), len(dg0) + len(check.u))
        ax[0].plot(xc, delta_g(cal.model, check) * 1e6, "^", label="check poses")
    ax[0].axhline(0, color="k", lw=0.5)
    ax[0].set_xlabel("pose")
    ax[0].set_ylabel("|a| - 1 [µg]")
    ax[0].legend()
    a = cal.model.specific_force(poses.u, poses.t, poses.temp)
    d = a / np.linalg.norm(a, axis=1, keepdims=True)
    for i, axn in enumerate("xyz"):
        ax[1].plot(d[:, i], dg1, "o", label=f"vs a_{axn}")
    ax[1].set_xlabel("gravity direction component")
    ax[1].set_ylabel("residual |a| - 1 [µg]")
    ax[1].legend()
    return tight(fig)


def plot_gonio(counts: np.ndarray, fa, faces: list[str], folder: Path) -> Path:
    return _write(fig_gonio(counts, fa, faces), folder, "gonio")


def fig_gonio(counts: np.ndarray, fa, faces: list[str]):
    """Per-face angle against revolution, their Allan deviation, and the residual spectrum."""
    from scipy import signal

    plt = _plt()
    a = 2 * np.pi * counts / counts.sum(1, keepdims=True)
    dev = np.rad2deg(a - fa.angles_rad) * 3600
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    n = len(faces)
    for i in range(n):
        ax[0].plot(dev[:, i], ".", ms=2, label=f"{faces[i]}→{faces[(i + 1) % n]}")
    ax[0].set_xlabel("revolution")
    ax[0].set_ylabel("angle − mean [″]")
    ax[0].legend(fontsize=8)
    if fa.allan_tau_rev.size:
        for i in range(n):
            ax[1].loglog(fa.allan_tau_rev, np.rad2deg(fa.allan_dev_rad[:, i]) * 3600, "o-",
                         label=faces[i])
        tau = fa.allan_tau_rev
        ax[1].loglog(tau, np.rad2deg(fa.allan_dev_rad[0, 0]) * 3600 / np.sqrt(tau), "k:",
                     label="white (1/√τ)")
    ax[1].set_xlabel("averaging [revolutions]")
    ax[1].set_ylabel("Allan deviation [″]")
    ax[1].legend(fontsize=8)
    f, p = signal.periodogram(dev - dev.mean(0), axis=0)
    ax[2].semilogy(f[1:], p[1:], lw=0.7)
    ax[2].set_xlabel("frequency [cycles per revolution]")
    ax[2].set_ylabel("residual power [″² · rev]")
    return tight(fig)


def fig_fusion(rows) -> object:
    """Normalised residual of every fusion observation, coloured by source."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(11, 3.8))
    sources = list(dict.fromkeys(r.source for r in rows))
    for k, src in enumerate(sources):
        idx = [i for i, r in enumerate(rows) if r.source == src]
        ax.bar(idx, [rows[i].normalised for i in idx], color=f"C{k}", label=src)
    ax.axhline(2, color="k", lw=0.5, ls=":")
    ax.axhline(-2, color="k", lw=0.5, ls=":")
    ax.set_xticks(range(len(rows)))
    ax.set_xticklabels([r.label for r in rows], rotation=90, fontsize=6)
    ax.set_ylabel("(observed − fitted) / u")
    ax.legend(fontsize=8, ncol=len(sources))
    return tight(fig)
