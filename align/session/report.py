"""One self-contained HTML report of a session (figures embedded as PNG data URIs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from align.html import esc, png_img, table
from align.loop import LoopReport, LoopSummary
from align.plots import fig_calibration, fig_fusion, fig_gonio, fig_mark, png_bytes
from align.session.run import SessionResult
from align.warnings import session_warnings
from axisbase.output import write_atomic
from axisbase.provenance import Provenance
from axisbase.table import OUTPUT_UNITS
from axisbase.units import ARCSEC
from goniometry import kept_table
from imaging import ImageInputError, read_image

CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}.bad{color:#b00;font-weight:bold}
.ok{color:#070}img{max-width:100%}h2{border-bottom:2px solid #446;margin-top:1.6em}"""


def _img(fig) -> str:
    return png_img(png_bytes(fig))


def _loop(loop: LoopReport | LoopSummary | None, scale: float = 1.0, unit: str = "") -> str:
    if loop is None:
        return "<p>The residual loop did not run for this stage.</p>"
    s = loop.summary()

    def chi(v: float | None) -> str:
        return "—" if v is None else f"{v:.3f}"
    rows = [["declared model", "", "", f"{s.rms_before:.4g}", chi(s.chi2_dof_before)]]
    for e in s.effects:
        rows.append([f"+ {e.name}", f"{e.estimate * scale:.4g} ± {e.u * scale:.2g} "
                     f"{unit or e.unit}", f"{e.p_value:.2g}", f"{e.rms_after:.4g}", ""])
    rows[-1][4] = chi(s.chi2_dof_after)
    out = table(["model", "effect estimate", "p", "residual RMS", "chi2/dof"], rows)
    if s.unexplained_structure:
        out += (f'<p class="bad">Unexplained structure remains: {esc(s.structure_test)} '
                f"(p = {s.structure_p:.2g}) {esc(s.structure_detail)}</p>")
    else:
        out += '<p class="ok">No structure left in the residual.</p>'
    return out


def _provenance(doc: dict | None) -> str:
    if not doc:
        return ""

    p = Provenance.from_dict(doc)
    rows = [[i.path, i.sha256 or "unreadable"] for i in p.inputs]
    return (f"<p>{esc(p.tool)} {esc(p.tool_version)}, {esc(doc['format'])} format version "
            f"{doc['format_version']}, written {esc(p.created_utc)} (UTC) by "
            f"<code>{esc(' '.join(p.command))}</code>; settings "
            f"<code>{esc(dict(p.settings))}</code>.</p>"
            "<details><summary>Input files (SHA-256)</summary>"
            + table(["file", "SHA-256"], rows, left=2) + "</details>")


def write_report(res: SessionResult, path: str | Path, force: bool = False,
                 doc: dict | None = None) -> Path:
    """Write the report to ``path`` (atomically; exclusively unless ``force``). ``doc``: the
    result JSON, whose warnings and provenance head the report."""

    return write_atomic(path, report_html(res, doc), force)


