"""One self-contained HTML report of a session (figures embedded as PNG data URIs), rendered
from ``align/templates/session.html.j2``.

The page opens with the answer: the unit's identity (``[metadata]``), the verdict against the
tolerance (the result's ``disposition``; "no tolerance given" without one), a strip of the
stages (ok / warned / failed) and the set-up effects the fusion found. Then E with u and the
margins, the uncertainty budget (the result's ``budget``), and the stages in detail; the
provenance closes it, collapsed. Everything here turns results into strings for the template;
the layout is the template's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from align.fusion import E_INDEX, E_NAMES
from align.html import png_img, render
from align.loop import LoopReport, LoopSummary
from align.plots import (
    fig_calibration,
    fig_fusion,
    fig_gonio,
    fig_mark_residuals,
    fig_mark_thumb,
    jpeg_bytes,
    png_bytes,
)
from align.session.run import SessionResult
from align.warnings import session_notes, session_warnings, setup_notices
from axisbase.header import OUTPUT_UNITS
from axisbase.output import write_atomic
from axisbase.provenance import Provenance
from axisbase.units import ARCSEC
from goniometry import kept_table
from imaging import ImageInputError, read_image

IDENTITY_KEYS = ("serial", "unit", "operator", "date", "lot")
"""``[metadata]`` keys shown first, in this order, as the unit's identity."""

VERDICT_CLASS = {"PASS": "v-pass", "FAIL": "v-fail", "INCONCLUSIVE": "v-inconclusive",
                 "NOT MEASURED": "v-notmeasured", "NO TOLERANCE": "v-none"}


def _img(fig, alt: str = "figure", cls: str = "", dpi: int = 90):
    return png_img(png_bytes(fig, dpi), alt, cls)


def _thumb(fig, alt: str):
    return png_img(jpeg_bytes(fig), alt, "thumb", "image/jpeg")


def _chi(v: float | None) -> str:
    return "—" if v is None else f"{v:.3f}"


def loop_view(loop: LoopReport | LoopSummary | None, scale: float = 1.0,
              unit: str = "") -> dict | None:
    """A residual loop as the template's ``loop_table`` shows it (None: it did not run)."""
    if loop is None:
        return None
    s = loop.summary()
    rows = [["declared model", "", "", f"{s.rms_before:.4g}", _chi(s.chi2_dof_before)]]
    for e in s.effects:
        # a vector effect by its components (its estimate is only their vector's length)
        value = (", ".join(f"{c} {v * scale:+.4g} ± {u * scale:.2g}" for c, v, u in
                           e.components) if e.components
                 else f"{e.estimate * scale:.4g} ± {e.u * scale:.2g}")
        rows.append([f"+ {e.name}", f"{value} {unit or e.unit}", f"{e.p_value:.2g}",
                     f"{e.rms_after:.4g}", ""])
    rows[-1][4] = _chi(s.chi2_dof_after)
    structure = (f"{s.structure_test} (p = {s.structure_p:.2g}) {s.structure_detail}".strip()
                 if s.unexplained_structure else None)
    return {"rows": rows, "structure": structure}


@dataclass(frozen=True)
class Stage:
    """One stage in the page's strip: ``status`` ok | warn | fail | absent."""

    name: str
    status: str
    label: str
    anchor: str
    title: str = ""


def stage_strip(res: SessionResult, warnings: list[str]) -> list[Stage]:
    """The stages a session names, each ok / warned / failed (``warnings``: the result's)."""
    s = res.session
    failed = {}
    for e in res.errors:
        key = "marks" if e.stage.startswith("camera ") else e.stage
        failed.setdefault(key, []).append(e.message)

    def status(stage: str, prefixes: tuple[str, ...]) -> tuple[str, str]:
        if stage in failed:
            return "fail", "; ".join(failed[stage])
        w = [x for x in warnings if x.startswith(prefixes)]
        return ("warn", "; ".join(w)) if w else ("ok", "")

    out = []
    if s.calibration is not None:
        st, why = status("calibration", ("calibration",))
        out.append(Stage("calibration", st, {"ok": "ok", "warn": "warned",
                                             "fail": "FAILED"}[st], "calibration", why))
    if s.goniometer is not None:
        st, why = status("goniometer", ("goniometer",))
        out.append(Stage("goniometer", st, {"ok": "ok", "warn": "warned",
                                            "fail": "FAILED"}[st], "goniometer", why))
    if s.images:
        # a mark's warnings start with its image's path (MarkResult.image)
        st, why = status("marks", tuple({str(im.file) for im in s.images}
                                        | {im.file.name for im in s.images}))
        out.append(Stage("marks", st, f"{len(res.marks)}/{len(s.images)}", "marks", why))
    if s.platform is not None:
        st, why = status("platform static", ("platform",))
        out.append(Stage("static", st, {"ok": "ok", "warn": "warned",
                                        "fail": "FAILED"}[st], "fusion", why))
    f = res.fusion
    if f is None or "fusion" in failed:
        out.append(Stage("fusion", "fail", "FAILED" if f is None else
                         f"χ² {f.chi2:.1f}/{f.dof} GROSS", "misalignment",
                         "; ".join(failed.get("fusion", ["did not run"]))))
    else:
        st, why = status("fusion", ("fusion", "set-up"))
        out.append(Stage("fusion", st, f"χ² {f.chi2:.1f}/{f.dof}", "fusion", why))
    return out


