"""What ``align lot`` writes: its warnings, the lot JSON (format ``axis-align/lot``, in the
envelope of :mod:`align.contract`), the CSV of one row per unit, and writing them all (each
atomically, none lost). Angles are converted to arc-seconds here, at the edge."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

from align.contract import document
from align.decision import ToleranceSpec
from align.lot.dispose import dispositions
from align.lot.duplicates import Duplicate, spelling_warnings
from align.lot.read import ANGLE_NAMES, ReadFile
from align.lot.report import write_lot_report
from align.lot.stats import GUARD, PROVISIONAL, AngleStats, Lot
from axisbase.output import write_atomic, write_json
from axisbase.provenance import InputFile, Provenance
from axisbase.units import ARCSEC

MAX_LINES = 20
"""Warnings of one kind listed one by one; the rest are counted (all are in the JSON)."""
CPK_MIN = 1.33
"""Cpk below this is warned about (the usual requirement for an established process)."""


def _capped(lines: list[str], what: str, code: str) -> list[tuple[str, str]]:
    out = [(code, x) for x in lines[:MAX_LINES]]
    if len(lines) > MAX_LINES:
        out.append((code, f"... and {len(lines) - MAX_LINES} more {what} (all listed in "
                          "the JSON and the CSV)"))
    return out


def _as(v: float) -> str:
    return f"{v / ARCSEC:+.2f}″"


def lot_warnings(lot: Lot) -> list[str]:
    """What a reader of the lot must know first: files not read, units not ok or not in the
    statistics, units outside the control limits or the tolerance, capability below
    1.33, angles that differ with the metadata, provisional limits (each with its code:
    :func:`lot_warning_items`)."""
    return [text for _, text in lot_warning_items(lot)]


def lot_warning_items(lot: Lot) -> list[tuple[str, str]]:
    """(code, text) of each of :func:`lot_warnings` (the codes:
    :data:`align.lot.disposition.WARNING_CODES`)."""
    out = _capped([f"{r.file}: not read: {r.reason}" for r in lot.rejected], "files not read",
                  "not_read")
    out += _capped(spelling_warnings(lot.units), "serials written several ways", "spelling")
    out += _capped([duplicate_line(d, lot) for d in lot.duplicates], "units in several results",
                   "duplicate")
    out += _capped([f"unit {u.label} ({u.file}): result NOT ok or not fused ("
                    + ("; ".join(f"stage {s} failed: {m}" for s, m in u.failed_stages)
                       or ("not fused" if not u.fused else "see its warnings"))
                    + "): not in the statistics" for u in (lot.units[k] for k in lot.not_ok)],
                   "units not ok", "not_ok")
    if not lot.in_stats:
        out.append(("no_statistics", "no unit is ok and fused: no statistics"))
        return out
    n = len(lot.in_stats)
    if n < PROVISIONAL:
        out.append(("provisional", f"only {n} units in the statistics: control limits are "
                    f"provisional (at least {PROVISIONAL} are usually needed)"))
    limits, tolerance = [], []
    for a in lot.angles:
        c = a.chart
        for k in a.outside_limits:
            u = lot.units[k]
            v = a.values[a.units.index(k)]
            limits.append(f"unit {u.label}: {a.name} = {_as(v)} outside the control limits "
                          f"{_as(c.lcl)} … {_as(c.ucl)}")
        for k in a.outside_tolerance:
            u = lot.units[k]
            v = a.values[a.units.index(k)]
            tolerance.append(f"unit {u.label}: {a.name} = {_as(v)} outside the tolerance "
                             f"±{lot.tolerance / ARCSEC:g}″")
    out += _capped(limits, "control-limit flags", "control_limits")
    out += _capped(tolerance, "units outside the tolerance", "outside_tolerance")
    for a in lot.angles:
        cap = a.capability
        if cap is not None and math.isfinite(cap.cpk) and cap.cpk < CPK_MIN:
            out.append(("not_capable", f"{a.name}: Cpk {cap.cpk:.2f} ± {cap.cpk_u:.2f} "
                        f"(n = {cap.n}) below {CPK_MIN}: the process is not capable of "
                        f"±{lot.tolerance / ARCSEC:g}″"))
    for m in lot.metadata:
        for name, p, d in zip(ANGLE_NAMES, m.p_values, m.differs, strict=True):
            if d:
                out.append(("differs_with_metadata", f"{name} differs with {m.key}"
                            + (" (by day)" if m.by_day else "")
                            + f" (Kruskal–Wallis p = {p:.2g} < {m.threshold:.2g})"))
    return out


def duplicate_line(d: Duplicate, lot: Lot) -> str:
    """One line for a unit found in several results: which is counted, which are not."""
    used = lot.units[d.used]
    others = "; ".join(f"{lot.units[k].file} left out ({r})"
                       for k, r in zip(d.left_out, d.relations, strict=True))
    return (f"unit {d.label} is in {len(d.left_out) + 1} results: counted once, {used.file} "
            f"used ({d.why}); {others}")


def _angle_dict(a: AngleStats, lot: Lot) -> dict:
    def arc(v: float) -> float:
        return v / ARCSEC

    c, cap = a.chart, a.capability
    labels = [lot.units[k].label for k in a.units]
    return {
        "name": a.name, "n": a.n, "mean_arcsec": arc(a.mean), "std_arcsec": arc(a.std),
        "median_arcsec": arc(a.median), "min_arcsec": arc(a.min), "max_arcsec": arc(a.max),
        "median_u_arcsec": arc(a.median_u),
        "control_chart": None if c is None else {
            "center_arcsec": arc(c.center), "mr_bar_arcsec": arc(c.mr_bar),
            "sigma_within_arcsec": arc(c.sigma_within), "ucl_arcsec": arc(c.ucl),
            "lcl_arcsec": arc(c.lcl), "mr_ucl_arcsec": arc(c.mr_ucl), "n": c.n,
            "provisional": c.n < PROVISIONAL},
        "outside_limits": [labels[a.units.index(k)] for k in a.outside_limits],
        "outside_tolerance": [labels[a.units.index(k)] for k in a.outside_tolerance],
        "marginal": [labels[a.units.index(k)] for k in a.marginal],
        "capability": None if cap is None else {
            "tolerance_arcsec": arc(cap.tolerance), "cp": cap.cp, "cp_u": cap.cp_u,
            "cpk": cap.cpk, "cpk_u": cap.cpk_u, "pp": cap.pp, "ppk": cap.ppk, "n": cap.n,
            "dof": cap.dof},
    }


def lot_body(lot: Lot) -> dict:
    """The lot's JSON body (without the envelope)."""
    flagged = lot.flagged
    in_stats = set(lot.in_stats)
    run_index = {k: i for i, k in enumerate(lot.in_stats)}
    left_out = lot.left_out
    units = []
    for k, u in enumerate(lot.units):
        d = u.to_dict()
        d.update({"in_statistics": k in in_stats, "run_index": run_index.get(k),
                  "flags": flagged.get(k, []),
                  "counted_as": lot.units[left_out[k]].file if k in left_out else None})
        units.append(d)
    items = lot_warning_items(lot)
    return {
        "ok": lot.ok, "in_control": lot.in_control, "within_tolerance": lot.within_tolerance,
        "warnings": [t for _, t in items], "warning_codes": [c for c, _ in items],
        "run_order": lot.run_order,
        "run_order_note": lot.run_order_note,
        "tolerance_arcsec": None if lot.tolerance is None else lot.tolerance / ARCSEC,
        "guard_band_k": GUARD, "n_units": len(lot.units), "n_in_statistics": len(in_stats),
        "angle_names": list(ANGLE_NAMES),
        "angles": [_angle_dict(a, lot) for a in lot.angles],
        "metadata": [{"key": m.key, "by_day": m.by_day, "threshold": m.threshold,
                      "groups": [{"value": g.value, "n": g.n,
                                  "mean_arcsec": [v / ARCSEC for v in g.mean],
                                  "std_arcsec": [v / ARCSEC for v in g.std]}
                                 for g in m.groups],
                      "p_values": list(m.p_values), "differs": list(m.differs)}
                     for m in lot.metadata],
        "metadata_not_compared": [{"key": k, "why": w} for k, w in lot.metadata_skipped],
        "units": units,
        "duplicates": [d.to_dict(lot.units) for d in lot.duplicates],
        "rejected": [r.to_dict() for r in lot.rejected],
    }


