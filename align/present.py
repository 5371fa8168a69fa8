"""Results as lines of text: marks, camera, static intervals, calibration, tilt, goniometer,
fusion, batch, lot. One place renders each result, so the terminal and the HTML reports say
the same thing; each function returns lines (no printing, no I/O).

Degrees, arc-seconds, µrad and µg appear here, at the edge; results hold radians and SI.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

from align.decision import Disposition
from align.fusion.budget import Budget
from align.plan import plan_from_result
from align.session_json import LoadedSession
from align.warnings import is_information, mark_notes
from axisbase.header import OUTPUT_UNITS
from axisbase.units import ARCSEC

# ----------------------------------------------------------------------------- imaging

def mark_lines(r) -> list[str]:
    """One measured mark (:class:`align.marks.MarkResult` with ``found``): angle, offset,
    length, then its loop and its image frame's distortion check, indented; after the last
    member of a family of lines, the family's line (:meth:`align.family.LineFamily.summary`)."""
    lines = [f"{r.image} mark {r.index}: angle {np.rad2deg(r.angle_rad):+.6f}° "
             f"± {r.angle_u_rad / ARCSEC:.2f}″, offset {r.offset_px:+.3f} px, "
             f"length {r.length_px:.0f} px, {'dark' if r.dark else 'bright'}"]
    lines += [f"    {line}" for line in r.loop.summary_lines()]
    if r.frame is not None:
        f = r.frame
        state = ("applied" if f.applied else "not significant" if f.consistent else
                 "LINES DISAGREE beyond one distortion: u inflated")
        lines.append(f"    frame ({f.n_lines} marks, one lens): k1 {f.k1:+.4g} ± "
                     f"{f.k1_u:.2g}, {state}")
    fam = getattr(r, "family", None)
    if fam is not None and r.index == max(fam.members):  # once, after its last member
        lines.append(f"    {fam.summary()} (marks {', '.join(map(str, fam.members))})")
    dial = getattr(r, "dial", None)
    if dial is not None and r.index == max(dial.members):
        lines.append(f"    {dial.summary()} (marks {', '.join(map(str, sorted(dial.members)))})")
    if r.lens and "parameters" in r.lens:
        par = r.lens["parameters"]
        fitted = [f"{k} {v['value']:+.4g}" for k, v in par.items() if v["applied"]]
        lines.append(f"    lens ({r.lens['lines']} marks, one lens): "
                     f"{', '.join(fitted) or 'nothing applied'}; not determined: "
                     f"{', '.join(k for k, v in par.items() if not v['determined']) or 'none'}")
    if r.u_terms:
        big = sorted(r.u_terms.items(), key=lambda kv: -kv[1])[:3]
        lines.append("    largest u terms: " + ", ".join(f"{k} {v / ARCSEC:.2f}″"
                                                       for k, v in big))
    lines += [f"    note: {n.removeprefix(f'{r.image} mark {r.index}: ')}" for n in r.notes
              if is_information(n)]
    if r.lens_limited:
        # What helps is the mark's own NOT OK note (align.lens_advice: it knows whether a
        # model was given and what limits it); an advice of its own here told a user who
        # had given --camera to calibrate the camera.
        lines += [f"    NOT OK: {n}" for n in r.lens_not_ok] or ["    NOT OK: lens-limited"]
    if r.bend_off_frame:
        lines.append("    NOT OK: a bent mark running off the image: its direction is not in it")
    if r.kinked:
        lines.append("    NOT OK: two grooves meeting at a kink: measure each part on its own")
    return lines


def camera_lines(model, field: dict | None = None) -> list[str]:
    """A chessboard camera calibration: views, reprojection RMS, intrinsics, distortion, the
    lens model chosen, and (``field``) what its own u leaves a typical mark's angle."""
    K, D, u = model.camera_matrix, model.dist_coeffs, model.u or {}
    lines = [f"{model.views} views, RMS reprojection {model.rms_px:.3f} px"]
    lines += [f"    {name}: RMS {rms:.3f} px"
              for name, rms in (model.per_view_rms_px or {}).items()]
    vals = dict(zip(("fx", "fy", "cx", "cy"), (K[0, 0], K[1, 1], K[0, 2], K[1, 2]),
                    strict=True))
    lines.append(" ".join(f"{k} {v:.2f} ± {u.get(k, np.nan):.2f}" for k, v in vals.items())
                 + " px")
    choice = model.lens_choice or {}
    carried = choice.get("carried_k3")
    lines.append("distortion " + " ".join(
        f"{k} left out (± {carried:.5f} carried)" if k == "k3" and carried is not None
        else f"{k} {v:+.5f} ± {u.get(k, np.nan):.5f}"
        for k, v in zip(("k1", "k2", "p1", "p2", "k3"), D[:5], strict=False)))
    if choice.get("why"):
        lines.append(f"k3 {choice['k3']}: {choice['why']}")
    if model.board_scale:
        lines.append(f"board {model.board_scale['board']}: {model.board_scale['why']}")
    views = model.views_one_camera or {}
    if views.get("tested"):
        lines.append(f"one camera: W = {views['W']:.1f} between the views' best split "
                     f"(p = {views['p']:.2g}, {views['splits']} splits; "
                     f"{'passed' if views['one_camera'] else 'NOT one camera'})")
    elif views:
        lines.append(f"one camera: not tested ({views['why']})")
    if field:
        lines.append(f"the model's own u in a {field['length_px']:.0f} px mark "
                     f"{field['radii_px'][0]:.0f}-{field['radii_px'][1]:.0f} px from the "
                     f"centre: {field['median_u_arcsec']:.0f}″ median, up to "
                     f"{field['max_u_arcsec']:.0f}″")
    return lines