def report_html(res: SessionResult, doc: dict | None = None) -> str:
    """The report as one self-contained HTML page (see :func:`write_report`)."""

    s = res.session
    warnings = doc["warnings"] if doc else session_warnings(res)
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>Alignment report "
             f"{esc(s.name)}</title><style>{CSS}</style></head><body>",
             f"<h1>Alignment report — {esc(s.name)}</h1>"]
    if warnings:
        parts.append('<div class="bad"><h2>Warnings</h2><ul>'
                     + "".join(f"<li>{esc(w)}</li>" for w in warnings) + "</ul></div>")
    parts.append(f"<p>Session folder {esc(s.folder)}; result "
                 + ('<span class="ok">ok</span>' if res.ok else
                    '<span class="bad">NOT ok</span>') + ".</p>" + _provenance(doc))
    if res.errors:
        parts.append("<h2>Stage failures</h2>" + table(
            ["stage", "message"], [[e.stage, e.message] for e in res.errors], left=2))
    f = res.fusion
    parts.append("<h2>Misalignment matrix E (platform frame)</h2>")
    if f is None:
        parts.append('<p class="bad">No misalignment: the fusion did not run (see the stage '
                     "failures).</p>")
    else:
        rows = [[f"accelerometer {'xyz'[i]}"] + [
            "0" if i == j else f"{f.E[i, j] / ARCSEC:+.2f} ± {f.E_u[i, j] / ARCSEC:.2f}″"
            for j in range(3)] for i in range(3)]
        parts.append("<p>E<sub>ij</sub>: component of accelerometer i's sensing axis along "
                     "platform axis j; u is the standard uncertainty"
                     + (f", inflated ×{f.inflation:.2f} for the inconsistency that remains"
                        if f.inflation > 1 else "") + ".</p>")
        parts.append(table(["", "X", "Y", "Z"], rows))
        verdict = ('<span class="ok">consistent</span>' if f.consistent
                   else '<span class="bad">NOT consistent</span>')
        parts.append(f"<p>Sources: {esc(', '.join(f.sources))}. chi2 = {f.chi2:.2f} for "
                     f"{f.dof} degrees of freedom (p = {f.p_value:.3g}): the instruments are "
                     f"{verdict} with each other.</p>")
        parts.append("<h3>Fusion loop (nuisances added when the data call for them)</h3>"
                     + _loop(f.loop, 1 / ARCSEC, "″"))
        parts.append("<h3>Normalised residual per observation</h3>" + _img(fig_fusion(f.rows)))
        parts.append(table(
            ["source", "observation", "observed", "fitted", "u", "normalised"],
            [[r.source, r.label] + ([f"{r.value / ARCSEC:+.3f}″", f"{r.predicted / ARCSEC:+.3f}″",
                                     f"{r.u / ARCSEC:.3f}″"] if r.unit == "rad" else
                                    [f"{r.value * 1e6:+.2f} µg", f"{r.predicted * 1e6:+.2f} µg",
                                     f"{r.u * 1e6:.2f} µg"]) + [f"{r.normalised:+.2f}"]
             for r in f.rows], left=2))
    if res.calibration is not None:
        c, m = res.calibration, res.calibration.model
        parts.append("<h2>Triad calibration (ellipsoid, seed paper's model)</h2>")

        k, k_u = m.sensitivity(), m.sensitivity_u()  # output per g along each axis
        parts.append(table(["axis", f"scale factor [{OUTPUT_UNITS[res.units]}]", "β [µrad]",
                             "bias [µg]"], [
            [ax, f"{k[i]:.7f} ± {k_u[i]:.2g}",
             f"{m.beta[i] * 1e6:.2f} ± {m.u_of(f'beta_{ax}') * 1e6:.2g}",
             f"{m.bias[i] * 1e6:.2f} ± {m.u_of(f'bias_{ax}') * 1e6:.2g}"]
            for i, ax in enumerate("xyz")]))
        parts.append(_loop(c.loop))
        if res.calibration_poses is not None:
            parts.append("<h3>Δg per pose</h3>"
                         + _img(fig_calibration(c, res.calibration_poses, None)))
    if res.gonio is not None:

        g, fa = res.gonio, res.gonio.angles
        faces = list(s.goniometer.faces)
        parts.append("<h2>Goniometer</h2>")
        parts.append(f"<p>{fa.revolutions} revolutions used; "
                     f"{np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count. "
                     + " ".join(esc(n) for n in g.notes) + "</p>")
        n = len(faces)
        parts.append(table(["faces", "angle [°]", "u [″]", "deviation from nominal [″]"], [
            [f"{faces[i]} → {faces[(i + 1) % n]}", f"{np.rad2deg(fa.angles_rad[i]):.7f}",
             f"{fa.u_rad[i] / ARCSEC:.3f}",
             f"{(fa.angles_rad[i] - s.goniometer.nominal_rad[i]) / ARCSEC:+.3f}"]
            for i in range(n)]))
        if g.loop is not None:
            parts.append(_loop(g.loop))
        parts.append(_img(fig_gonio(kept_table(g.summary)[0], fa, faces)))
        for reason, count in g.summary.exclusions.counts.items():
            parts.append(f"<p>{count} × {esc(reason)}</p>")
    if res.marks:
        parts.append("<h2>Scribe marks</h2>")
        parts.append(table(["image", "housing", "view", "angle [°]", "u [″]", "effects"], [
            [im.file.name, im.housing, im.view, f"{np.rad2deg(r.angle_rad):+.6f}",
             f"{r.angle_u_rad / ARCSEC:.2f}", ", ".join(e.name for e in r.loop.effects)
             or "none"] for im, r in res.marks], left=3))

        for im, r in res.marks:
            try:
                image = read_image(im.file)
            except ImageInputError:
                image = None
            parts.append(f"<h3>{esc(im.file.name)} — housing {im.housing}, view {im.view}</h3>"
                         + _loop(r.loop) + _img(fig_mark(r, image)))
    parts.append("</body></html>")
    return "\n".join(parts)