def identity(res: SessionResult) -> list[tuple[str, str]]:
    """The unit's identity from ``[metadata]`` (the known keys first, then the others)."""
    m = res.session.metadata
    out = [(k, str(m[k])) for k in IDENTITY_KEYS if k in m]
    if "serial" not in m and "unit" not in m:
        out.insert(0, ("serial", "not given ([metadata] serial)"))
    out += [(k, str(v)) for k, v in m.items() if k not in IDENTITY_KEYS]
    out.append(("session", res.session.name))
    return out


def banner(res: SessionResult, disposition: dict | None) -> dict:
    """The verdict: the result's disposition, or 'no tolerance given' (NOT ok when a stage
    failed: a failed session is never shown as if measured)."""
    failed = ", ".join(dict.fromkeys(e.stage for e in res.errors))
    if disposition and disposition.get("verdict") == "NO TOLERANCE":
        disposition = None  # said below as "No tolerance given" (or NOT ok)
    if disposition:
        v = str(disposition["verdict"])
        text = str(disposition.get("reason", ""))
        if disposition.get("worst"):
            text += f" (worst angle: {disposition['worst']})"
        if disposition.get("p_conform_all") is not None:
            text += f"; P(every angle conforms) = {disposition['p_conform_all']:.3f}"
        return {"verdict": v, "cls": VERDICT_CLASS.get(v, "v-none"), "text": text}
    if not res.ok:
        why = (f"stage(s) failed: {failed or 'fusion'}" if failed or res.fusion is None
               else "; ".join(res.problems))
        return {"verdict": "NOT ok", "cls": "v-notmeasured",
                "text": f"no tolerance given; {why} — not a measurement of this unit"}
    return {"verdict": "No tolerance given", "cls": "v-none",
            "text": "E ± u below; a [tolerance] in session.toml or --tolerance-arcsec gives "
                    "a verdict"}


def _num(d: dict, key: str, fmt: str = "{:+.2f}") -> str:
    v = d.get(key)
    return "—" if v is None else fmt.format(v)


def _angles(res: SessionResult, disposition: dict | None) -> tuple[list[str], list[list[str]]]:
    f = res.fusion
    head = ["angle", "E ± u [″]"]
    by_name = {a["name"]: a for a in (disposition or {}).get("angles", [])}
    if by_name:
        head += ["nominal [″]", "tolerance zone [″]", "guard band [″]", "margin [″]",
                 "P(conform)", "verdict"]
    rows = []
    for name, (i, j) in zip(E_NAMES, E_INDEX, strict=True):
        r = [name, f"{f.E[i, j] / ARCSEC:+.2f} ± {f.E_u[i, j] / ARCSEC:.2f}"]
        a = by_name.get(name)
        if by_name and a is None:
            r += ["—"] * 6
        elif a is not None:
            r += [_num(a, "nominal_arcsec"),
                  f"{_num(a, 'lower_arcsec')} … {_num(a, 'upper_arcsec')}",
                  _num(a, "guard_arcsec", "{:.2f}"), _num(a, "margin_arcsec"),
                  _num(a, "p_conform", "{:.3f}"), str(a.get("verdict", "—"))]
        rows.append(r)
    return head, rows


def _budget(doc: dict) -> list[dict]:
    b = (doc.get("budget") or {}).get("angles") or {}
    out = []
    for name, entry in b.items():
        rows = sorted(entry.get("contributions", []), key=lambda c: -c["u2_arcsec2"])
        out.append({"name": name, "u": f"{entry['u_arcsec']:.3g}",
                    "rows": [[c["source"], c.get("kind", ""), f"{c['u2_arcsec2']:.3g}",
                              f"{c['fraction']:.1%}"] for c in rows]})
    return out