# ----------------------------------------------------------------------------- calibration

def interval_lines(intervals: Sequence) -> list[str]:
    """The static intervals found in a recording: times [s], samples, mean and noise."""
    return [f"{len(intervals)} static intervals found:"] + [
        f"  {iv.start_s:9.2f}-{iv.end_s:9.2f} s ({iv.duration_s:6.1f} s, "
        f"{iv.samples} samples), mean {' '.join(f'{v:.6g}' for v in iv.mean)}, "
        f"noise {' '.join(f'{v:.3g}' for v in iv.std)}"
        + "".join(f"; {a:.2f}-{b:.2f} s left out (a disturbance, the attitude unchanged)"
                  for a, b in iv.left_out) for iv in intervals]


def calibration_lines(cal, n_poses: int, units: str, signs: Sequence[float],
                      fixture_error_deg: float) -> list[str]:
    """A triad calibration: the method, the table of k [unit/g], β [µrad], b [µg] (first
    estimate, refined, u), the loop's effects and the cross-check of both methods."""
    m, a = cal.model, cal.algebraic
    sign_note = ("negative" if all(s < 0 for s in signs) else "positive"
                 if all(s > 0 for s in signs) else "mixed")
    lines = [f"{n_poses} poses in {units}; scale-factor signs {tuple(signs)} ({sign_note}: "
             "from the face labels +x,-x,... when the poses carry them, else --scale-sign)"]
    if cal.method == "known-pose":
        kf = cal.known
        used = Counter(kf.faces)
        faces = ", ".join(f"{f} x{c}" if c > 1 else f for f, c in sorted(used.items()))
        lines.append(f"known-pose (six-position) method on faces {faces}: fixture error "
                     f"{fixture_error_deg:g}° declared; chi2 {kf.chi2:.3g} on {kf.dof} dof")
    elif cal.known is not None:
        lines.append("the six faces are among the poses: known-pose fit run too, cross-check "
                     "below")
    heads = (("algebraic (paper)", "ML refined") if cal.method == "ellipsoid"
             else ("known-pose (GLS)", "(the same)"))
    lines.append(f"{'':14s} {heads[0]:>22s} {heads[1]:>16s} {'u':>10s}")
    ku = OUTPUT_UNITS[units]
    sa, sm, su = a.sensitivity(), m.sensitivity(), m.sensitivity_u()
    for i, ax in enumerate("xyz"):  # per g along each sensitive axis (k_i |r_i|)
        lines.append(f"{f'k_{ax} [{ku}]':14s} {sa[i]:22.7f} {sm[i]:16.7f} {su[i]:10.2g}")
    u_beta, u_bias = m.u_per_axis("beta"), m.u_per_axis("bias")
    for i, ax in enumerate("xyz"):
        lines.append(f"{f'beta_{ax} [µrad]':14s} {a.beta[i] * 1e6:22.3f} "
                     f"{m.beta[i] * 1e6:16.3f} {u_beta[i] * 1e6:10.3g}")
    for i, ax in enumerate("xyz"):
        lines.append(f"{f'b_{ax} [µg]':14s} {a.bias[i] * 1e6:22.3f} {m.bias[i] * 1e6:16.3f} "
                     f"{u_bias[i] * 1e6:10.3g}")
    lines += ["  " + line for line in cal.effect_lines()]
    if cal.stability and cal.stability["assumed"]:
        lines.append("  scale stability: " + cal.stability["statement"])
    if getattr(cal, "nonlinearity", None) and cal.nonlinearity["statement"]:
        lines.append("  nonlinearity: " + cal.nonlinearity["statement"])
    if cal.cross_check:
        lines.append("cross-check ellipsoid vs known-pose (difference / combined u): "
                     + ", ".join(f"{n} {v['z']:+.1f}" for n, v in cal.cross_check.items()))
    return lines


