"""One self-contained HTML page of a lot (figures embedded as PNG data URIs, no scripts, no
external resources), rendered from ``align/templates/lot.html.j2``: the lot's name and
verdict first, a disposition per unit (linking each unit's session report when it is at
hand), the warnings ranked into "act" and "note", then per angle the summary, distribution,
control chart (units named by serial and date) and capability, the metadata breakdown, and
every unit.

It imports nothing of the session pipeline (seconds of start-up): a lot of 10⁴ results must
be reported in a few seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

from markupsafe import Markup

from align.html import esc, png_img, render, table
from align.lot.disposition import (
    SEVERITY,
    lot_name,
    rank_warnings,
    relative_link,
    session_report_of,
    unit_dispositions,
)
from align.lot.figures import fig_control_chart, fig_distributions, fig_metadata, png
from align.lot.read import ANGLE_NAMES
from align.lot.stats import FALSE_RATE, GUARD, Lot
from axisbase.output import write_atomic
from axisbase.provenance import Provenance
from axisbase.units import ARCSEC

UNIT_ROWS_MAX = 20000
"""Units listed one by one in the page (the CSV and JSON always list them all)."""


def _img(fig, alt: str) -> str:
    return str(png_img(png(fig), alt))  # a str: these pages are joined as text


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
    parts = ["<h2 id='metadata'>Each angle against the session metadata</h2>"]
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
    ``doc``: the lot JSON, whose warnings and provenance the page shows."""

    return write_atomic(path, lot_html(lot, doc, Path(path)), force)


VERDICT_CELL = {"PASS": "ok", "FAIL": "bad", "INCONCLUSIVE": "warnc", "NOT MEASURED": "bad",
                "NO TOLERANCE": ""}


DISPOSITION_ROWS_MAX = 1000
"""Units listed one by one in the disposition table (all needing a decision come first;
every unit is in the unit table below, the CSV and the JSON)."""


def _dispositions(lot: Lot, disps: list, page: Path | None
                  ) -> tuple[list[dict], list[dict], int]:
    """The units needing a decision (FAIL, INCONCLUSIVE, NOT MEASURED), the others, and how
    many are left out of the table (beyond :data:`DISPOSITION_ROWS_MAX`)."""

    decide, rest = [], []
    for d in disps[:DISPOSITION_ROWS_MAX]:
        u = lot.units[d.index]
        rep = session_report_of(u.file) if page is not None else None
        w = u.when
        row = {"unit": u.label, "date": "—" if w is None else w.date().isoformat(),
               "verdict": d.verdict, "cls": VERDICT_CELL.get(d.verdict, ""),
               "worst": d.worst or "—",
               "margin": "—" if d.margin_arcsec is None else f"{d.margin_arcsec:+.2f}",
               "link": None if rep is None else relative_link(rep, page)}
        (rest if d.verdict in ("PASS", "NO TOLERANCE") else decide).append(row)
    return decide, rest, max(0, len(disps) - DISPOSITION_ROWS_MAX)


def _banner(lot: Lot, counts: dict[str, int]) -> dict:
    n = len(lot.units)
    if counts.get("FAIL") or counts.get("NOT MEASURED") or lot.rejected:
        bad = [f"{counts[v]} {v}" for v in ("FAIL", "INCONCLUSIVE", "NOT MEASURED")
               if counts.get(v)] + ([f"{len(lot.rejected)} files not read"]
                                    if lot.rejected else [])
        return {"verdict": "ACTION NEEDED", "cls": "v-fail",
                "text": f"{', '.join(bad)} of {n} units"}
    if counts.get("INCONCLUSIVE"):
        return {"verdict": "INCONCLUSIVE UNITS", "cls": "v-inconclusive",
                "text": f"{counts['INCONCLUSIVE']} of {n} units cannot be stated in or out"}
    if counts.get("PASS") == n:
        return {"verdict": "ALL PASS", "cls": "v-pass", "text": f"{n} units"}
    return {"verdict": "No tolerance given", "cls": "v-none",
            "text": f"{n} units measured; --tolerance-arcsec (or each session's "
                    "[tolerance]) gives a verdict per unit"}