def _fusion(res: SessionResult) -> dict | None:
    f = res.fusion
    if f is None:
        return None
    matrix = [[f"accelerometer {'xyz'[i]}"] + [
        "0" if i == j else f"{f.E[i, j] / ARCSEC:+.2f} ± {f.E_u[i, j] / ARCSEC:.2f}″"
        for j in range(3)] for i in range(3)]
    rows = [[r.source, r.label] + ([f"{r.value / ARCSEC:+.3f}″", f"{r.predicted / ARCSEC:+.3f}″",
                                    f"{r.u / ARCSEC:.3f}″"] if r.unit == "rad" else
                                   [f"{r.value * 1e6:+.2f} µg", f"{r.predicted * 1e6:+.2f} µg",
                                    f"{r.u * 1e6:.2f} µg"]) + [f"{r.normalised:+.2f}"]
            for r in f.rows]
    return {"matrix": matrix, "rows": rows, "sources": ", ".join(f.sources),
            "chi2": f"{f.chi2:.2f}", "dof": f.dof, "p": f"{f.p_value:.3g}",
            "consistent": f.consistent, "loop": loop_view(f.loop, 1 / ARCSEC, "″"),
            "inflation_note": (f", inflated ×{f.inflation:.2f} for the inconsistency that "
                               "remains" if f.inflation > 1 else ""),
            "figure": _img(fig_fusion(f.rows), "normalised residual per observation")}


def _calibration(res: SessionResult) -> dict | None:
    if res.calibration is None:
        return None
    c, m = res.calibration, res.calibration.model
    k, k_u = m.sensitivity(), m.sensitivity_u()  # output per g along each axis
    u_beta, u_bias = m.u_per_axis("beta"), m.u_per_axis("bias")
    rows = [[ax, f"{k[i]:.7f} ± {k_u[i]:.2g}",
             f"{m.beta[i] * 1e6:.2f} ± {u_beta[i] * 1e6:.2g}",
             f"{m.bias[i] * 1e6:.2f} ± {u_bias[i] * 1e6:.2g}"]
            for i, ax in enumerate("xyz")]
    fig = (_img(fig_calibration(c, res.calibration_poses, None), "delta g per pose")
           if res.calibration_poses is not None else None)
    return {"head": ["axis", f"scale factor [{OUTPUT_UNITS[res.units]}]", "β [µrad]",
                     "bias [µg]"], "rows": rows, "loop": loop_view(c.loop), "figure": fig}


def _gonio(res: SessionResult) -> dict | None:
    if res.gonio is None:
        return None
    s, g, fa = res.session, res.gonio, res.gonio.angles
    faces = list(s.goniometer.faces)
    n = len(faces)
    rows = [[f"{faces[i]} → {faces[(i + 1) % n]}", f"{np.rad2deg(fa.angles_rad[i]):.7f}",
             f"{fa.u_rad[i] / ARCSEC:.3f}",
             f"{(fa.angles_rad[i] - s.goniometer.nominal_rad[i]) / ARCSEC:+.3f}"]
            for i in range(n)]
    return {"intro": f"{fa.revolutions} revolutions used; "
                     f"{np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count. " + " ".join(g.notes),
            "rows": rows, "loop": loop_view(g.loop),
            "figure": _img(fig_gonio(kept_table(g.summary)[0], fa, faces), "goniometer"),
            "exclusions": [f"{count} × {reason}"
                           for reason, count in g.summary.exclusions.counts.items()]}


def _marks(res: SessionResult) -> dict | None:
    s = res.session
    if not s.images:
        return None
    measured = {im.key: (im, r) for im, r in res.marks}
    failures = {e.message.split(" (", 1)[0]: e.message for e in res.errors
                if e.stage == "marks"}
    rows = []
    for k, im in enumerate(s.images):
        if im.key not in measured:
            why = next((m for key, m in failures.items() if key == im.key),
                       "not measured (see the stage failures)")
            rows.append({"file": im.file.name, "thumb": "—", "housing": im.housing,
                         "view": im.view, "angle": "—", "u": "—", "effects": "—", "rms": "—",
                         "structure": f"FAILED: {why}", "structure_cls": "bad",
                         "anchor": None, "figure": None})
            continue
        _, r = measured[im.key]
        try:
            image = read_image(im.file)
        except ImageInputError:
            image = None
        lp = r.loop.summary()
        rows.append({
            "file": im.file.name,
            "thumb": ("—" if image is None else
                      _thumb(fig_mark_thumb(r, image), f"{im.file.name} thumbnail")),
            "housing": im.housing, "view": im.view,
            "angle": f"{np.rad2deg(r.angle_rad):+.6f}", "u": f"{r.angle_u_rad / ARCSEC:.2f}",
            "effects": ", ".join(e.name for e in r.loop.effects) or "none",
            "rms": f"{lp.rms_before:.3f} → {lp.rms_after:.3f}",
            "structure": ("unexplained: " + (lp.structure_test or "")
                          if lp.unexplained_structure else "none left"),
            "structure_cls": "bad" if lp.unexplained_structure else "ok",
            "anchor": f"mark-{k + 1}",
            "figure": _img(fig_mark_residuals(r), f"{im.file.name} residuals", dpi=72)})
    return {"rows": rows, "n": len(s.images), "n_ok": len(res.marks)}