def check_lines(checked) -> list[str]:
    """Check poses through a calibration: |a| - 1 [µg] and its z per pose."""
    return ["check poses |a| - 1 [µg]: " + " ".join(f"{d * 1e6:+.2f}" for d in checked.dg),
            "              z (/ u): " + " ".join(f"{z:+.2f}" for z in checked.z)]


def tilt_lines(res, method: str) -> list[str]:
    """Roll and pitch of readings: means [°], spreads [″], |a| - 1 [µg]."""
    s = res.to_dict()
    return [f"{s['samples']} readings ({method} roll, {s['frame']} frame): "
            f"roll {s['roll_deg_mean']:+.6f}° "
            f"(sd {s['roll_deg_std'] * 3600:.1f}″), pitch {s['pitch_deg_mean']:+.6f}° "
            f"(sd {s['pitch_deg_std'] * 3600:.1f}″), |a| - 1 mean "
            f"{s['norm_minus_1_ug']:+.2f} µg"]


def apply_lines(res) -> list[str]:
    """Readings taken to the platform frame: their count and mean specific force [g]."""
    return [f"{res.samples} readings -> platform frame; mean a = "
            + " ".join(f"{v:+.7f}" for v in res.mean_g) + " g"]


# ----------------------------------------------------------------------------- goniometer

def gonio_lines(run, faces: Sequence[str], nominal_rad: np.ndarray | None) -> list[str]:
    """A goniometer log: rows and revolutions used, exclusions, each face angle [°] ± u [″]
    (and its deviation from nominal), the loop's effects and notes."""
    summary, fa, loop = run.summary, run.angles, run.loop
    lines = [f"{summary.rows} rows, {fa.revolutions} revolutions used, "
             f"{fa.counts_per_rev:.2f} counts per revolution "
             f"({np.rad2deg(fa.quantum_rad) * 3600:.3f}″ a count)"]
    for reason, n in summary.exclusions.counts.items():
        where = ", ".join(map(str, summary.exclusions.lines[reason][:10]))
        lines.append(f"  {n} x {reason} (lines {where}{', ...' if n > 10 else ''})")
    if summary.incomplete_tail:
        lines.append(f"  last {summary.incomplete_tail} rows after the final reference pulse: "
                     "an incomplete revolution, not used")
    for i, name in enumerate(faces):
        nxt = faces[(i + 1) % len(faces)]
        dev = "" if nominal_rad is None else (
            f"  deviation {np.rad2deg(fa.angles_rad[i] - nominal_rad[i]) * 3600:+9.3f}″")
        lock = "  (quantisation locked: not averaged)" if fa.quantisation_locked[i] else ""
        lines.append(f"  {name:>6s} -> {nxt:<6s} {np.rad2deg(fa.angles_rad[i]):12.7f}° "
                     f"± {np.rad2deg(fa.u_rad[i]) * 3600:.3f}″{dev}{lock}")
    if loop is not None:
        lines += ["  " + line for line in loop.summary_lines()]
    lines += ["  " + note for note in run.notes]
    return lines


# ----------------------------------------------------------------------------- sessions

def session_lines(res) -> list[str]:
    """A session result: the misalignment E [″] ± u, the consistency of the instruments and
    the effects the fusion loop added. Its failed stages are its warnings (said once, by
    :func:`align.warnings.session_warnings`), not repeated here; the marks' information
    notes (:func:`align.warnings.mark_notes`) last, as ``note:`` lines."""
    notes = [f"  note: {n}" for n in mark_notes([r for _, r in res.marks])]
    f = res.fusion
    lines: list[str] = []
    if f is None:
        return lines + ["  no misalignment (the fusion did not run)"] + notes
    lines.append("  misalignment E [″] (row: accelerometer, column: platform X Y Z), sources: "
                 f"{', '.join(f.sources)}")
    for i in range(3):
        cells = ["0".rjust(17) if i == j else
                 f"{f.E[i, j] / ARCSEC:+9.2f} ± {f.E_u[i, j] / ARCSEC:5.2f}" for j in range(3)]
        lines.append(f"    {'xyz'[i]}: " + "  ".join(cells))
    state = ("consistent" if f.consistent else
             f"NOT consistent (uncertainty inflated x{f.inflation:.2f})" if f.inflation > 1 else
             "NOT consistent (structure left in the residual: see the fusion loop)")
    lines.append(f"  chi2 {f.chi2:.2f} / {f.dof} dof (p {f.p_value:.3g}): instruments {state}")
    for e in f.loop.effects:
        parts = (", ".join(f"{c} {v / ARCSEC:+.2f} ± {u / ARCSEC:.2f}″" for c, v, u in
                           e.components) if e.components
                 else f"{e.estimate / ARCSEC:+.2f} ± {e.u / ARCSEC:.2f}″")
        lines.append(f"  fusion loop added {e.name}: {parts} (p {e.p_value:.2g}, dBIC "
                     f"{e.delta_bic:.1f})")
    if f.loop.unexplained_structure:
        lines.append("  " + f.loop.summary_lines()[-1])
    return lines + notes


