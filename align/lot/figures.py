"""Figures of a lot (matplotlib, object API: no pyplot state), as PNG bytes for the report.

Angles are drawn in arc-seconds (the edge); the statistics they show are in
:mod:`align.lot.stats`.
"""

from __future__ import annotations

import io
import math

import numpy as np

from align.lot.read import ANGLE_NAMES
from align.lot.stats import AngleStats, Lot, MetadataEffect, _day
from axisbase.units import ARCSEC

DENSE = 2000
"""Above this many units a control chart shows pixels, not joined markers (a line through
10⁴ points is a smear, and drawing it is most of the chart's cost)."""
SCATTER_MAX = 5000
"""Points drawn one by one in the metadata figures up to this many units."""


def _figure(w: float, h: float):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    # Margins set by hand: the constrained layout engine takes 2-3 times as long as the
    # drawing itself, and a lot report has 10+ figures.
    return Figure(figsize=(w, h))


def png(fig, dpi: int = 80) -> bytes:
    """The figure as PNG bytes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def fig_distributions(lot: Lot):
    """Histogram of each angle over the units, with x̄, ±3σ_w and the tolerance."""
    fig = _figure(11, 5.2)
    axes = fig.subplots(2, 3)
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.1, top=0.94, wspace=0.22, hspace=0.42)
    for ax, a in zip(axes.ravel(), lot.angles, strict=True):
        x = np.asarray(a.values) / ARCSEC
        if x.size:
            ax.hist(x, bins=min(60, max(5, int(np.sqrt(x.size)))), color="#5a7fb0")
            ax.axvline(a.mean / ARCSEC, color="k", lw=1)
        if a.chart is not None:
            for v in (a.chart.lcl, a.chart.ucl):
                ax.axvline(v / ARCSEC, color="#d08000", ls="--", lw=1)
        if lot.tolerance is not None:
            for v in (-lot.tolerance, lot.tolerance):
                ax.axvline(v / ARCSEC, color="#c00000", lw=1.2)
        ax.set_title(f"{a.name} (n = {a.n})", fontsize=10)
        ax.set_xlabel("arc-seconds")
    return fig


def fig_control_chart(a: AngleStats, lot: Lot):
    """Individuals and moving-range charts of one angle in run order; points outside the
    limits or the tolerance in red."""
    fig = _figure(11, 5.6)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=[2.2, 1])
    # room under the axis for the units' names (serial and date, vertical)
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.27, top=0.98, hspace=0.08)
    x = np.asarray(a.values) / ARCSEC
    k = np.arange(x.size)
    dense = x.size > DENSE
    if not dense:
        top.plot(k, x, "-", color="#9ab", lw=0.6, zorder=1)
    top.plot(k, x, "," if dense else ".", color="#246", ms=4, zorder=2)
    bad = np.isin(a.units, a.outside_limits + a.outside_tolerance)
    if bad.any():
        top.plot(k[bad], x[bad], "o", mfc="none", mec="#d00000", ms=8, zorder=3,
                 label="flagged")
    c = a.chart
    if c is not None:
        top.axhline(c.center / ARCSEC, color="k", lw=1, label=f"x̄ {c.center / ARCSEC:+.2f}″")
        top.axhline(c.ucl / ARCSEC, color="#d08000", ls="--", lw=1,
                    label=f"x̄ ± 2.66·MR̄ ({c.lcl / ARCSEC:+.2f}, {c.ucl / ARCSEC:+.2f}″)")
        top.axhline(c.lcl / ARCSEC, color="#d08000", ls="--", lw=1)
        mr = np.abs(np.diff(x))
        bottom.plot(k[1:], mr, "," if dense else ".-", color="#246", lw=0.5, ms=3)
        bottom.axhline(c.mr_bar / ARCSEC, color="k", lw=1)
        bottom.axhline(c.mr_ucl / ARCSEC, color="#d08000", ls="--", lw=1)
    if lot.tolerance is not None:
        t = lot.tolerance / ARCSEC
        top.axhline(t, color="#c00000", lw=1.2, label=f"tolerance ±{t:g}″")
        top.axhline(-t, color="#c00000", lw=1.2)
    top.set_ylabel(f"{a.name} [″]")
    top.legend(fontsize=8, loc="upper left", ncols=4)
    bottom.set_ylabel("MR [″]")
    bottom.set_xlabel(f"unit in run order ({lot.run_order_note})")
    _unit_ticks(bottom, [lot.units[j] for j in a.units])
    return fig


UNIT_TICKS = 40
"""Units named under a control chart at most (every n-th beyond)."""


def _unit_ticks(ax, units) -> None:
    """Name the units on the run-order axis: serial (and date), not 0…n−1."""
    if not units:
        return
    step = max(1, math.ceil(len(units) / UNIT_TICKS))
    idx = list(range(0, len(units), step))

    def name(u) -> str:
        w = u.when
        return u.label if w is None else f"{u.label} {w.date().isoformat()}"
    ax.set_xticks(idx, [name(units[i]) for i in idx], rotation=90, fontsize=6)


def fig_metadata(m: MetadataEffect, lot: Lot):
    """Each angle against one metadata key: the units of each group (jittered) and the
    group's mean ± 2 standard errors."""
    fig = _figure(11, 5.2)
    axes = fig.subplots(2, 3)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.13, top=0.9, wspace=0.28, hspace=0.55)
    used = [lot.units[k] for k in lot.in_stats]
    values = []
    for u in used:
        v = u.metadata.get(m.key)
        if m.by_day:

            d = _day(v)
            v = d if d is not None else v
        values.append("(missing)" if v is None else str(v))
    names = [g.value for g in m.groups]
    pos = {g: i for i, g in enumerate(names)}
    xs = np.array([pos[v] for v in values], float)
    rng = np.random.default_rng(0)  # jitter only: a fixed seed keeps the figure reproducible
    jitter = rng.uniform(-0.18, 0.18, xs.size)
    for a, ax in enumerate(axes.ravel()):
        y = np.array([u.e_rad[a] for u in used]) / ARCSEC
        if y.size <= SCATTER_MAX:
            ax.plot(xs + jitter, y, ".", color="#8aa", ms=3)
        means = np.array([g.mean[a] for g in m.groups]) / ARCSEC
        se = np.array([g.std[a] / np.sqrt(g.n) if g.n > 1 else np.nan
                       for g in m.groups]) / ARCSEC
        ax.errorbar(np.arange(len(names)), means, yerr=2 * se, fmt="o", color="#b03000",
                    capsize=3, ms=4)
        p = m.p_values[a]
        ax.set_title(f"{ANGLE_NAMES[a]}" + ("" if p is None else f"  p = {p:.2g}")
                     + ("  DIFFERS" if m.differs[a] else ""), fontsize=10,
                     color="#c00000" if m.differs[a] else "k")
        # At most ~12 labelled ticks: hundreds of days would cost seconds and be unreadable.
        step = max(1, math.ceil(len(names) / 12))
        ticks = np.arange(0, len(names), step)
        ax.set_xticks(ticks, [names[i] for i in ticks], rotation=30, fontsize=7, ha="right")
        ax.set_ylabel("arc-seconds")
    fig.suptitle(f"each angle against {m.key}" + (" (by day)" if m.by_day else ""),
                 fontsize=11)
    return fig