def lot_document(lot: Lot, read: Sequence[ReadFile], settings: Mapping) -> dict:
    """:func:`lot_body` in its envelope; the inputs' SHA-256 are those computed while
    reading (each file is read once)."""
    prov = Provenance(settings=dict(settings),
                      inputs=tuple(InputFile(str(r.path), r.sha256, r.size) for r in read))
    return document("lot", lot_body(lot), settings, prov=prov)


def lot_csv(lot: Lot) -> str:
    """One row per unit in run order: identity, ok, E ± u per angle [″], χ², flags,
    failed stages, metadata (one column per key)."""
    keys = sorted({k for u in lot.units for k in u.metadata})
    head = (["run_index", "unit", "session", "file", "ok", "fused", "in_statistics",
             "counted_as"]
            + [c for n in ANGLE_NAMES for c in (f"{n}_arcsec", f"{n}_u_arcsec")]
            + ["chi2", "dof", "p_value", "n_warnings", "flags", "failed_stages"]
            + [f"meta_{k}" for k in keys])
    flagged = lot.flagged
    run_index = {k: i for i, k in enumerate(lot.in_stats)}
    left_out = lot.left_out
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)

    def num(v: float | None, fmt: str = "{:.4f}") -> str:
        return "" if v is None or not math.isfinite(v) else fmt.format(v)

    for k, u in enumerate(lot.units):
        e = u.e_rad or (None,) * 6
        s = u.u_rad or (None,) * 6
        ang = [c for v, uu in zip(e, s, strict=True)
               for c in (num(None if v is None else v / ARCSEC),
                         num(None if uu is None else uu / ARCSEC))]
        w.writerow([run_index.get(k, ""), u.label, u.session, u.file, u.ok, u.fused,
                    k in run_index, lot.units[left_out[k]].file if k in left_out else ""]
                   + ang
                   + [num(u.chi2, "{:.3f}"), "" if u.dof is None else u.dof,
                      num(u.p_value, "{:.3g}"), len(u.warnings), "; ".join(flagged.get(k, [])),
                      "; ".join(f"{st}: {m}" for st, m in u.failed_stages)]
                   + [u.metadata.get(key, "") for key in keys])
    return buf.getvalue()


def lot_outputs(lot: Lot, read: Sequence[ReadFile], outs: Mapping[str, Path | None],
                force: bool, settings: Mapping, spec: ToleranceSpec | None = None,
                flags: Mapping | None = None) -> tuple[dict[str, Path], dict]:
    """Write the outputs asked for (``json``, ``csv``, ``report``: checked paths or None);
    returns what was written and the lot JSON. ``spec``: the tolerance and decision rule
    every unit is judged against (None: each unit's own, :mod:`align.lot.dispose`); ``flags``:
    the decision flags given, applied over each unit's own tolerance."""
    doc = lot_document(lot, read, settings)
    doc["dispositions"] = dispositions(lot.units, spec, flags)
    written: dict[str, Path] = {}
    if outs.get("json") is not None:
        written["json"] = write_json(outs["json"], doc, force)
    if outs.get("csv") is not None:
        written["csv"] = write_atomic(outs["csv"], lot_csv(lot), force)
    if outs.get("report") is not None:

        written["report"] = write_lot_report(lot, outs["report"], doc, force)
    return written, doc