def timing_lines(timings: dict[str, float]) -> list[str]:
    """One short line per stage: its wall-clock time [s]."""
    return [f"  {stage}: {dt:.2f} s" for stage, dt in timings.items()]


def truth_lines(err: np.ndarray, z_rms: float) -> list[str]:
    """A synthetic session's error against its truth [″] and the RMS of error / u."""
    lines = ["  error against truth [″]:"]
    for i in range(3):
        lines.append("    " + "xyz"[i] + ": " + "  ".join(
            "0".rjust(8) if i == j else f"{err[i, j] / ARCSEC:+8.3f}" for j in range(3)))
    return lines + [f"  normalised errors (error / u): RMS {z_rms:.2f}"]


def batch_row_line(row) -> str | None:
    """One session of a batch (:class:`align.session.batch.BatchRow`): verdict, the largest
    |E| and u [″], chi2/dof, outputs; None when there is nothing to show."""
    outs = "".join(f", {k} {v}" for k, v in row.outputs.items())
    if row.e_max_arcsec is not None:
        return (f"{row.session}: {row.verdict or 'no verdict'}, "
                f"{'OK' if row.ok else 'FAILED stages'}, |E| max "
                f"{row.e_max_arcsec:.1f}″, u max {row.u_max_arcsec:.2f}″, chi2/dof "
                f"{row.chi2:.1f}/{row.dof}" + ("" if row.consistent else ", NOT consistent")
                + (" (complete before, skipped)" if row.skipped else "") + outs)
    if row.skipped:
        return f"{row.session}: complete before, skipped" + outs
    return None


def decision_lines(res: LoadedSession, budget: bool = False, plan: bool = False) -> list[str]:
    """A session result's verdict line (:mod:`align.decision`), and with ``budget`` its
    uncertainty budget, with ``plan`` what to measure next (:mod:`align.plan`)."""
    lines = ["  " + Disposition.from_dict(res.disposition).line()]
    if budget and res.budget:
        lines += ["  " + ln for ln in Budget.from_dict(res.budget).table_lines()]
    if plan and res.budget:
        lines += ["  " + ln for ln in plan_from_result(res).lines()]
    return lines


# ----------------------------------------------------------------------------- lot

def lot_lines(lot, doc: dict, tolerance_arcsec: float | None) -> list[str]:
    """A production lot: counts, then per angle its mean, control limits and capability."""
    lines = [f"lot: {len(lot.units)} session results ({len(lot.in_stats)} ok, in the "
             f"statistics), {len(lot.rejected)} files not read; run order {lot.run_order_note}"]
    for a in doc["angles"]:
        c, cap = a["control_chart"], a["capability"]
        line = f"  {a['name']}: n {a['n']}"
        if c is not None:
            line += (f", mean {a['mean_arcsec']:+.2f}″, σ_w {c['sigma_within_arcsec']:.2f}″, "
                     f"limits {c['lcl_arcsec']:+.2f} … {c['ucl_arcsec']:+.2f}″, "
                     f"{len(a['outside_limits'])} outside")
        if cap is not None:
            line += (f"; Cpk {cap['cpk']:.2f} ± {cap['cpk_u']:.2f}, "
                     f"{len(a['outside_tolerance'])} outside ±{tolerance_arcsec:g}″")
        lines.append(line)
    return lines


def verdict_lines(dispositions: Sequence[dict], rule: str | None) -> list[str]:
    """A lot's verdicts: the count of each, then one line per unit that did not pass."""
    verdicts = [d["verdict"] for d in dispositions]
    counts = ", ".join(f"{verdicts.count(v)} {v}" for v in dict.fromkeys(verdicts))
    lines = [f"  verdicts ({f'{rule} rule' if rule else 'each unit its own'}): {counts}"]
    return lines + [f"    {d['unit']}: {d['verdict']}: {d['reason']}" for d in dispositions
                    if d["verdict"] != "PASS"]
