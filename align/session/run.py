"""Run a whole session: calibration, goniometer, marks, platform static, fusion.

Each stage's failure is recorded (``StageError``) and the others go on; the fusion uses
whatever succeeded, and says so. A stage fails in one of two ways, the same for every stage:

* bad input (an :class:`~axisbase.errors.InputError`: a file, a key, an image) — the stage's
  error is its message, for the user to fix;
* anything else is a defect of the tool: an :class:`~axisbase.errors.InternalError` "internal
  error — please report" is recorded for that stage (``StageError.internal``), its traceback
  goes to the log, and the other stages still run.

``align run`` exits 1 when a stage hit an internal error, else 2 when one failed, else 0 —
as ``align marks`` does for its images. Nothing is written here: outputs are the caller's
business.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from align import problem_codes as pc
from align.apply import PlatformCalibration
from align.calibration import STATIC, Calibration, Poses, calibrate, r_matrix, read_poses
from align.calibration.files import ARRAY_SUFFIXES
from align.calibration.output import with_units
from align.calibration.stability import chosen_ppm
from align.calibration.static import StaticSettings, session_names
from align.calibration.triad import per_axis
from align.calibration.units import unit_scale_check, unit_source
from align.decision import Disposition, ToleranceSpec, decide, undecided
from align.errors import InputError
from align.fusion import (
    E_INDEX,
    Block,
    FusionResult,
    MarkObs,
    PlatformPose,
    ellipsoid_block,
    fuse,
    gonio_block,
    mark_block,
    static_block,
)
from align.fusion.observations import wrap_half
from align.fusion.solve import NOMINAL_LIMIT_DEG
from align.gonio import measure_log
from align.gonio_run import GonioRun
from align.grid_phase import with_grid_phase
from align.marks import MarkResult, measure_camera
from align.session.config import HOUSINGS, ImageEntry, Session
from align.tilt import FAR_FROM_1G
from align.warnings import session_notes, session_warnings
from axisbase.console import captured_warnings
from axisbase.errors import internal_error
from axisbase.header import header_units, resolve_units
from imaging import CameraModel

Progress = Callable[[str], None]
log = logging.getLogger("align.session")


@dataclass(frozen=True)
class StageError:
    """A stage that failed: its name, the message, and whether it was a defect of the tool
    (``internal``: "internal error — please report") rather than bad input."""

    stage: str
    message: str
    internal: bool = False


@dataclass
class SessionResult:
    """Everything a session produced (stage results are None when the stage failed or was not in
    the session).

    Attributes
    ----------
    session : Session
        The session as loaded; unit —.
    calibration : Calibration or None
        The triad's calibration (its fields carry units); unit —.
    calibration_poses : Poses or None
        The static poses it was made from, their readings in ``units``; unit —.
    gonio : GonioRun or None
        The goniometer log's face angles; unit —.
    marks : list of (ImageEntry, MarkResult)
        Each image measured; unit —.
    platform : list of PlatformPose
        The platform's static readings, calibrated [g].
    fusion : FusionResult or None
        The fused misalignment; unit —.
    errors : list of StageError
        Each failed stage; unit —.
    units : str
        The output unit of the triad's readings (``V``, ``g``, ...); unit —.
    timings : dict
        Wall-clock time of each stage [s] (in the order they ran).
    log_warnings : list of str
        Warnings the stages logged (e.g. how a file was read): they reach the JSON too; unit —.
    tolerance : ToleranceSpec or None
        The specification the disposition is judged against (session.toml's ``[tolerance]``
        unless the command line overrides it); unit —.
    """

    session: Session
    calibration: Calibration | None = None
    calibration_poses: Poses | None = None
    gonio: GonioRun | None = None
    marks: list[tuple[ImageEntry, MarkResult]] = field(default_factory=list)
    platform: list[PlatformPose] = field(default_factory=list)
    fusion: FusionResult | None = None
    errors: list[StageError] = field(default_factory=list)
    units: str = "V"
    timings: dict[str, float] = field(default_factory=dict)
    """Wall-clock time of each stage [s] (in the order they ran)."""
    log_warnings: list[str] = field(default_factory=list)
    """Warnings the stages logged (e.g. how a file was read): they reach the JSON too."""
    tolerance: ToleranceSpec | None = None
    """The specification the disposition is judged against (session.toml's ``[tolerance]``
    unless the command line overrides it)."""

    def __post_init__(self) -> None:
        if self.tolerance is None:
            self.tolerance = self.session.tolerance

    @property
    def internal_error(self) -> bool:
        """A stage hit a defect of the tool (exit status 1), not bad input."""
        return any(e.internal for e in self.errors)

    def disposition(self, d: dict | None = None) -> Disposition:
        """PASS / FAIL / INCONCLUSIVE / NOT MEASURED / NO TOLERANCE (:mod:`align.decision`);
        ``d``: :meth:`to_dict` when already at hand."""
        return decide(d if d is not None else self._core_dict(), self.tolerance)

    @property
    def fused(self) -> bool:
        """The fusion ran (a misalignment exists, perhaps from fewer sources than named)."""
        return self.fusion is not None

    @property
    def ok(self) -> bool:
        """Every stage the session names succeeded, the fusion ran and nothing in the
        result is untrusted (:attr:`problems`). A result that is not ok is still written
        (exit status 2)."""
        return self.fusion is not None and not self.errors and not self.problems

    @property
    def problems(self) -> list[str]:
        """Why a result that ran is still not a measurement to act on (empty: none) — the
        README's exit-2 cases beyond a failed stage: a calibration whose effects its poses
        cannot tell apart, a mark whose angle the uncalibrated lens limits, instruments that
        disagree beyond their uncertainties (E's u is then
        inflated or widened to cover the disagreement, but which instrument is right is the
        user's to find out), a toleranced angle a nuisance the data cannot determine leaves
        undecided."""
        return [text for _, text in self.problem_items()]

    @property
    def problem_codes(self) -> list[str]:
        """The code of each of :attr:`problems` (:mod:`align.problem_codes`), same order."""
        return [code for code, _ in self.problem_items()]

    def problem_items(self) -> list[tuple[str, str]]:
        """(code, text) of each problem (:attr:`problems`)."""
        out: list[tuple[str, str]] = []
        if self.calibration is not None and not self.calibration.ok:
            out += [(pc.CALIBRATION, f"calibration: {p}") for p in self.calibration.problems]
        if self.gonio is not None:
            out += [(pc.GONIOMETER, f"goniometer: {p}") for p in self.gonio.problems]
        for im, r in self.marks:
            if not r.found:
                continue  # a stage error already
            if r.lens_limited:
                # what helps as the mark's own note says it (a model given or not)
                out += [(pc.LENS_LIMITED, f"{im.file.name}: {n}") for n in r.lens_not_ok] or [
                    (pc.LENS_LIMITED, f"{im.file.name}: the angle is lens-limited")]
        f = self.fusion
        if f is not None and not f.gross and (not f.consistent or f.disagreement is not None):
            who = f"; {f.disagreement.message()}" if f.disagreement is not None else ""
            s = f.loop.summary()  # which test said so: chi2 alone may look fine
            seen = (f"{s.structure_test}, p = {s.structure_p:.2g}; " if s.structure_test
                    and s.structure_p is not None else "")
            out.append((pc.DISAGREEMENT, f"fusion: the instruments disagree beyond their "
                        f"uncertainties ({seen}chi2 {f.chi2:.4g} / {f.dof} dof){who}"))
        if f is not None and self.tolerance is not None and f.undetermined:
            out += [(pc.ANGLE_UNDECIDED, why) for why in _undecided(f, self.tolerance)]
        return out

    def platform_calibration(self) -> PlatformCalibration | None:
        """The triad model and the misalignment in one (what 'align apply' needs), when both
        the calibration and the fusion ran."""
        if self.fusion is None or self.calibration is None or self.fusion.gross:
            return None  # a gross disagreement's E is not a measurement: nothing to apply
        e6 = np.array([self.fusion.E[i, j] for i, j in E_INDEX])
        why = tuple(self.problems) + tuple(f"{e.stage}: {e.message}" for e in self.errors)
        return PlatformCalibration(self.calibration.model, e6, self.fusion.cov, why)

    def to_dict(self) -> dict:
        """The JSON contract of 'align run' (without its envelope): ok/fused, warnings,
        errors, metadata, the fusion's E with its covariance, observations and loop, the
        platform calibration, and each stage's own result. A session result is not loaded
        back whole (it needs the session's files); its parts are:
        :meth:`FusionResult.from_dict`, :meth:`PlatformCalibration.from_dict`."""
        d = self._core_dict()
        d["disposition"] = self.disposition(d).to_dict()
        return d

    def _core_dict(self) -> dict:
        items = self.problem_items()
        d: dict = {"session": self.session.name, "folder": str(self.session.folder),
                   "ok": self.ok, "fused": self.fused, "problems": [t for _, t in items],
                   "problem_codes": [c for c, _ in items],
                   "warnings": session_warnings(self),
                   "notes": session_notes(self),
                   "errors": [{"stage": e.stage, "message": e.message,
                               **({"internal": True} if e.internal else {})}
                              for e in self.errors],
                   "metadata": dict(self.session.metadata)}
        if self.fusion is not None:
            d.update(self.fusion.to_dict())
        pc = self.platform_calibration()
        if pc is not None:
            d["platform_calibration"] = pc.to_dict(self.units)
        stages: dict = {}
        if self.calibration is not None:
            stages["calibration"] = with_units(
                self.calibration.to_dict(self.calibration_poses), self.units)
        if self.gonio is not None:
            g = self.session.goniometer
            stages["goniometer"] = self.gonio.to_dict(g.faces, g.nominal_rad)
        if self.marks:
            stages["marks"] = [dict(r.to_dict(), housing=im.housing, view=im.view,
                                    nominal=im.nominal) for im, r in self.marks]
        d["stages"] = stages
        return d


def _try(res: SessionResult, stage: str, fn: Callable[[], object],
         where: str = "") -> object | None:
    """``fn()``, or None with the stage's failure recorded. Bad input is the user's to fix;
    anything else is a defect of the tool and is named as one, with its traceback in the log
    (the other stages still run, so nothing else is lost). An interruption (Ctrl-C, a stop
    signal) is not a stage's failure: it propagates."""
    start = time.perf_counter()
    try:
        return fn()
    except InputError as exc:
        res.errors.append(StageError(stage, f"{where}{exc}"))
    except Exception as exc:  # noqa: BLE001 - deliberate: one stage's defect, not the session's
        bug = internal_error(exc)
        log.error("stage %s: %s%s", stage, where, bug, exc_info=exc)
        res.errors.append(StageError(stage, f"{where}{bug}", internal=True))
    finally:
        dt = time.perf_counter() - start
        res.timings[stage] = res.timings.get(stage, 0.0) + dt
        log.debug("stage %s: %s%.3f s", stage, where, dt)
    return None


def run_session(s: Session, progress: Progress = lambda msg: None,
                alpha: float = 1e-3) -> SessionResult:
    """Run every stage of ``s`` and fuse; stage failures are collected, not raised.

    Parameters
    ----------
    s : Session
        A checked session (:func:`load_session`).
    progress : callable
        Called with a line of text as each stage starts.
    alpha : float
        Significance level of every stage's tests.

    Returns
    -------
    SessionResult
        Each stage's result (None where it failed, with the error in ``errors``), the
        fusion (E [rad] with its covariance) and the warnings.

    Examples
    --------
    A synthetic session folder (``synth.session``: images, counter log, tumble, platform
    poses, with its truth), run end to end:

    >>> import tempfile, pathlib
    >>> import numpy as np
    >>> from synth.session import SessionSpec, write_session
    >>> from align import load_session, run_session
    >>> folder = pathlib.Path(tempfile.mkdtemp()) / "unit"
    >>> truth = write_session(folder, SessionSpec(seed=3))
    >>> res = run_session(load_session(folder))
    >>> off = ~np.eye(3, dtype=bool)  # E's six angles (its diagonal is zero by definition)
    >>> z = (res.fusion.E - np.array(truth["misalignment_rad"]))[off] / res.fusion.E_u[off]
    >>> res.ok, bool(np.max(np.abs(z)) < 4)
    (True, True)
    """
    res = SessionResult(s)
    with captured_warnings() as logged:
        _run_stages(s, res, progress, alpha)
    res.log_warnings.extend(dict.fromkeys(logged))
    return res


def _run_stages(s: Session, res: SessionResult, progress: Progress, alpha: float) -> None:
    if s.calibration is not None:
        progress("calibration: ellipsoid fit over the static poses")
        c = s.calibration

        def _cal() -> Calibration:
            tk = c.table
            res.units = resolve_units(tk.units, [c.static] + ([c.check] if c.check else []),
                                      STATIC, tk.columns, ("ux", "uy", "uz"),
                                      flag="[calibration] units")
            left_out: list[str] = []
            res.calibration_poses, _ = read_poses(c.static, c.detection, columns=tk.columns,
                                                  rate_hz=tk.rate_hz, adc_range=c.adc_range,
                                                  time_unit=tk.time_unit,
                                                  warnings=left_out)
            ppm, default = chosen_ppm(c.scale_stability_ppm,
                                      res.calibration_poses.temp is not None)
            cal = calibrate(res.calibration_poses, c.scale_sign, alpha=alpha,
                            signs_as="[calibration] scale_sign", scale_stability_ppm=ppm,
                            stability_default=default, nonlinearity_bound=c.nonlinearity_bound)
            if left_out:
                cal = replace(cal, notes=(*cal.notes, *left_out))
            # Readings declared in g or m/s² must read ~1 g of that unit per g (as
            # `align calibrate` checks): a contradiction fails the stage, a stretch is warned.
            source = ("[calibration] units" if tk.units else unit_source(
                str(c.static), res.units, c.static.suffix.lower() not in ARRAY_SUFFIXES
                and header_units(c.static, STATIC, tk.columns, ("ux", "uy", "uz")) is not None))
            w = unit_scale_check(cal.model, res.units, source, "[calibration] units")
            return replace(cal, notes=(*cal.notes, *w)) if w else cal
        res.calibration = _try(res, "calibration", _cal)
    if s.goniometer is not None:
        g = s.goniometer
        progress(f"goniometer: {g.log.name}")
        res.gonio = _try(res, "goniometer", lambda: measure_log(
            g.log, len(g.faces), s.latitude_rad, g.direction, alpha, reverse_log=g.reverse_log,
            steady_table=g.steady_table, columns=g.columns,
            latitude_range_rad=s.latitude_range_rad, time_unit=g.time_unit,
            latency_max_s=g.latency_max_s, counters_sound=g.counters_sound))
    cams: dict[str, CameraModel | None] = {}
    for name, cam in s.cameras.items():
        cams[name] = (_try(res, f"camera {name}", lambda cam=cam: CameraModel.load(cam.model))
                      if cam.model is not None else None)
        res.errors += [StageError(f"camera {name}", f"{cam.model}: {w}")
                       for w in (cams[name].problems if cams[name] is not None else [])]
    # One lens per camera: every image of a camera enters one plumb-line fit (issue 18).
    by_cam: dict[str, list[int]] = {}
    for k, im in enumerate(s.images):
        by_cam.setdefault(s.views[im.view].camera, []).append(k)
    found_of: dict[int, list[MarkResult]] = {}
    done = 0
    for cname, idx in by_cam.items():
        def tick(j: int, idx=idx, done=done) -> None:
            progress(f"marks: {s.images[idx[j]].file.name} ({done + j + 1}/{len(s.images)})")

        cam_cfg = s.cameras.get(cname)
        got = _try(res, "marks", lambda idx=idx, cname=cname, cam_cfg=cam_cfg, tick=tick:
                   measure_camera([(s.images[k].file, s.images[k].roi) for k in idx],
                                  cams.get(cname), alpha=alpha, expect_one=True,
                                  ranges=cam_cfg.lens if cam_cfg is not None else None,
                                  label=cname, on_image=tick),
                   where=f"camera {cname}: ")
        if got is not None and cam_cfg is not None and cam_cfg.blur_after_pixels:
            got = [with_grid_phase(r) for r in got]  # declared: the grid's phase in u
        if got is not None:
            found_of.update(zip(idx, got, strict=True))
        done += len(idx)
    for k, im in enumerate(s.images):
        found = found_of.get(k)
        if found is None:  # its camera's stage error says why
            continue
        ok = [r for r in found if r.found]
        if len(ok) != 1:
            why = found[0].error if found and not ok else f"{len(ok)} marks found"
            kinked = [n for r in ok for n in r.notes if "measured as two lines" in n]
            if kinked:  # one groove with a kink: two lines, neither is the image's one mark
                why += f" ({kinked[0]})"
            res.errors.append(StageError("marks", f"{im.key} ({im.file.name}): {why}"))
            continue
        off = _off_nominal(s, im, ok[0])
        if off is not None:
            res.errors.append(StageError("marks", off))
            continue
        res.marks.append((im, ok[0]))
    if s.platform is not None and res.calibration is not None:
        progress("platform static readings")
        res.platform = _try(res, "platform static", lambda: _platform_poses(
            s, res.calibration, res.units)) or []
    elif s.platform is not None:
        res.errors.append(StageError("platform static", "not used: the calibration failed"))
    progress("fusion")
    failed = list(dict.fromkeys(e.stage for e in res.errors))
    blocks = observation_blocks(s, res)
    res.fusion = (_try(res, "fusion", lambda: fuse(blocks, alpha=alpha,
                                                   plausible_u=s.plausible_u()))
                  if blocks else None)
    if res.fusion is None and blocks and failed:  # say why a source is missing
        e = res.errors[-1]
        res.errors[-1] = StageError(e.stage, f"{e.message} (without the failed stage(s): "
                                             f"{', '.join(failed)})")
    if not blocks:
        res.errors.append(StageError("fusion", "no stage produced observations"))
    elif res.fusion is not None and res.fusion.gross:
        res.errors.append(StageError("fusion", res.fusion.gross_message()))


def _undecided(f: FusionResult, spec: ToleranceSpec) -> list[str]:
    """The problem lines of the toleranced angles the disposition cannot decide
    (:func:`align.decision.undecided`: a nuisance the data cannot determine sets their u)."""
    e6 = [float(f.E[i, j]) for i, j in E_INDEX]
    u6 = [float(f.E_u[i, j]) for i, j in E_INDEX]
    return [why for _, why in undecided(e6, u6, f.undetermined, spec)]


def _off_nominal(s: Session, im: ImageEntry, r: MarkResult) -> str | None:
    """The refusal of a mark far from its entry's nominal direction, or None."""
    nominal = 0.0 if im.nominal == "horizontal" else np.pi / 2
    dev = float(wrap_half(r.angle_rad - nominal - s.cameras[s.views[im.view].camera].roll_rad))
    if abs(dev) <= np.deg2rad(NOMINAL_LIMIT_DEG):
        return None
    return (f"{im.key} file = {im.file.name!r}: the mark is at {np.rad2deg(r.angle_rad):.2f}°, "
            f"{np.rad2deg(dev):+.1f}° from its declared nominal ({im.nominal}; a misalignment "
            "is arc-minutes): images swapped, or the entry's housing, view or nominal wrong")


def _axis_name(v: np.ndarray) -> str:
    i = int(np.argmax(np.abs(v)))
    return f"{'+' if v[i] > 0 else '-'}{'XYZ'[i]}"


def _check_attitudes(path, poses: Poses, ups: list[np.ndarray], a: np.ndarray,
                     units: str) -> None:
    """Refuse platform readings that are not 1 g after the calibration (another unit, another
    triad) or that point far from their pose's declared 'up' (a scale sign, a column, a pose's
    attitude), naming the poses."""
    norm = np.linalg.norm(a, axis=1)
    far = np.flatnonzero(np.abs(norm - 1) > FAR_FROM_1G)
    if far.size:
        i = int(far[0])
        raise InputError(
            f"{path}: pose {poses.labels[i]} reads |a| = {norm[i]:.4g} g after the calibration "
            f"(a static pose reads 1 g within ~1e-3){_more(poses, far)}: not in the "
            f"calibration's unit ({units})? check [platform] units, or the file is of another "
            "triad")
    cosang = np.array([a[k] @ ups[k] / norm[k] for k in range(len(a))])
    bad = np.flatnonzero(cosang < np.cos(np.deg2rad(NOMINAL_LIMIT_DEG)))
    if not bad.size:
        return
    i = int(bad[0])
    up = ups[i]
    ax = int(np.argmax(np.abs(up)))
    reads = ", ".join(f"{v:+.2f}" for v in a[i])
    if a[i][ax] * up[ax] < -0.5 * norm[i]:
        hint = (f"reads {a[i][ax]:+.2f} g on {'xyz'[ax]}: check [calibration] scale_sign (the "
                f"ellipsoid cannot tell a sign, the poses can), the sign of column "
                f"u{'xyz'[ax]}, or the pose's declared up")
    else:
        hint = (f"reads along {_axis_name(a[i]).lower()}: check the columns (ux, uy, uz) or "
                "the pose's declared up")
    raise InputError(
        f"{path}: platform pose {poses.labels[i]} declared up {_axis_name(up)} reads "
        f"({reads}) g, {np.degrees(np.arccos(np.clip(cosang[i], -1, 1))):.0f}° from its "
        f"declared attitude{_more(poses, bad)}; it {hint}")


def _more(poses: Poses, idx: np.ndarray) -> str:
    if len(idx) < 2:
        return ""
    return f" (so do {len(idx) - 1} more: {', '.join(poses.labels[k] for k in idx[1:])})"


def _platform_poses(s: Session, cal: Calibration, units: str) -> list[PlatformPose]:
    p = s.platform
    stated = resolve_units(p.table.units, [p.static], STATIC, p.table.columns,
                           ("ux", "uy", "uz"), flag="[platform] units", default=None)
    if stated is not None and stated != units:
        raise InputError(f"{p.static}: readings in {stated}, but the triad was calibrated "
                         f"from {units}: one triad, one unit")
    poses, _ = read_poses(p.static, StaticSettings(names=session_names("[platform]")),
                          calibration=False, columns=p.table.columns,
                          rate_hz=p.table.rate_hz, time_unit=p.table.time_unit)
    missing = [lab for lab in poses.labels if lab not in p.poses]
    if missing:
        raise InputError(f"{p.static}: pose(s) {', '.join(missing)} have no attitude in "
                         "session.toml [platform.poses]")
    absent = [lab for lab in p.poses if lab not in poses.labels]
    if absent:  # a declared attitude without data is a typo or a lost pose, never nothing
        raise InputError(f"session.toml [platform.poses]: {', '.join(absent)} not in "
                         f"{p.static} (its poses: {', '.join(poses.labels)})")
    if poses.sigma_u is None:
        raise InputError(f"{p.static}: needs >= 3 samples per pose (their scatter is the "
                         "readings' uncertainty)")
    m = cal.model
    R = r_matrix(m.beta)
    a = m.specific_force(poses.u, poses.t, poses.temp)
    _check_attitudes(p.static, poses, [p.poses[lab][0] for lab in poses.labels], a, units)
    # Calibrated per-axis readings w = R a_c = x - R b (see align.fusion.observations).
    w = a @ R.T
    u_w = poses.sigma_u / np.abs(m.k)
    return [PlatformPose(lab, p.poses[lab][0], p.poses[lab][1], w[i], u_w[i],
                         int(poses.count[i]))
            for i, lab in enumerate(poses.labels)]


def observation_blocks(s: Session, res: SessionResult) -> list[Block]:
    """The fusion's observation blocks from whatever stages of ``res`` succeeded."""
    blocks: list[Block] = []
    if res.marks:
        obs = []
        for im, r in res.marks:
            v = s.views[im.view]
            obs.append(MarkObs(f"{im.housing} in {im.view} ({im.file.name})",
                               HOUSINGS.index(im.housing), v.right, v.up, v.camera,
                               0.0 if im.nominal == "horizontal" else np.pi / 2,
                               r.angle_rad, r.angle_u_rad, s.cameras[v.camera].roll_rad,
                               im.file.name, im.view, r.lens_coupling, r.lens_group))
        blocks.append(mark_block(obs))
    if res.gonio is not None:
        g = s.goniometer
        fa = res.gonio.angles
        # The Type B terms are kept apart for the budget; a two-direction mean mixes both
        # logs' terms, so they stay inside the log's share there.
        tb = fa.type_b_terms if g.reverse_log is None else {}
        b = gonio_block(list(g.faces), fa.angles_rad, fa.cov, g.nominal_rad, g.direction,
                        g.reference_offset_rad, type_b=tb,
                        name=f"goniometer {g.log.name}")
        if b is not None:
            blocks.append(b)
    if res.calibration is not None:
        m = res.calibration.model
        if res.platform:
            blocks.append(ellipsoid_block(m.beta, m.cov_of(*per_axis("beta", "bias")), m.bias))
            blocks.append(static_block(res.platform, np.linalg.norm(r_matrix(m.beta), axis=1),
                                       s.platform.table_tilt_rad))
        else:
            blocks.append(ellipsoid_block(m.beta, m.cov_of(*per_axis("beta"))))
    return blocks