def lot_html(lot: Lot, doc: dict, page: Path | None = None) -> str:
    """The lot's report as one self-contained HTML page; ``page``: where it will be written
    (links to the units' session reports are relative to it; None: no links)."""

    n_units, n_stats = len(lot.units), len(lot.in_stats)
    counts: dict[str, int] = {}
    disps = unit_dispositions(lot, doc.get("dispositions"))
    for d in disps:
        counts[d.verdict] = counts.get(d.verdict, 0) + 1
    decide, rest, more = _dispositions(lot, disps, page)
    act, note = rank_warnings(list(zip(doc.get("warning_codes") or ["unknown"] * len(
        doc["warnings"]), doc["warnings"], strict=True)))

    def verdict(good: bool | None, yes: str, no: str) -> str:
        if good is None:
            return ""
        return f'<span class="ok">{yes}</span>' if good else f'<span class="bad">{no}</span>'

    parts = [
        f"<h2 id='summary'>Summary</h2><p>{n_units + len(lot.rejected)} files: {n_units} session "
        f"results, {len(lot.rejected)} not read; {n_stats} units ok and in the statistics, "
        f"{len(lot.not_ok)} not ok"
        + (f", {len(lot.left_out)} left out as another result of a unit counted once"
           if lot.duplicates else "") + f". Run order: {esc(lot.run_order_note)}. "
        + verdict(lot.ok, "Every result read and ok.", "NOT every result read and ok.") + " "
        + (verdict(lot.in_control, "In control.", "NOT in control.") if n_stats else "") + " "
        + verdict(lot.within_tolerance, "Every unit within tolerance.",
                  "NOT every unit within tolerance.") + "</p>"]
    toc = [("dispositions", "Dispositions"), ("warnings", "Warnings"), ("summary", "Summary")]
    if lot.rejected:
        parts.append("<h2 id='rejected'>Files not read</h2>" + table(
            ["file", "why"], [[r.file, r.reason] for r in lot.rejected], left=2))
        toc.append(("rejected", "Files not read"))
    if lot.duplicates:
        parts.append("<h2 id='duplicates'>Units in several results (each counted once)</h2>"
                     + table(["unit", "used", "why", "left out"],
                             [[d.label, lot.units[d.used].file, d.why,
                               "; ".join(f"{lot.units[k].file} ({r})" for k, r in
                                         zip(d.left_out, d.relations, strict=True))]
                              for d in lot.duplicates], left=4))
        toc.append(("duplicates", "Duplicates"))
    if lot.not_ok:
        parts.append("<h2 id='not-ok'>Units not ok (not in the statistics)</h2>" + table(
            ["unit", "file", "fused", "failed stages"],
            [[u.label, u.file, "yes" if u.fused else "no",
              "; ".join(f"{s}: {m}" for s, m in u.failed_stages) or "—"]
             for u in (lot.units[k] for k in lot.not_ok)], left=4))
        toc.append(("not-ok", "Units not ok"))
    if n_stats:
        parts.append("<h2 id='per-angle'>Per angle</h2>" + _summary(lot))
        parts.append("<h2 id='flagged'>Flagged units</h2>" + _flagged(lot))
        parts.append("<h2 id='distribution'>Distribution over the units</h2>"
                     + _img(fig_distributions(lot), "distributions")
                     + "<p>Black: mean; orange dashed: control limits; red: tolerance.</p>")
        parts.append("<h2 id='charts'>Control charts (individuals and moving range, run "
                     "order; units named by serial and date)</h2>")
        for a in lot.angles:
            parts.append(f"<h3 id='chart-{esc(a.name)}'>{esc(a.name)}</h3>")
            if a.chart is None:
                parts.append("<p>Fewer than 2 units: no chart.</p>")
                continue
            parts.append(_img(fig_control_chart(a, lot), f"control chart {a.name}"))
        parts.append(_metadata(lot))
        toc += [("per-angle", "Per angle"), ("flagged", "Flagged"),
                ("distribution", "Distribution"), ("charts", "Control charts"),
                ("metadata", "Metadata")]
    parts.append("<h2 id='units'>Units</h2>" + _units(lot))
    toc += [("units", "Units"), ("provenance", "Provenance")]
    if disps and disps[0].source == "lot" and doc.get("dispositions"):
        rule = ("Each unit judged by align lot against the tolerance and decision rule it was "
                "given (the JSON's dispositions: rule, k, each angle's margin and probability "
                "of conformance).")
    else:
        rule = ("Each unit's verdict is its own result's disposition when it has one; "
                "otherwise " + (
                    f"against the lot's tolerance ±{lot.tolerance / ARCSEC:g}″: FAIL outside "
                    f"it, INCONCLUSIVE inside by less than {GUARD:g}·u, PASS otherwise"
                    if lot.tolerance is not None else
                    "no tolerance was given (--tolerance-arcsec)") + ".")
    rule += (" NOT MEASURED: the result is not ok. The margin is the worst angle's distance "
             "inside the tolerance (negative: outside).")
    order = sorted(counts, key=lambda v: SEVERITY.get(v, 9))
    return render(
        "lot.html.j2", name=lot_name(lot), n_units=n_units, banner=_banner(lot, counts),
        counts=[(v, counts[v], "s-" + {"PASS": "ok", "INCONCLUSIVE": "warn",
                                       "NO TOLERANCE": "absent"}.get(v, "fail"))
                for v in order],
        toc=toc, rule=rule, decide=decide, passed=rest,
        passed_label="PASS" if lot.tolerance is not None or any(
            r["verdict"] == "PASS" for r in rest) else "without a tolerance",
        more=more, act=act, note=note, body=Markup("\n".join(parts)),
        provenance=Markup(_provenance(doc)))
