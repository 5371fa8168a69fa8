"""Statistics of a lot: per angle the distribution over units, an individuals (I-MR) control
chart in run order, units outside its limits or the tolerance, process capability, and the
angle against each piece of session metadata that varies.

Model (Montgomery, *Introduction to Statistical Quality Control*, ch. 6.4 and 8): the units'
values x_1..x_n of one angle, in run order, are independent draws from one process while it
is in control. The moving ranges MR_k = |x_k − x_{k−1}| estimate its short-term spread,
σ_w = MR̄ / d2 with d2 = 1.128 (two-point ranges of a normal variable), so a drift or a step
does not inflate it the way the overall standard deviation would. The limits are
x̄ ± 3σ_w = x̄ ± 2.66·MR̄ for the values and D4·MR̄ = 3.267·MR̄ for the moving ranges.
Capability against a tolerance ±T (the nominal is 0: a perfectly aligned unit):
Cp = 2T / 6σ_w, Cpk = min(T − x̄, x̄ + T) / 3σ_w; Pp, Ppk the same with the overall σ.
Everything here is in radians; arc-seconds only at the edges (document, CSV, report).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from align.lot.duplicates import Duplicate, find_duplicates
from align.lot.read import ANGLE_NAMES, Rejected, UnitResult, when_of

D2 = 1.128
"""Mean range of two normal draws in units of σ (d2 for n = 2)."""
E2 = 3 / D2
"""Limits of the individuals chart: x̄ ± E2·MR̄ (E2 = 3/d2 = 2.66)."""
D4 = 3.267
"""Upper limit of the moving-range chart: D4·MR̄ (D4 for n = 2)."""
MR_DOF = 0.62
"""Effective degrees of freedom of σ_w = MR̄/d2, per unit, as a fraction of n − 1 (the
average moving range of n normal values carries about 0.62(n − 1) of the n − 1 dof of s:
Wheeler, *Advanced Topics in SPC*, table of effective dof)."""
FALSE_RATE = 0.0027
"""Probability that a normal value falls outside ±3σ: the chart's false-flag rate when the
process is in control."""
GUARD = 2.0
"""Coverage factor of the guard band: a unit within tolerance by less than GUARD·u is
'marginal' (conformance cannot be stated at ~95 % confidence, ISO 14253-1)."""
PROVISIONAL = 20
"""Fewer units than this: control limits are provisional (Montgomery's rule of thumb)."""
ALPHA_METADATA = 0.01
"""Family-wise significance of the metadata breakdown (Bonferroni over angles × keys)."""
ID_KEYS = ("unit", "serial", "name", "id")
"""Metadata keys that name the unit: never broken down."""
TIME_KEYS = ("datetime", "date")
"""Metadata keys of the measurement's date: broken down by calendar day."""


@dataclass(frozen=True)
class ControlChart:
    """Individuals (I-MR) chart of one angle in run order [rad].

    center : x̄; ``mr_bar``: mean moving range MR̄; ``sigma_within``: MR̄/d2;
    ``ucl``, ``lcl``: x̄ ± 2.66·MR̄; ``mr_ucl``: 3.267·MR̄; ``n``: number of values.
    """

    center: float
    mr_bar: float
    sigma_within: float
    ucl: float
    lcl: float
    mr_ucl: float
    n: int


@dataclass(frozen=True)
class Capability:
    """Process capability of one angle against ±T [T in rad].

    cp, cpk : with σ_w (short-term, from the moving range); ``cp_u``, ``cpk_u`` their
    standard uncertainties from the sampling of x̄ and σ_w with ``dof`` effective degrees of
    freedom (u(Cp) = Cp/√(2ν); u(Cpk) = √(1/(9n) + Cpk²/(2ν)), Bissell 1990, with ν for the
    moving-range σ); ``pp``, ``ppk``: with the overall σ; ``n``: the sample size.
    """

    tolerance: float
    cp: float
    cp_u: float
    cpk: float
    cpk_u: float
    pp: float
    ppk: float
    n: int
    dof: float


@dataclass(frozen=True)
class AngleStats:
    """One angle over the lot's units (those ok and fused, in run order) [rad].

    values : the angle per unit; ``units``: index of each value's unit in ``Lot.units``.
    n, mean, std (sample, ddof 1), median, min, max; ``median_u``: the units' median
    standard uncertainty. ``chart``: None with fewer than 2 values. ``outside_limits``,
    ``outside_tolerance``, ``marginal``: indices into ``Lot.units``. ``capability``: None
    without a tolerance or with fewer than 2 values.
    """

    name: str
    values: tuple[float, ...]
    units: tuple[int, ...]
    n: int
    mean: float
    std: float
    median: float
    min: float
    max: float
    median_u: float
    chart: ControlChart | None
    outside_limits: tuple[int, ...]
    outside_tolerance: tuple[int, ...]
    marginal: tuple[int, ...]
    capability: Capability | None


@dataclass(frozen=True)
class GroupStats:
    """The units sharing one value of a metadata key: n, mean and std of each angle [rad]."""

    value: str
    n: int
    mean: tuple[float, ...]
    std: tuple[float, ...]


@dataclass(frozen=True)
class MetadataEffect:
    """One metadata key that varies over the lot, each angle against it.

    groups : per value of the key; ``p_values``: Kruskal–Wallis test (rank-based, so one
    outlier does not make a group differ) of equal distributions per angle (None where fewer
    than 2 groups hold 2 or more units); ``differs``: p below ``ALPHA_METADATA`` divided by
    the number of tests; ``by_day``: a date key grouped by calendar day.
    """

    key: str
    groups: tuple[GroupStats, ...]
    p_values: tuple[float | None, ...]
    differs: tuple[bool, ...]
    threshold: float
    by_day: bool = False


@dataclass(frozen=True)
class Lot:
    """A lot: its units in run order, the files rejected, and the statistics.

    run_order : "date" (metadata date/time of every unit) or "given" (the order of the
    files); ``run_order_note`` says why. ``in_stats``: indices of the units used in the
    statistics (ok and fused). ``metadata_skipped``: keys not broken down, with why.
    """

    units: tuple[UnitResult, ...]
    rejected: tuple[Rejected, ...]
    run_order: str
    run_order_note: str
    tolerance: float | None
    in_stats: tuple[int, ...]
    angles: tuple[AngleStats, ...]
    metadata: tuple[MetadataEffect, ...]
    metadata_skipped: tuple[tuple[str, str], ...]
    duplicates: tuple[Duplicate, ...] = ()

    @property
    def left_out(self) -> dict[int, int]:
        """Results of a unit counted in another result: index -> index of the one used."""
        return {k: d.used for d in self.duplicates for k in d.left_out}

    @property
    def not_ok(self) -> tuple[int, ...]:
        """Units not in the statistics: result not ok (failed stages) or not fused (a unit's
        result left out for another of the same unit is not among them: see
        ``duplicates``)."""
        used = set(self.in_stats) | set(self.left_out)
        return tuple(k for k in range(len(self.units)) if k not in used)

    @property
    def ok(self) -> bool:
        """Every file was a readable session result and every unit's result is ok."""
        return not self.rejected and not self.not_ok

    @property
    def flagged(self) -> dict[int, list[str]]:
        """unit index -> what flags it ('E_xY outside control limits', ...)."""
        out: dict[int, list[str]] = {}
        for a in self.angles:
            for k in a.outside_limits:
                out.setdefault(k, []).append(f"{a.name} outside control limits")
            for k in a.outside_tolerance:
                out.setdefault(k, []).append(f"{a.name} outside tolerance")
            for k in a.marginal:
                out.setdefault(k, []).append(f"{a.name} marginal (within tolerance by less "
                                             f"than {GUARD:g}u)")
        return out

    @property
    def in_control(self) -> bool:
        return not any(a.outside_limits for a in self.angles)

    @property
    def within_tolerance(self) -> bool | None:
        if self.tolerance is None:
            return None
        return not any(a.outside_tolerance for a in self.angles)


def control_chart(x: Sequence[float]) -> ControlChart | None:
    """The I-MR chart of ``x`` in run order (None with fewer than 2 values)."""
    x = np.asarray(x, float)
    if x.size < 2:
        return None
    mr_bar = float(np.mean(np.abs(np.diff(x))))
    c = float(np.mean(x))
    return ControlChart(c, mr_bar, mr_bar / D2, c + E2 * mr_bar, c - E2 * mr_bar,
                        D4 * mr_bar, int(x.size))


def capability(x: Sequence[float], chart: ControlChart, tolerance: float) -> Capability:
    """Cp, Cpk (σ_w) and Pp, Ppk (overall σ) of ``x`` against ±``tolerance``."""
    x = np.asarray(x, float)
    n = x.size
    t = float(tolerance)
    sw = chart.sigma_within
    s = float(np.std(x, ddof=1))
    m = chart.center
    near = min(t - m, m + t)
    inf = math.inf
    cp = 2 * t / (6 * sw) if sw > 0 else inf
    cpk = near / (3 * sw) if sw > 0 else (inf if near > 0 else -inf)
    pp = 2 * t / (6 * s) if s > 0 else inf
    ppk = near / (3 * s) if s > 0 else (inf if near > 0 else -inf)
    nu = MR_DOF * (n - 1)
    cp_u = cp / math.sqrt(2 * nu) if math.isfinite(cp) else math.nan
    cpk_u = (math.sqrt(1 / (9 * n) + cpk ** 2 / (2 * nu)) if math.isfinite(cpk)
             else math.nan)
    return Capability(t, cp, cp_u, cpk, cpk_u, pp, ppk, int(n), nu)


def angle_stats(name: str, x: Sequence[float], u: Sequence[float], units: Sequence[int],
                tolerance: float | None) -> AngleStats:
    """Statistics of one angle; ``x`` and ``u`` [rad] in run order, ``units`` their unit
    indices."""
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    idx = np.asarray(units, int)
    n = int(x.size)
    chart = control_chart(x)
    out_lim: tuple[int, ...] = ()
    if chart is not None and chart.mr_bar > 0:
        out_lim = tuple(int(k) for k in idx[(x > chart.ucl) | (x < chart.lcl)])
    out_tol: tuple[int, ...] = ()
    marginal: tuple[int, ...] = ()
    cap = None
    if tolerance is not None:
        ax = np.abs(x)
        out_tol = tuple(int(k) for k in idx[ax > tolerance])
        marginal = tuple(int(k) for k in idx[(ax <= tolerance) & (ax + GUARD * u > tolerance)])
        if chart is not None:
            cap = capability(x, chart, tolerance)
    nan = math.nan

    def stat(f) -> float:
        return float(f(x)) if n else nan

    return AngleStats(name, tuple(map(float, x)), tuple(map(int, idx)), n, stat(np.mean),
                      float(np.std(x, ddof=1)) if n > 1 else nan, stat(np.median),
                      stat(np.min), stat(np.max), float(np.median(u)) if n else nan, chart,
                      out_lim, out_tol, marginal, cap)


def _run_order(units: Sequence[UnitResult]) -> tuple[list[int], str, str]:
    """Indices in run order: by metadata date/time when every unit has one, else as given."""
    whens = [u.when for u in units]
    if units and all(w is not None for w in whens):
        # sorted() is stable: units measured at the same time keep the order given.
        order = sorted(range(len(units)), key=lambda k: whens[k])  # type: ignore[arg-type,return-value]
        return order, "date", "by the sessions' date/time metadata"
    have = sum(w is not None for w in whens)
    note = ("in the order given (no session has date/time metadata)" if have == 0 else
            f"in the order given ({len(units) - have} of {len(units)} sessions have no "
            "readable date/time metadata)")
    return list(range(len(units))), "given", note


def _day(v: object) -> str | None:
    w = when_of({"date": v}) if isinstance(v, str) else None
    return None if w is None else w.date().isoformat()


def kruskal_p(samples: Sequence[np.ndarray]) -> float:
    """p-value of the Kruskal–Wallis H test that the samples share one distribution (ranks
    averaged over ties, H corrected for them, χ² with k − 1 dof).

    Written here rather than ``scipy.stats.kruskal`` because importing ``scipy.stats``
    costs 1–2 s, a large part of reporting a lot of 10⁴ results; the tests check it against
    scipy."""
    from scipy.special import chdtrc

    x = np.concatenate(samples)
    n = x.size
    order = np.argsort(x, kind="mergesort")
    xs = x[order]
    # average ranks of tied values: each run of equal values gets the mean of its positions
    starts = np.flatnonzero(np.r_[True, xs[1:] != xs[:-1]])
    counts = np.diff(np.r_[starts, n])
    mean_rank = starts + (counts + 1) / 2.0
    ranks = np.empty(n)
    ranks[order] = np.repeat(mean_rank, counts)
    h = 0.0
    k0 = 0
    for s in samples:
        r = ranks[k0:k0 + s.size]
        h += r.sum() ** 2 / s.size
        k0 += s.size
    h = 12.0 / (n * (n + 1)) * h - 3.0 * (n + 1)
    ties = 1.0 - float(np.sum(counts ** 3 - counts)) / (n ** 3 - n)
    if ties <= 0:
        return 1.0  # every value equal: no evidence of any difference
    return float(chdtrc(len(samples) - 1, h / ties))


def metadata_effects(units: Sequence[UnitResult], in_stats: Sequence[int]
                     ) -> tuple[list[MetadataEffect], list[tuple[str, str]]]:
    """Each angle against each metadata key that varies over the units in the statistics."""
    used = [units[k] for k in in_stats]
    keys = sorted({k for u in used for k in u.metadata})
    candidates: list[tuple[str, list[str], bool]] = []
    skipped: list[tuple[str, str]] = []
    for key in keys:
        if key.lower() in ID_KEYS:
            skipped.append((key, "names the unit"))
            continue
        if key.lower() == "time":
            skipped.append((key, "time of day (the run order uses it)"))
            continue
        by_day = key.lower() in TIME_KEYS
        vals = []
        for u in used:
            v = u.metadata.get(key)
            if by_day:
                d = _day(v)
                vals.append(d if d is not None else "(missing)" if v is None else str(v))
            else:
                vals.append("(missing)" if v is None else str(v))
        distinct = set(vals)
        if len(distinct) < 2:
            skipped.append((key, f"the same for every unit ({vals[0]})" if vals else "unused"))
            continue
        if len(distinct) == len(vals):
            skipped.append((key, "different for every unit: no groups to compare"))
            continue
        candidates.append((key, vals, by_day))
    tests = sum(1 for _ in candidates) * len(ANGLE_NAMES)
    threshold = ALPHA_METADATA / max(tests, 1)
    effects = []
    for key, vals, by_day in candidates:
        names = sorted(set(vals))
        groups = []
        p_values: list[float | None] = []
        members: dict[str, list[int]] = {g: [] for g in names}
        for i, v in enumerate(vals):
            members[v].append(i)
        e = np.array([u.e_rad for u in used], float)
        for g in names:
            sel = e[members[g]]
            groups.append(GroupStats(g, len(sel), tuple(map(float, sel.mean(axis=0))),
                                     tuple(map(float, sel.std(axis=0, ddof=1)))
                                     if len(sel) > 1 else (math.nan,) * len(ANGLE_NAMES)))
        big = [members[g] for g in names if len(members[g]) >= 2]
        for a in range(len(ANGLE_NAMES)):
            samples = [e[m, a] for m in big]
            if len(samples) < 2 or np.ptp(e[:, a]) == 0:
                p_values.append(None)
                continue
            p_values.append(kruskal_p(samples))
        effects.append(MetadataEffect(
            key, tuple(groups), tuple(p_values),
            tuple(p is not None and p < threshold for p in p_values), threshold, by_day))
    return effects, skipped


def analyse(units: Sequence[UnitResult], rejected: Sequence[Rejected] = (),
            tolerance: float | None = None) -> Lot:
    """The lot's statistics. ``units`` in the order given; ``tolerance`` ±T [rad] or None.

    Only units whose result is ok enter the statistics, each unit once (a unit in several
    results: :mod:`align.lot.duplicates` chooses one, ``Lot.duplicates`` says which); the
    others are kept in ``Lot.units`` (and listed by the report) with their failed stages."""
    if tolerance is not None and not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance {tolerance!r}: expected a positive number [rad]")
    order, how, note = _run_order(units)
    ordered = tuple(units[k] for k in order)
    # One unit, one value: a unit in several results is counted once (align.lot.duplicates).
    dups = find_duplicates(ordered)
    left = {k for d in dups for k in d.left_out}
    in_stats = tuple(k for k, u in enumerate(ordered) if u.ok and u.fused and k not in left
                     and u.e_rad is not None and u.u_rad is not None)
    e = np.array([ordered[k].e_rad for k in in_stats], float).reshape(-1, len(ANGLE_NAMES))
    u = np.array([ordered[k].u_rad for k in in_stats], float).reshape(-1, len(ANGLE_NAMES))
    angles = tuple(angle_stats(name, e[:, a], u[:, a], in_stats, tolerance)
                   for a, name in enumerate(ANGLE_NAMES))
    effects, skipped = metadata_effects(ordered, in_stats) if in_stats else ([], [])
    return Lot(ordered, tuple(rejected), how, note, tolerance, in_stats, angles,
               tuple(effects), tuple(skipped), dups)
