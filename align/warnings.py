"""What a result must warn its reader about, one function per result type.

The same lines go to the terminal (``WARNING: ...`` on stderr), into the JSON (``warnings``)
and at the top of the HTML report: a reader of any one of them learns that the result is not
to be taken at face value, and why.
"""

from __future__ import annotations

from collections.abc import Sequence

from align.gonio import nominal_mismatch
from align.loop import LoopReport, LoopSummary
from goniometry.revolutions import R_TAIL


def loop_warnings(what: str, loop: LoopReport | LoopSummary | None) -> list[str]:
    """Unexplained structure left by a residual loop (run now, or loaded)."""
    if loop is None or not loop.unexplained_structure:
        return []
    s = loop.summary()
    return [f"{what}: unexplained structure remains in the residual ({s.structure_test}, "
            f"p = {s.structure_p:.2g}): the model does not describe the data fully"]


def mark_warnings(results: Sequence) -> list[str]:
    """Marks (``MarkResult``): failures, unexplained structure, inflated uncertainty."""
    out = []
    for r in results:
        what = f"{r.image} mark {r.index}"
        if not r.found:
            out.append(f"{r.image}: not measured: {str(r.error).removeprefix(f'{r.image}: ')}")
            continue
        out += loop_warnings(what, r.loop)
        if r.uncertainty_inflation > 1:
            out.append(f"{what}: uncertainty inflated x{r.uncertainty_inflation:.2f} for the "
                       "structure no effect explains")
        elif r.uncertainty_inflation < 1:
            out.append(f"{what}: uncertainty scaled x{r.uncertainty_inflation:.2f} to the "
                       "centres' scatter: the groove model's shape does not fit this groove")
    return out


def calibration_warnings(cal, poses) -> list[str]:
    """A triad calibration (``Calibration``) and its poses."""
    out = loop_warnings("calibration", cal.loop)
    out += [f"calibration: effect {r.name} REFUSED: {r.reason}" for r in cal.loop.refused]
    out += list(getattr(cal, "notes", ()))
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
        out += loop_warnings("fusion", f.loop)
        if f.inflation > 1:
            out.append(f"fusion: the instruments disagree beyond their uncertainties; E's "
                       f"uncertainty is inflated x{f.inflation:.2f}")
    return out
