"""What a result must warn its reader about, one function per result type.

The same lines go to the terminal (``WARNING: ...`` on stderr), into the JSON (``warnings``)
and at the top of the HTML report: a reader of any one of them learns that the result is not
to be taken at face value, and why.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import numpy as np

from align.gonio import nominal_mismatch
from align.loop import LoopReport, LoopSummary
from align.plan import plan
from axisbase.units import ARCSEC
from goniometry.exclusions import R_TAIL


def p_is(p: float) -> str:
    """``p = 0.0012``; a p below the smallest double (the test's tail underflowed) as
    ``p < 1e-300`` rather than an impossible ``p = 0``."""
    return f"p = {p:.2g}" if p > 0 else "p < 1e-300"


def loop_warnings(what: str, loop: LoopReport | LoopSummary | None) -> list[str]:
    """Unexplained structure left by a residual loop (run now, or loaded)."""
    if loop is None or not loop.unexplained_structure:
        return []
    s = loop.summary()
    return [f"{what}: unexplained structure remains in the residual ({s.structure_test}, "
            f"{p_is(s.structure_p)}): the model does not describe the data fully"]


def not_measured(r) -> str:
    """The warning of an image that was not measured (:class:`align.marks.MarkResult` not
    ``found``): in the JSON's warnings; the terminal says it once, as the image's error."""
    return f"{r.image}: not measured: {str(r.error).removeprefix(f'{r.image}: ')}"


HANDLED_CROSSING = re.compile(r" mark \d+: crossing with .*: \d+ px excluded \(the other "
                              r"groove lies in its profile window there\)$")
"""A crossing :func:`align.marks.finish_mark` handled: the stretch under the other groove left
out of the fit, the angle and its u from the rest (a crossing that cannot be handled so is
refused, as the mark's error). A note for the reader, not a warning: nothing is less to be
trusted (``tests/align/test_marks_crossing.py``)."""


def handled_crossing(note: str) -> bool:
    """Whether a mark's note is a handled crossing (:data:`HANDLED_CROSSING`)."""
    return HANDLED_CROSSING.search(note) is not None


INFORMATION = (
    HANDLED_CROSSING,
    # A lens the lines determine and need, applied; the principal point's range in u.
    re.compile(r": lens [\w, ]+ applied: the lines need it \(.*that range is carried in u$"),
    # A lens parameter whose sign the lines leave open: not applied, its range in u.
    re.compile(r": lens \w+ = \S+ ± \S+ from the lines: sign not determined; not applied, "
               r"carried in u$"),
    # A parameter of open sign fitted free with the angle (the smaller u of the two
    # readings, align/lens.py): its covariance in u, no lens applied.
    re.compile(r": lens \w+ fitted free with each angle \(.*\): the angle marginalised over "
               r"it \(u from the joint covariance, lens_fit\), smaller than carrying it over "
               r"its range$"),
    # Parameters the lines do not determine (the usual case of few marks): ranges in u.
    re.compile(r": lens [\w, ]+ not determined by these \d+ line\(s\): carried in u over "
               r"their plausible range$"),
    # Stripes found and divided out, what the removal may leave a Type B term of each mark.
    re.compile(r": (column|row) stripes in the background \(.*\): removed: each offset "
               r"estimated from the background away from the marks$"),
    # The stored image turned as its header says (as every viewer shows it). (A signed
    # image's offset stays a warning: that its zero means mid-scale is an assumption.)
    re.compile(r": orientation tag \d+ applied \([^)]*\)$"),
    # The user declared the image blurred after its pixels (align/grid_phase.py): in u.
    re.compile(r": blurred after the pixels \(declared\): .* carried in u as grid_phase$"),
    # A loop decision within its statistic's spread of the threshold (align/mark_choice.py):
    # the other side's reading carried by its chance, in u as model_choice.
    re.compile(r": the loop's decision on the edge of its test \(.*\): the angle is the "
               r"readings' average by weight, u carries the other reading \(model_choice .*\)$"),
)
"""Marks' notes that are information, not warnings: the tool did what the data called for
and u carries what is left, nothing for the user to act on and nothing less to be trusted.
They stay in each mark's JSON ``notes`` and are printed as ``note:`` lines; every other
note of a mark (a bent mark, a lens beyond any lens or disagreeing with its calibration,
JPEG blocks, a defocus gradient, stripes not removed, a misfit, a signed image's
offset, NOT OK) is a warning."""


def is_information(note: str) -> bool:
    """Whether a mark's note is information (:data:`INFORMATION`), not a warning."""
    return any(p.search(note) for p in INFORMATION)


def mark_notes(results: Sequence) -> list[str]:
    """The information notes of marks (``MarkResult``), each once, in order (the
    terminal's ``note:`` lines; the JSON keeps them in each mark's ``notes``)."""
    out: list[str] = []
    for r in results:
        out += [n for n in getattr(r, "notes", ()) if is_information(n) and n not in out]
    return out


def mark_warnings(results: Sequence) -> list[str]:
    """Marks (``MarkResult``): failures, unexplained structure, inflated uncertainty."""
    out = []
    seen: set[tuple[str, int]] = set()
    for r in results:
        what = f"{r.image} mark {r.index}"
        if r.unreported and (r.image, -1) not in seen:
            seen.add((r.image, -1))
            out.append(f"{r.image}: {r.unreported} more line(s) found and not reported "
                       "(beyond --max-marks, the strongest reported; or lines of a family "
                       "shorter than --min-length)")
        fam = getattr(r, "family", None)
        if fam is not None and (r.image, fam.members[0]) not in seen:
            seen.add((r.image, fam.members[0]))
            out += family_warnings(r.image, fam)
        dial = getattr(r, "dial", None)
        if dial is not None and (r.image, dial.members[0]) not in seen:
            seen.add((r.image, dial.members[0]))
            if not dial.uniform():
                out.append(f"{r.image}: dial of {len(dial.members)} lines: the lines do not "
                           f"meet at one point (p {dial.centre_p:.2g}) or are not evenly "
                           f"spaced (chi2/dof {dial.chi2_dof:.2f}, p {dial.p_value:.2g}) "
                           "within their u; the increment's u is widened by sqrt(chi2/dof)")
        if not r.found:
            out.append(not_measured(r))
            continue
        out += loop_warnings(what, r.loop)
        out += [n for n in getattr(r, "notes", ()) if n not in out and not is_information(n)]
        if r.uncertainty_inflation > 1:
            out.append(f"{what}: uncertainty inflated x{r.uncertainty_inflation:.2f} for the "
                       "structure no effect explains")
        elif r.uncertainty_inflation < 1:
            out.append(f"{what}: uncertainty scaled x{r.uncertainty_inflation:.2f} to the "
                       "centres' scatter: the groove model's shape does not fit this groove")
    return out


def family_warnings(image: str, fam) -> list[str]:
    """A family of lines (``align.family.LineFamily``): members not parallel, failed ones,
    steps of its ruling without a line."""
    out = []
    what = f"{image}: family of {len(fam.members)} lines (marks {fam.members[0]}..)"
    if fam.deviant:
        out.append(f"{what}: mark(s) {', '.join(map(str, fam.deviant))} not parallel to the "
                   "others beyond their u (a tilted or bent line)")
    if fam.p_value < 1e-3:  # the deviant members have their own line above
        out.append(f"{what}: angles disagree (chi2/dof {fam.chi2_dof:.2f}, p {fam.p_value:.2g})"
                   "; the family's angle u is widened by sqrt(chi2/dof)")
    if fam.failed:
        out.append(f"{what}: {fam.failed} member(s) found but not measured")
    gaps = getattr(fam, "missing_steps", ())
    if gaps:
        out.append(f"{what}: no line measured at step(s) {', '.join(map(str, gaps))} of its "
                   f"ruling (pitch {fam.pitch_px:.2f} px): a graduation missing, hidden or "
                   "not found; the family is not complete (not ok)")
    return out


def camera_warnings(skipped: Mapping[str, str], field: Mapping | None = None,
                    bound_arcsec: float = float("inf")) -> list[str]:
    """A chessboard calibration's warnings: each photograph left out, and why; and when the
    model's own u leaves typical marks (``field``: :func:`align.camera_model_u.field_u`)
    beyond the lens bound [″], that they will be lens-limited."""
    out = [f"{name}: skipped, not used in the calibration: {why}"
           for name, why in skipped.items()]
    if field and field["median_u_arcsec"] > bound_arcsec:
        out.append(f"camera: a {field['length_px']:.0f} px mark {field['radii_px'][0]:.0f}-"
                   f"{field['radii_px'][1]:.0f} px from the centre carries "
                   f"{field['median_u_arcsec']:.0f}″ (median; up to "
                   f"{field['max_u_arcsec']:.0f}″) from this calibration alone, beyond the "
                   f"lens bound {bound_arcsec:g}″: such marks will be lens-limited; more "
                   "chessboard views spread over the frame lower it (about as "
                   "1/sqrt(views))")
    return out


def calibration_warnings(cal, poses) -> list[str]:
    """A triad calibration (``Calibration``) and its poses."""
    out = list(getattr(cal, "problems", ())) + loop_warnings("calibration", cal.loop)
    out += [f"calibration: effect {r.name} REFUSED: {r.reason}" for r in cal.loop.refused]
    out += list(getattr(cal, "notes", ()))
    settled = getattr(poses, "settling", None)
    if settled is not None and settled.found:
        out.append(settled.statement())
    dof = cal.loop.after.dof
    if dof < 3:
        out.append(f"calibration: {len(poses.u)} poses leave {dof} degrees of freedom: the fit "
                   "is (nearly) exact, its residual proves nothing; add poses")
    if not cal.noise_known:
        out.append("calibration: noise unknown (per-pose means only): uncertainties from the "
                   "residual scatter, no chi2 test")
    return out


def gonio_warnings(run, faces: Sequence[str] | None = None, nominal_rad=None) -> list[str]:
    """A goniometer run (``GonioRun``); with the faces' names and nominal angles [rad], a
    nominal that does not describe the measured faces too."""

    out = loop_warnings("goniometer", run.loop)
    out += [f"goniometer: {w}" for w in run.warnings]

    # Noise's own tail in a long log is listed in the JSON's exclusions, not warned of.
    ex = {why: k for why, k in run.summary.exclusions.counts.items() if why != R_TAIL}
    if ex:
        out.append("goniometer: pulse faults (each repaired or its revolution excluded, as said): "
                   + ", ".join(f"{n} x {reason}" for reason, n in ex.items()))
    if nominal_rad is not None and faces is not None:
        out += [f"goniometer: {w}" for w in nominal_mismatch(run.angles.angles_rad,
                                                             nominal_rad, faces)]
    return out


SETUP_KEY = {
    "camera_roll": ("[cameras.{name}] roll_arcsec", "re-level the camera"),
    "reference_face_offset": ("[goniometer] reference_offset_arcsec", "re-set the reference face"),
    "platform_tilt": ("[platform] table_tilt_arcsec", "re-level the table"),
}
"""Per kind of set-up effect the fusion finds (by the effect's name): the session.toml key
that declares it and what else to do about it."""


def _arcsec(v: np.ndarray) -> str:
    """A declared or found value [rad] as session.toml takes it [″]: a number or [x, y]."""
    a = [f"{x / ARCSEC:+.1f}" for x in v]
    return a[0] if len(a) == 1 else f"[{', '.join(a)}]"


def _with_u(v: np.ndarray, u: np.ndarray, axes: Sequence[str]) -> str:
    """Values [rad] with their u in [″]; a vector's components named by axis."""
    parts = [f"{x / ARCSEC:+.1f} ± {s / ARCSEC:.1f}″" for x, s in zip(v, u, strict=True)]
    return parts[0] if len(parts) == 1 else ", ".join(
        f"{a} {p}" for a, p in zip(axes, parts, strict=True))


def setup_notice(e, declared: np.ndarray | None = None) -> str:
    """One set-up effect the fusion's loop found (an ``EffectReport``): every component with
    its u; on top of a declared value [rad], the declaration, the increment found and the
    total to declare (the loop's estimate is the increment: the declared set-up is applied
    before it)."""
    what = e.description or e.name
    if e.unit != "rad":
        return (f"set-up: the fusion found a {what} of {e.estimate:+.3g} ± {e.u:.2g} {e.unit} "
                f"({p_is(e.p_value)}) and corrected E for it; check the set-up against "
                "session.toml")
    if e.components:  # the components are named with their values
        what = what.removesuffix(" (x, y)")
    axes = [c for c, _, _ in e.components] or [""]
    found = np.array([v for _, v, _ in e.components] or [e.estimate])
    u = np.array([s for _, _, s in e.components] or [e.u])
    kind = next((k for k in SETUP_KEY if e.name.startswith(k)), None)
    if kind is None:
        return (f"set-up: the fusion found a {what} of {_with_u(found, u, axes)} "
                f"({p_is(e.p_value)}) and corrected E for it; check the set-up against "
                "session.toml")
    key, other = SETUP_KEY[kind]
    # camera_roll[A] -> A: the camera to name in the key
    key = key.replace("{name}", e.name.partition("[")[2].rstrip("]") or "NAME")
    dec = np.zeros_like(found) if declared is None else np.broadcast_to(declared, found.shape)
    if not np.any(dec):
        return (f"set-up: the fusion found a {what} of {_with_u(found, u, axes)} "
                f"({p_is(e.p_value)}) and corrected E for it; declare it ({key} = "
                f"{_arcsec(found)}) or {other}")
    total = dec + found
    return (f"set-up: the fusion found a {what}: declared {_arcsec(dec)}″, found "
            f"{_with_u(found, u, axes)} more ({p_is(e.p_value)}): it is "
            f"{_with_u(total, u, axes)}; E is corrected for it; declare that ({key} = "
            f"{_arcsec(total)}) or {other}")


def setup_notices(fusion, declared: Mapping[str, np.ndarray] | None = None) -> list[str]:
    """Set-up effects the fusion's loop found and corrected for (a camera's roll, the
    reference face's offset, the table's tilt): E is corrected, but the set-up is not what
    session.toml declares, and the reader must know (``FusionResult``, run or loaded).
    ``declared``: what session.toml declares, by effect name [rad]
    (``Session.declared_setup``), which each estimate is an increment on."""
    declared = declared or {}
    return [setup_notice(e, declared.get(e.name)) for e in fusion.loop.summary().effects]


CARRIED_PREFIX = "fusion: E's u carries "
"""How a carried candidate's note begins (the report shows these on its first screen)."""


def carried_notices(fusion) -> list[str]:
    """The candidates E's u carries as not excluded (:mod:`align.fusion.plausible`), each
    with the measurement that would resolve it (:func:`align.plan.plan`'s ``resolves``): the
    reader must know that part of u is an effect the data could not decide
    (``FusionResult``, run or loaded)."""
    b = fusion.budget
    if b is None or b.model is None or not b.model.held:
        return []
    p = plan(b.model)
    return [f"{CARRIED_PREFIX}{c.label}: {p.resolves[c.name]}" for c in p.carried]


def session_notes(res) -> list[str]:
    """What a reader of a session must know that is no alarm (``SessionResult``): the
    candidates E's u carries as not excluded, each with what would resolve it. Not among the
    warnings: a candidate at 2 u is carried in a few clean sessions in a hundred by design
    (the Type B term is part of u, like any budget line), and a warning there would be a
    false alarm (docs/false-alarms.md)."""
    return carried_notices(res.fusion) if res.fusion is not None else []


def session_warnings(res) -> list[str]:
    """A whole session (``SessionResult``): failed stages first, then every stage's own."""
    out = [f"stage {e.stage} FAILED: {e.message}" for e in res.errors]
    out += res.log_warnings
    if res.calibration is not None and res.calibration_poses is not None:
        out += calibration_warnings(res.calibration, res.calibration_poses)
    if res.gonio is not None:
        g = res.session.goniometer
        out += gonio_warnings(res.gonio, g.faces, g.nominal_rad)
    out += mark_warnings([r for _, r in res.marks])
    f = res.fusion
    if f is not None:
        out += setup_notices(f, res.session.declared_setup())
        out += loop_warnings("fusion", f.loop)
        u_e = np.sqrt(np.diag(f.cov))
        out += [m for c in f.undetermined if (m := c.message(u_e)) is not None]
        if f.inflation > 1:
            out.append(f"fusion: the instruments disagree beyond their uncertainties; E's "
                       f"uncertainty is inflated x{f.inflation:.2f}")
        if f.disagreement is not None and not f.gross:  # (gross: in the stage's error)
            widened = ", ".join(n for n, _, _ in f.disagreement.angles)
            out.append(f"fusion: {f.disagreement.message()}; the uncertainty of {widened} "
                       "is widened by the whole disagreement")
    return out