def provenance_view(doc: dict | None) -> dict:
    """Provenance as table rows (tool, format, when, command, each setting) and the inputs."""
    if not doc or "tool" not in doc:
        return {"rows": [["provenance", "not recorded (no result document)"]], "inputs": []}

    p = Provenance.from_dict(doc)
    rows = [["tool", f"{p.tool} {p.tool_version}"],
            ["format", f"{doc['format']} version {doc['format_version']}"],
            ["written (UTC)", p.created_utc], ["command", " ".join(p.command)]]
    rows += [[f"setting {k}", str(v)] for k, v in dict(p.settings).items()]
    return {"rows": rows, "inputs": [[i.path, i.sha256 or "unreadable"] for i in p.inputs]}


def write_report(res: SessionResult, path: str | Path, force: bool = False,
                 doc: dict | None = None) -> Path:
    """Write the report to ``path`` (atomically; exclusively unless ``force``). ``doc``: the
    result JSON, whose warnings, disposition, budget and provenance the report shows."""

    return write_atomic(path, report_html(res, doc), force)


def stage_views(res: SessionResult) -> dict:
    """What the page shows of each stage, figures drawn (the costly part: seconds); a page
    re-rendered with another ``doc`` (a disposition, a budget) can reuse it."""
    return {"fusion": _fusion(res), "calibration": _calibration(res), "gonio": _gonio(res),
            "marks": _marks(res)}


def report_html(res: SessionResult, doc: dict | None = None,
                views: dict | None = None) -> str:
    """The report as one self-contained HTML page (see :func:`write_report`); ``views``:
    :func:`stage_views` of ``res`` when already drawn."""

    d = doc if doc is not None else res.to_dict()
    v = views if views is not None else stage_views(res)
    warnings = list(d.get("warnings", session_warnings(res)))
    disposition = d.get("disposition")
    if disposition and disposition.get("verdict") == "NO TOLERANCE":
        disposition = None  # no rule, no margins: the banner says "No tolerance given"
    ident = identity(res)
    unit_label = next((val for k, val in ident if k in ("serial", "unit")
                       and not val.startswith("not given")), res.session.name)
    fusion = v["fusion"]
    angle_head, angle_rows = _angles(res, disposition) if fusion else ([], [])
    sections = [("misalignment", "Misalignment E"), ("budget", "Budget")]
    if fusion:
        sections.append(("fusion", "Fusion"))
    cal, gon, marks = v["calibration"], v["gonio"], v["marks"]
    for key, name, present in (("calibration", "Calibration", cal), ("goniometer",
                               "Goniometer", gon), ("marks", "Scribe marks", marks)):
        if present:
            sections.append((key, name))
    notices = (setup_notices(res.fusion, res.session.declared_setup())
               if res.fusion is not None else [])
    carried = list(d.get("notes", session_notes(res)))
    # the notices and the carried candidates are on the first screen
    shown = [w for w in warnings if w not in notices]
    if shown:
        sections.insert(0, ("warnings", f"Warnings ({len(shown)})"))
    if res.errors:
        sections.insert(0, ("failures", "Stage failures"))
    sections.append(("provenance", "Provenance"))
    if disposition:
        disposition = dict(disposition, rule_text=(
            f"{disposition.get('rule', '?')}" + (f", guard band w = {disposition['k']:g}·u"
                                                  if disposition.get("rule") == "guarded"
                                                  and disposition.get("k") is not None
                                                  else "")))
    failed = ", ".join(dict.fromkeys(e.stage for e in res.errors))
    return render(
        "session.html.j2", title=f"Alignment report {unit_label} ({res.session.name})",
        unit_label=unit_label, identity=ident, banner=banner(res, disposition),
        strip=stage_strip(res, warnings),
        notices=notices, carried=carried, toc=sections, warnings=shown,
        errors=[[e.stage, e.message] for e in res.errors], ok=res.ok,
        not_ok_reason=(f"stage(s) failed: {failed}" if failed else
                       res.calibration.problems[0] if res.calibration is not None
                       and res.calibration.problems else "not ok"),
        fusion=fusion, disposition=disposition, angle_head=angle_head, angle_rows=angle_rows,
        budget=_budget(d), calibration=cal, gonio=gon, marks=marks,
        provenance_view=provenance_view(doc))
