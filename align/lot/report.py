"""One self-contained HTML page of a lot (figures embedded as PNG data URIs, no scripts, no
external resources): warnings first, then per angle the summary, distribution, control chart
and capability, the metadata breakdown, and every unit.

The small HTML helpers are repeated from :mod:`align.session.report` rather than imported:
that module imports the whole session pipeline (seconds of start-up), and a lot of 10⁴
results must be reported in a few seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

from align.html import esc, png_img, table
from align.lot.figures import fig_control_chart, fig_distributions, fig_metadata, png
from align.lot.read import ANGLE_NAMES
from align.lot.stats import FALSE_RATE, GUARD, Lot
from axisbase.output import write_atomic
from axisbase.provenance import Provenance
from axisbase.units import ARCSEC

CSS = """body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}.bad{color:#b00;font-weight:bold}
.ok{color:#070}img{max-width:100%}h2{border-bottom:2px solid #446;margin-top:1.6em}
div.warn{border:2px solid #b00;padding:0 1em;background:#fff4f4}"""

UNIT_ROWS_MAX = 20000
"""Units listed one by one in the page (the CSV and JSON always list them all)."""


def _img(fig, alt: str) -> str:
    return png_img(png(fig), alt)


def _a(v: float | None, fmt: str = "{:+.2f}") -> str:
    return "—" if v is None or not math.isfinite(v) else fmt.format(v / ARCSEC)


def _n(v: float | None, fmt: str = "{:.2f}") -> str:
    return "—" if v is None or not math.isfinite(v) else fmt.format(v)


def _provenance(doc: dict) -> str:
    p = Provenance.from_dict(doc)
    return (f"<p>{esc(p.tool)} {esc(p.tool_version)}, {esc(doc['format'])} format version "
            f"{doc['format_version']}, written {esc(p.created_utc)} (UTC) by "
            f"<code>{esc(' '.join(p.command[:12]))}"
            f"{' …' if len(p.command) > 12 else ''}</code>; {len(p.inputs)} input files "
            "(their SHA-256 are in the JSON's inputs).</p>")


def _summary(lot: Lot) -> str:
    head = ["angle", "n", "mean [″]", "std [″]", "σ_w = MR̄/1.128 [″]", "median u [″]",
            "LCL [″]", "UCL [″]", "outside limits", "by chance"]
    if lot.tolerance is not None:
        head += ["outside ±T", f"marginal (< {GUARD:g}u)", "Cp ± u", "Cpk ± u", "Pp", "Ppk"]
    rows = []
    for a in lot.angles:
        c = a.chart
        r = [a.name, a.n, _a(a.mean), _a(a.std, "{:.2f}"),
             _a(None if c is None else c.sigma_within, "{:.2f}"), _a(a.median_u, "{:.2f}"),
             _a(None if c is None else c.lcl), _a(None if c is None else c.ucl),
             len(a.outside_limits), f"{FALSE_RATE * a.n:.1f}"]
        if lot.tolerance is not None:
            cap = a.capability
            r += [len(a.outside_tolerance), len(a.marginal),
                  "—" if cap is None else f"{_n(cap.cp)} ± {_n(cap.cp_u)}",
                  "—" if cap is None else f"{_n(cap.cpk)} ± {_n(cap.cpk_u)}",
                  "—" if cap is None else _n(cap.pp), "—" if cap is None else _n(cap.ppk)]
        rows.append(r)
    out = table(head, rows)
    out += ("<p>Control limits x̄ ± 2.66·MR̄ from the average moving range of consecutive "
            "units (individuals chart): a drift or a step inflates them less than the overall "
            "standard deviation would. 'By chance': the number expected outside them in a "
            f"process in control ({FALSE_RATE:.2%} of the units, normal values): a few flags in "
            "a large lot are expected, and each is a unit to look at, not proof of a fault. ")
    if lot.tolerance is not None:
        n = len(lot.in_stats)
        out += (f"Capability against ±{lot.tolerance / ARCSEC:g}″ (nominal 0): Cp, Cpk from "
                "σ_w, Pp, Ppk from the overall standard deviation; the ± is the standard "
                f"uncertainty from the sample of n = {n} units (σ_w carries about "
                "0.62(n − 1) degrees of freedom; Bissell's approximation for Cpk). A unit is "
                f"marginal when it is within the tolerance by less than {GUARD:g} times its "
                "own standard uncertainty: its conformance cannot be stated.")
    else:
        out += "No tolerance given (--tolerance-arcsec): no capability, no tolerance flags."
    out += "</p>"
    ratios = [(a.name, a.median_u / a.chart.sigma_within) for a in lot.angles
              if a.chart is not None and a.chart.sigma_within > 0]
    big = [f"{n} ({r:.2f})" for n, r in ratios if r > 1 / 3]
    if big:
        out += ("<p>The units' own uncertainty is a large part of the lot's spread "
                "(median u / σ_w above 1/3) for " + esc(", ".join(big))
                + ": part of what the charts show is measurement, not process.</p>")
    return out


def _flagged(lot: Lot) -> str:
    flagged = lot.flagged
    if not flagged:
        return '<p class="ok">No unit outside the control limits' + (
            " or the tolerance" if lot.tolerance is not None else "") + ".</p>"
    rows = []
    idx = {k: i for i, k in enumerate(lot.in_stats)}
    for k in sorted(flagged, key=lambda k: idx.get(k, -1)):
        u = lot.units[k]
        rows.append([u.label, idx.get(k, "—"), u.file, "; ".join(flagged[k])])
    return table(["unit", "run index", "file", "why"], rows, left=4)


def _metadata(lot: Lot) -> str:
    parts = ["<h2>Each angle against the session metadata</h2>"]
    if not lot.metadata:
        parts.append("<p>No metadata key varies over the units in groups that can be "
                     "compared" + ("" if lot.metadata_skipped else
                                   " (the results carry no [metadata])") + ".</p>")
    for m in lot.metadata:
        parts.append(f"<h3>{esc(m.key)}" + (" (by day)" if m.by_day else "") + "</h3>")
        head = ["value", "n"] + [f"{n} mean [″]" for n in ANGLE_NAMES]
        rows = [[g.value, g.n] + [_a(v) for v in g.mean] for g in m.groups]
        rows.append(["Kruskal–Wallis p", ""] + [
            "—" if p is None else (f"{p:.2g} DIFFERS" if d else f"{p:.2g}")
            for p, d in zip(m.p_values, m.differs, strict=True)])
        parts.append(table(head, rows))
        parts.append(f"<p>A difference is reported when p &lt; {m.threshold:.2g} (α = 0.01 "
                     "shared by every angle and key compared).</p>")
        parts.append(_img(fig_metadata(m, lot), f"angles against {m.key}"))
    if lot.metadata_skipped:
        parts.append("<p>Not compared: " + "; ".join(f"{esc(k)} ({esc(w)})"
                                                     for k, w in lot.metadata_skipped)
                     + ".</p>")
    return "".join(parts)


def _units(lot: Lot) -> str:
    flagged = lot.flagged
    idx = {k: i for i, k in enumerate(lot.in_stats)}
    head = ["unit", "run index", "ok"] + [f"{n} [″]" for n in ANGLE_NAMES] + [
        "χ²/dof", "warnings", "failed stages", "flags"]
    rows = []
    for k, u in enumerate(lot.units[:UNIT_ROWS_MAX]):
        ang = (["—"] * 6 if u.e_rad is None else
               [f"{v / ARCSEC:+.2f} ± {s / ARCSEC:.2f}"
                for v, s in zip(u.e_rad, u.u_rad or (math.nan,) * 6, strict=True)])
        chi = ("—" if u.chi2 is None or u.dof is None else f"{u.chi2:.1f}/{u.dof}")
        rows.append([u.label, idx.get(k, "—"), "yes" if u.ok else "NO", *ang, chi,
                     len(u.warnings), "; ".join(s for s, _ in u.failed_stages) or "—",
                     "; ".join(flagged.get(k, [])) or "—"])
    more = len(lot.units) - UNIT_ROWS_MAX
    return (f"<details><summary>All {len(lot.units)} units (E ± u per angle)</summary>"
            + table(head, rows) + (f"<p>… and {more} more (in the CSV and the JSON).</p>"
                                    if more > 0 else "") + "</details>")


def write_lot_report(lot: Lot, path: str | Path, doc: dict, force: bool = False) -> Path:
    """Write the lot's report to ``path`` (atomically; exclusively unless ``force``).
    ``doc``: the lot JSON, whose warnings and provenance head the page."""

    n_units, n_stats = len(lot.units), len(lot.in_stats)
    parts = ["<!doctype html><html><head><meta charset='utf-8'>"
             f"<title>Lot report ({n_units} units)</title><style>{CSS}</style></head><body>",
             f"<h1>Lot report — {n_units} units</h1>"]
    if doc["warnings"]:
        parts.append('<div class="warn bad"><h2>Warnings</h2><ul>'
                     + "".join(f"<li>{esc(w)}</li>" for w in doc["warnings"]) + "</ul></div>")

    def verdict(good: bool | None, yes: str, no: str) -> str:
        if good is None:
            return ""
        return f'<span class="ok">{yes}</span>' if good else f'<span class="bad">{no}</span>'

    parts.append(
        f"<p>{n_units + len(lot.rejected)} files: {n_units} session results, "
        f"{len(lot.rejected)} not read; {n_stats} units ok and in the statistics, "
        f"{len(lot.not_ok)} not ok"
        + (f", {len(lot.left_out)} left out as another result of a unit counted once"
           if lot.duplicates else "") + f". Run order: {esc(lot.run_order_note)}. "
        + verdict(lot.ok, "Every result read and ok.", "NOT every result read and ok.") + " "
        + (verdict(lot.in_control, "In control.", "NOT in control.") if n_stats else "") + " "
        + verdict(lot.within_tolerance, "Every unit within tolerance.",
                  "NOT every unit within tolerance.") + "</p>" + _provenance(doc))
    if lot.rejected:
        parts.append("<h2>Files not read</h2>" + table(
            ["file", "why"], [[r.file, r.reason] for r in lot.rejected], left=2))
    if lot.duplicates:
        parts.append("<h2>Units in several results (each counted once)</h2>" + table(
            ["unit", "used", "why", "left out"],
            [[d.label, lot.units[d.used].file, d.why,
              "; ".join(f"{lot.units[k].file} ({r})" for k, r in
                        zip(d.left_out, d.relations, strict=True))]
             for d in lot.duplicates], left=4))
    if lot.not_ok:
        parts.append("<h2>Units not ok (not in the statistics)</h2>" + table(
            ["unit", "file", "fused", "failed stages"],
            [[u.label, u.file, "yes" if u.fused else "no",
              "; ".join(f"{s}: {m}" for s, m in u.failed_stages) or "—"]
             for u in (lot.units[k] for k in lot.not_ok)], left=4))
    if n_stats:
        parts.append("<h2>Per angle</h2>" + _summary(lot))
        parts.append("<h2>Flagged units</h2>" + _flagged(lot))
        parts.append("<h2>Distribution over the units</h2>"
                     + _img(fig_distributions(lot), "distributions")
                     + "<p>Black: mean; orange dashed: control limits; red: tolerance.</p>")
        parts.append("<h2>Control charts (individuals and moving range, run order)</h2>")
        for a in lot.angles:
            parts.append(f"<h3>{esc(a.name)}</h3>")
            if a.chart is None:
                parts.append("<p>Fewer than 2 units: no chart.</p>")
                continue
            parts.append(_img(fig_control_chart(a, lot), f"control chart {a.name}"))
        parts.append(_metadata(lot))
    parts.append("<h2>Units</h2>" + _units(lot))
    parts.append("</body></html>")
    return write_atomic(path, "\n".join(parts), force)
