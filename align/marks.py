"""The residual loop over a scribe-mark line fit, and the per-image result.

Declared model: the mark's centres lie on a straight line in the undistorted image. The lens
is a property of the camera, handled before the loop (:func:`camera_lens`, :mod:`align.lens`,
docs/camera.md): one lens for all marks of a frame (or of a camera's images in a session),
with identifiability first; what the lines do not determine is carried in u as named terms.
Candidate effects of the loop (each a few design columns with physical meaning):

* ``bent_mark`` — a bow across the mark the lens does not explain: named, and u widened to
  cover the straight fit vs the chord.
* ``periodic_wiggle`` — a sinusoid along the mark (vibration, rolling shutter) with at least
  2 periods along it; its period is searched on the residual's periodogram (counted as a
  searched parameter).
* ``illumination_gradient`` — a centre bias proportional to the local background slope across
  the mark (per unit contrast): lighting that is not even across the groove.

``radial_distortion`` (the old per-mark plumb-line k1) remains a :class:`MarkStage` term for
callers that pass it; :func:`measure_image` no longer offers it.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.errors import NotApplicable
from align.family import LineDial, LineFamily, line_dial, line_family, member_ends
from align.lens import (
    LensRanges,
    LineGeometry,
    angle_coupling,
    camera_coupling,
    check_camera,
    solve_lens,
)
from align.lens import (
    undistorted as lens_undistorted,
)
from align.loop import (
    Candidate,
    LoopReport,
    LoopSummary,
    StageFit,
    Term,
    periodogram_test,
    run_loop,
)
from axisbase.errors import internal_error
from imaging import (
    CameraModel,
    ImageInputError,
    MarkMeasurement,
    Roi,
    cross_magnification,
    defocus_note,
    fit_line,
    jpeg_note,
    line_frame,
    measure_frame,
    read_image_notes,
    undistort,
)
from imaging.lens import PARAMS

RADIAL = "radial_distortion"
WIGGLE = "periodic_wiggle"
ILLUM = "illumination_gradient"
BEND = "bent_mark"

log = logging.getLogger("align.marks")


def half_diagonal(shape: tuple[int, int]) -> float:
    h, w = shape
    return float(np.hypot(w - 1, h - 1) / 2)


K1_MAX = 0.3
"""Largest |k1| at the half-diagonal taken as a lens (30 % at the corner; beyond ~1/3 the
barrel model folds the image, so a larger fitted k1 means the lines do not constrain it)."""


class MarkStage:
    """Line fit along one mark, with extra terms (the stage the loop drives)."""

    def __init__(self, m: MarkMeasurement):
        self.m = m
        self.scale = half_diagonal(m.image_shape)
        ts = texture_scale(m)
        self.sigma = m.sigma * np.sqrt(ts)
        self.noise_dof = noise_dof(m, ts)

    def undistorted(self, k1: float, angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """The centres undistorted by k1 and their sigma across the line carried with them
        (:func:`imaging.cross_magnification` about the line at ``angle_rad``)."""
        if not k1:
            return self.m.points, self.sigma
        q = undistort(self.m.points, [k1], self.scale)
        g = cross_magnification(self.m.points, [k1], self.scale, line_frame(angle_rad)[1])
        if not np.all(np.isfinite(q)) or not np.all(g > 0):
            raise NotApplicable("k1 folds the image along this mark")
        return q, self.sigma * g

    def fit(self, terms: Sequence[Term]) -> StageFit:
        m = self.m
        names = [t.name for t in terms]
        k1, angle = 0.0, m.line.angle_rad
        rounds = 4 if RADIAL in names else 1
        for _ in range(rounds):
            q, sig = self.undistorted(k1, angle)
            cols = [(q**2).sum(1, keepdims=True) / self.scale**2 if t.name == RADIAL
                    else _bend_column(q, angle) if t.name == BEND
                    else np.asarray(t.columns, float).reshape(len(q), -1) for t in terms]
            F = np.hstack(cols) if cols else None
            lf = fit_line(q, sig, F, reject_sigma=None, chol=m.chol)
            angle = lf.angle_rad
            if RADIAL not in names:
                break
            j = self._col_index(terms, RADIAL)
            step = lf.beta[j] / lf.offset_px if lf.offset_px else np.inf
            if not np.isfinite(step) or abs(k1 + step) > K1_MAX:
                # No lens bends that much (and near the image centre k1 = bow / d runs away):
                # the fit stays where it is, and the estimate k1 + bow / d it reports is
                # refused by :func:`radial_admissible`.
                break
            k1 += step
        effects: dict[str, tuple[float, float]] = {}
        for t in terms:
            j = self._col_index(terms, t.name)
            cov = lf.cov[2 + j:2 + j + t.width, 2 + j:2 + j + t.width]
            b = lf.beta[j:j + t.width]
            if t.name == RADIAL:
                d = lf.offset_px
                effects[t.name] = (k1 + b[0] / d, float(np.sqrt(cov[0, 0])) / abs(d))
            elif t.name == BEND:
                # Sagitta of the fitted bow over the mark [px].
                half = np.ptp(q @ line_frame(angle)[0]) / 2
                effects[t.name] = (float(b[0]) * half**2, float(np.sqrt(cov[0, 0])) * half**2)
            elif t.name == WIGGLE:
                amp = float(np.hypot(*b))
                g = b / max(amp, 1e-300)
                effects[t.name] = (amp, float(np.sqrt(g @ cov @ g)))
            else:
                effects[t.name] = (float(b[0]), float(np.sqrt(cov[0, 0])))
        # Residuals as the loop's tests need them, independent under the model: whitened by
        # the centres' correlation when texture correlates them (z * sigma; the raw
        # residuals when the centres are independent).
        return StageFit(
            residuals=lf.z * lf.sigma_px, sigma=lf.sigma_px, n_params=2 + lf.beta.size,
            regressors={"t": m.regressors["t"], "r2": (q**2).sum(1),
                        "cross_slope": m.regressors["cross_slope"]},
            order="t", effects=effects,
            payload={"offset_px": lf.offset_px, "chord_rad": _chord_angle(q, lf, terms)},
            quantities={"angle_rad": (lf.angle_rad, lf.angle_u_rad),
                        "offset_px": (lf.offset_px, lf.offset_u_px)},
            noise_dof=self.noise_dof)

    @staticmethod
    def _col_index(terms: Sequence[Term], name: str) -> int:
        j = 0
        for t in terms:
            if t.name == name:
                return j
            j += t.width
        raise KeyError(name)


def texture_scale(m: MarkMeasurement) -> float:
    """Variance factor on a textured mark's centres from its own residuals (>= 1; 1 when the
    centres are independent).

    The replicas beside the mark give the shape of the texture's correlation, but a
    machining lay is a 1-D random profile: over the few hundred px of one mark its realised
    amplitude differs from the replicas' neighbouring stretches (chi2/dof up to ~1.9 on
    session images). The amplitude is re-read from the mark itself, on differences of
    neighbouring whitened residuals, which a smooth effect (a bow, a slow wiggle) hardly
    touches: var(z[i+1] - z[i]) = 2 for white z.
    """
    if m.chol is None or len(m.points) <= 10:
        return 1.0
    # Whitened both ways along the mark, and averaged: a Cholesky factor whitens causally
    # (each residual given the ones before it), so from the other end the whitened series
    # differs, and u would depend on which end the line starts from (the same pixels
    # rotated by 180 deg). The reversed series' correlation matrix is P R P (P the
    # reversal), factored again.
    z = fit_line(m.points, m.sigma, reject_sigma=None, chol=m.chol).z
    rev = np.linalg.cholesky((m.chol @ m.chol.T)[::-1, ::-1])
    zr = fit_line(m.points[::-1], m.sigma[::-1], reject_sigma=None, chol=rev).z
    return float(max(1.0, (np.mean(np.diff(z) ** 2) + np.mean(np.diff(zr) ** 2)) / 4))


def noise_dof(m: MarkMeasurement, scale: float) -> float | None:
    """Degrees of freedom of a textured mark's estimated centre covariance (None: the
    centres are independent with their Fisher sigma, nothing estimated).

    The correlation comes from the replicas (their spectrum estimate's equivalent dof); when
    :func:`texture_scale` re-read the amplitude from the mark (``scale`` > 1), that estimate
    adds its own relative variance: mean of squared neighbour differences of n white z has
    variance 3 / n relative, i.e. 2 n / 3 dof, and relative variances add (2/nu each).
    """
    tex = m.centres.texture
    if m.chol is None or tex is None or not np.isfinite(tex.dof):
        return None
    if scale <= 1.0:
        return float(tex.dof)
    return float(1.0 / (1.0 / tex.dof + 1.5 / max(len(m.points) - 1, 1)))


def _bend_column(q: np.ndarray, angle: float) -> np.ndarray:
    """A bow across the mark: (t - t_mid)^2 along it [px^2] (t_mid the middle of the
    span, so the column leaves the line through the chord's middle)."""
    t = q @ line_frame(angle)[0]
    return ((t - (t.min() + t.max()) / 2) ** 2)[:, None]


def _chord_angle(q: np.ndarray, lf, terms: Sequence[Term]) -> float:
    """Angle of the chord between the fitted curve's ends (the straight fit's angle when no
    bow is fitted): how a bent mark's direction is read end to end [rad]."""
    if not any(t.name == BEND for t in terms):
        return float(lf.angle_rad)
    j = MarkStage._col_index(terms, BEND)
    u, n = line_frame(lf.angle_rad)
    t = q @ u
    tm = (t.min() + t.max()) / 2
    ends = [(lf.offset_px + lf.beta[j] * (te - tm) ** 2) for te in (t.min(), t.max())]
    return float(lf.angle_rad - (ends[1] - ends[0]) / (t.max() - t.min()))


def _bend(fit: StageFit) -> Term:
    return Term(BEND, "px (sagitta)", np.zeros((fit.n, 1)))


def _radial(fit: StageFit) -> Term:
    return Term(RADIAL, "1 (k1 at the image half-diagonal)", np.zeros((fit.n, 1)))


def _wiggle(fit: StageFit) -> Term | None:
    t = np.asarray(fit.regressors["t"], float)
    test, omega = periodogram_test(fit.residuals / fit.sigma, t)
    if not np.isfinite(omega) or 2 * np.pi / omega > np.ptp(t) / 2:
        # Fewer than 2 periods along the mark: a slow bow is no wiggle (it is a bend or a
        # lens, told apart elsewhere).
        return None
    # Independent frequencies searched (up to the Nyquist of the point spacing): ~ n / 2.
    m_indep = max(1.0, 0.5 * (len(t) - 1))
    return Term(WIGGLE, "px", np.column_stack([np.sin(omega * t), np.cos(omega * t)]),
                searched=1, trials=m_indep, meta={"period_px": 2 * np.pi / omega})


def _illum(fit: StageFit) -> Term | None:
    g = np.asarray(fit.regressors["cross_slope"], float)
    if np.ptp(g) == 0:
        return None
    return Term(ILLUM, "px^2", (g - g.mean())[:, None])


def radial_admissible(current: StageFit, trial: StageFit, term: Term, alpha: float = 1e-3
                      ) -> str | None:
    """Why a significant ``radial_distortion`` cannot be a lens here (None: it can).

    A radial distortion bows a line by k1 d (r/R)^2: a mark through the principal point
    (d ~ 0) is imaged straight whatever k1, so its bow says nothing about k1 (u(k1) =
    u(bow) / |d|). The line identifies k1 only if the largest lens k1 (:data:`K1_MAX`) would
    stand out of u(k1) at the loop's level alpha (two-sided normal quantile); otherwise a
    significant bow is something else (a bent mark), never a distortion. Likewise an
    estimate beyond K1_MAX is no lens.
    """
    if term.name != RADIAL:
        return None
    k1, u = trial.effects.get(RADIAL, (float("nan"), float("inf")))
    d = float(trial.payload["offset_px"]) if isinstance(trial.payload, dict) else float("nan")
    z = float(np.sqrt(special.chdtri(1, alpha)))
    if not u * z <= K1_MAX:
        return (f"k1 not identifiable on this mark: it passes {abs(d):.2g} px from the image "
                f"centre, where a radial distortion leaves a line straight (u(k1) = {u:.2g}; "
                f"even the largest lens k1 {K1_MAX} would not stand out of it)")
    if not abs(k1) <= K1_MAX:
        return (f"k1 = {k1:.3g} is beyond any lens (|k1| <= {K1_MAX} at the half-diagonal): "
                "a bow that large is a bent mark, not distortion")
    return None


RADIAL_CANDIDATE = Candidate(
    RADIAL, "1", "curvature across the mark growing with distance from the image centre: "
    "lens radial distortion (plumb-line k1) or a bent mark", _radial)
"""The old per-mark k1 (kept for :class:`MarkStage` users; :func:`measure_image` handles the
lens per camera before the loop, :mod:`align.lens`)."""

CANDIDATES: tuple[Candidate, ...] = (
    Candidate(BEND, "px", "a bow across the mark the camera's lens does not explain: a bent "
              "mark (or a lens the model lacks)", _bend),
    Candidate(WIGGLE, "px", "periodic wiggle along the mark (vibration / rolling shutter)",
              _wiggle),
    Candidate(ILLUM, "px^2", "centre bias following the local illumination slope across the "
              "mark", _illum),
)


@dataclass(frozen=True)
class FrameDistortion:
    """One radial distortion shared by all marks of a frame (joint weighted plumb-line fit), as
    results written before the lens moved to :mod:`align.lens` saved it (read back only).

    Attributes
    ----------
    k1 : float
        Radial distortion at the image half-diagonal — dimensionless.
    k1_u : float
        Its standard uncertainty — dimensionless.
    applied : bool
        It was significant, explained the lines, and the marks were undistorted with it;
        unit —.
    consistent : bool
        The lines are straight within their uncertainties once it is removed (False: the lines
        disagree in a way no single radial distortion explains — bent marks, or lines that are
        not straight in the world — and every mark's u is inflated by sqrt(chi2/dof)); unit —.
    n_lines : int
        Marks in the fit — dimensionless.
    chi2_dof_before, chi2_dof_after : float
        All lines' straightness, χ²/dof — dimensionless.
    p_value : float
        Of the k1 = 0 test — dimensionless.
    """

    k1: float
    k1_u: float
    applied: bool
    consistent: bool
    n_lines: int
    chi2_dof_before: float
    chi2_dof_after: float
    p_value: float

    def to_dict(self) -> dict:
        return {"k1": self.k1, "k1_u": self.k1_u, "applied": self.applied,
                "consistent": self.consistent, "lines": self.n_lines,
                "chi2_dof_before": self.chi2_dof_before,
                "chi2_dof_after": self.chi2_dof_after, "p_value": self.p_value}

    @classmethod
    def from_dict(cls, d: Mapping) -> FrameDistortion:
        """From :meth:`to_dict`'s keys (a non-finite number is saved as null)."""
        return cls(_num(d["k1"]), _num(d["k1_u"]), bool(d["applied"]), bool(d["consistent"]),
                   int(d["lines"]), _num(d["chi2_dof_before"]), _num(d["chi2_dof_after"]),
                   _num(d["p_value"]))


def _num(v: object) -> float:
    """A saved float: strict JSON writes NaN and ±inf as null, read back as NaN."""
    return float("nan") if v is None else float(v)  # type: ignore[arg-type]


@dataclass(frozen=True)
class MarkResult:
    """One mark (or one failure) of one image.

    Attributes
    ----------
    image : str
        The image file; unit —.
    found : bool
        A mark was measured (else ``error`` says why); unit —.
    error : str or None
        Why not; unit —.
    index : int
        The mark's index in its image — dimensionless.
    angle_rad, angle_u_rad : float
        The mark's angle in the image and its standard uncertainty [rad].
    offset_px, offset_u_px : float
        Its distance from the image centre and its standard uncertainty [px].
    length_px : float
        Its length, between the groove's half-depth ends [px].
    width_px : float
        Its width [px].
    blur_px : float
        The edge blur [px].
    dark : bool
        A dark groove on a bright surface (else bright); unit —.
    n_points : int
        Centre points fitted — dimensionless.
    n_rejected : int
        Centre points rejected — dimensionless.
    angle_before_rad : float
        The angle of the declared model, before the loop [rad].
    loop : LoopReport or LoopSummary or None
        The residual loop's report; unit —.
    measurement : MarkMeasurement or None
        The raw measurement (not saved); unit —.
    uncertainty_inflation : float
        Factor on u for structure no effect explains — dimensionless.
    internal_error : bool
        The failure was a defect of the tool; unit —.
    frame : FrameDistortion or None
        The frame's shared distortion (older results); unit —.
    family : LineFamily or None
        The family of parallel lines it belongs to; unit —.
    unreported : int
        Lines found in the image and not reported — dimensionless.
    dial : LineDial or None
        The graduated dial (lines meeting at a point) it belongs to; unit —.
    lens : Mapping or None
        The camera's lens as used (source, parameters fitted or carried; dimensionless, pp in
        [px]).
    u_terms : Mapping
        Named contributions to ``angle_u_rad`` [rad].
    notes : tuple of str
        What the reader must know; unit —.
    lens_limited : bool
        The lens terms of u exceed the limit: not ok, calibrate the camera; unit —.
    lens_coupling : Mapping
        The lens terms of u as signed components on the lens's error directions [rad]
        (:func:`align.lens.angle_coupling`).
    lens_group : str
        The lens solve the mark shares with others (marks of one group share the lens's
        error); unit —.
    """

    image: str
    found: bool
    error: str | None = None
    index: int = 0
    angle_rad: float = float("nan")
    angle_u_rad: float = float("nan")
    offset_px: float = float("nan")
    offset_u_px: float = float("nan")
    length_px: float = float("nan")
    width_px: float = float("nan")
    blur_px: float = float("nan")
    dark: bool = True
    n_points: int = 0
    n_rejected: int = 0
    angle_before_rad: float = float("nan")
    loop: LoopReport | LoopSummary | None = None
    measurement: MarkMeasurement | None = None
    uncertainty_inflation: float = 1.0
    internal_error: bool = False
    frame: FrameDistortion | None = None
    family: LineFamily | None = None
    unreported: int = 0
    dial: LineDial | None = None
    lens: Mapping | None = None
    u_terms: Mapping[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    lens_limited: bool = False
    # The lens terms of u as signed components [rad] and the lens solve they belong to:
    # marks of one group share the lens's error (align.lens.angle_coupling).
    lens_coupling: Mapping[str, float] = field(default_factory=dict)
    lens_group: str = ""

    @property
    def unexplained_structure(self) -> bool:
        return bool(self.loop and self.loop.unexplained_structure)

    def to_dict(self) -> dict:
        """The mark as ``align marks --json`` and a session's ``stages.marks`` save it:
        angles in degrees (and radians, exact), the loop's summary
        (:meth:`align.loop.LoopSummary.to_dict`), the frame's shared distortion."""
        d: dict = {"image": self.image, "found": self.found, "error": self.error}
        if self.internal_error:
            d["internal_error"] = True
        if self.unreported:
            d["lines_not_reported"] = self.unreported
        if not self.found:
            return d
        d.update({
            "index": self.index, "angle_deg": float(np.rad2deg(self.angle_rad)),
            "angle_u_deg": float(np.rad2deg(self.angle_u_rad)),
            "angle_u_arcsec": float(np.rad2deg(self.angle_u_rad) * 3600),
            "angle_rad": self.angle_rad, "angle_u_rad": self.angle_u_rad,
            "offset_px": self.offset_px, "offset_u_px": self.offset_u_px,
            "length_px": self.length_px, "width_px": self.width_px, "blur_px": self.blur_px,
            "polarity": "dark" if self.dark else "bright", "points": self.n_points,
            "rejected_points": self.n_rejected,
            "angle_before_loop_deg": float(np.rad2deg(self.angle_before_rad)),
            "angle_before_loop_rad": self.angle_before_rad,
            "effects": [], "unexplained_structure": self.unexplained_structure,
            "uncertainty_inflation": self.uncertainty_inflation,
        })
        if self.frame is not None:
            d["frame_radial_distortion"] = self.frame.to_dict()
        if self.family is not None:
            d["family"] = self.family.to_dict()
        if self.dial is not None:
            d["dial"] = self.dial.to_dict()
        if self.lens is not None:
            d["lens"] = dict(self.lens)
        d["angle_u_terms_arcsec"] = {k: float(np.rad2deg(v) * 3600)
                                     for k, v in self.u_terms.items()}
        d["angle_u_terms_rad"] = {k: float(v) for k, v in self.u_terms.items()}
        d["notes"] = list(self.notes)
        d["lens_limited"] = self.lens_limited
        if self.lens_coupling:
            d["lens_group"] = self.lens_group
            d["angle_lens_coupling_rad"] = {k: float(v) for k, v in self.lens_coupling.items()}
        if self.loop:
            s = self.loop.summary()
            d.update(s.to_dict())
            d["residual_rms_px"] = {"before": s.rms_before, "after": s.rms_after}
            d["chi2_dof"] = {"before": s.chi2_dof_before, "after": s.chi2_dof_after}
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> MarkResult:
        """From :meth:`to_dict`'s keys. What is not saved comes back None: the measurement,
        and the full loop (its saved part is an :class:`align.loop.LoopSummary`, which
        answers ``effects``, ``unexplained_structure`` and ``summary_lines()`` alike)."""
        base = {"image": str(d["image"]), "found": bool(d["found"]),
                "error": None if d.get("error") is None else str(d["error"]),
                "internal_error": bool(d.get("internal_error", False)),
                "unreported": int(d.get("lines_not_reported", 0))}
        if not base["found"]:
            return cls(**base)

        def rad(key: str) -> float:  # radians saved exactly; degrees from older files
            return _num(d[key + "_rad"]) if key + "_rad" in d else np.deg2rad(
                _num(d[key + "_deg"]))

        fr = d.get("frame_radial_distortion")
        return cls(**base, index=int(d["index"]), angle_rad=rad("angle"),
                   angle_u_rad=rad("angle_u"), offset_px=_num(d["offset_px"]),
                   offset_u_px=_num(d["offset_u_px"]), length_px=_num(d["length_px"]),
                   width_px=_num(d["width_px"]), blur_px=_num(d["blur_px"]),
                   dark=d.get("polarity", "dark") == "dark", n_points=int(d["points"]),
                   n_rejected=int(d.get("rejected_points", 0)),
                   angle_before_rad=rad("angle_before_loop"),
                   loop=LoopSummary.from_dict(d) if "loop" in d else None,
                   uncertainty_inflation=_num(d.get("uncertainty_inflation", 1.0)),
                   frame=None if fr is None else FrameDistortion.from_dict(fr),
                   family=LineFamily.from_dict(d["family"]) if "family" in d else None,
                   dial=LineDial.from_dict(d["dial"]) if "dial" in d else None,
                   lens=d.get("lens"),
                   u_terms={str(k): _num(v)
                            for k, v in (d.get("angle_u_terms_rad") or {}).items()},
                   notes=tuple(str(n) for n in d.get("notes", ())),
                   lens_limited=bool(d.get("lens_limited", False)),
                   lens_coupling={str(k): _num(v) for k, v in
                                  (d.get("angle_lens_coupling_rad") or {}).items()},
                   lens_group=str(d.get("lens_group", "")))


def loop_mark(m: MarkMeasurement, image: str = "", index: int = 0, alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES) -> MarkResult:
    """Run the residual loop over one measured mark."""
    rep = run_loop(MarkStage(m), candidates, alpha=alpha,
                   admissible=functools.partial(radial_admissible, alpha=alpha))
    a, au = rep.after.quantities["angle_rad"]
    d, du = rep.after.quantities["offset_px"]
    infl = structure_inflation(rep)
    au, du = au * infl, du * infl
    terms: dict[str, float] = {}
    notes: list[str] = []
    f = rep.after
    if m.jpeg is not None:  # a Type B term: how far the blocks move this groove's angle
        terms["jpeg_blocks"] = m.jpeg_u_rad
        au = float(np.hypot(au, m.jpeg_u_rad))
        notes.append(jpeg_note(f"{image} mark {index}", m.jpeg,
                               float(np.rad2deg(m.jpeg_u_rad) * 3600)))
    defocus = defocus_note(f"{image} mark {index}", m.blur)
    if defocus:
        notes.append(defocus)
    elif f.dof > 0 and special.chdtr(f.dof, f.chi2) < 1e-6:
        notes.append(f"{image} mark {index}: the centres scatter far less than their stated "
                     f"sigma (chi2/dof {f.chi2 / f.dof:.2f}): the groove model does not fit "
                     "this groove; u kept as stated (a misfit never narrows it)")
    bend = next((e for e in rep.effects if e.name == BEND), None)
    if bend is not None:
        # A bent mark has no one direction: its straight fit and its end-to-end chord differ,
        # and which one the user means is not in the image. Cover both: the difference
        # (and the angle without the bow term) enter u.
        chord = float(rep.after.payload["chord_rad"])
        a0 = rep.before.quantities["angle_rad"][0]
        terms["bent_mark_chord_vs_fit"] = float(max(abs(_wrap(chord - a)), abs(_wrap(a0 - a))))
        notes.append(f"{image} mark {index}: the mark is bent (sagitta {bend.estimate:+.3g} ± "
                     f"{bend.u:.2g} px) and the lens does not explain the bow: its direction "
                     "is ambiguous (straight fit vs chord), u widened to cover both")
        au = float(np.hypot(au, terms["bent_mark_chord_vs_fit"]))
    return MarkResult(
        image=image, found=True, index=index, angle_rad=a, angle_u_rad=au, offset_px=d,
        offset_u_px=du, length_px=m.length_px, width_px=m.profile.width_px,
        blur_px=m.profile.blur_px, dark=m.candidate.dark, n_points=len(m.points),
        n_rejected=m.n_rejected, angle_before_rad=rep.before.quantities["angle_rad"][0],
        loop=rep, measurement=m, uncertainty_inflation=infl, u_terms=terms,
        notes=tuple(notes))


def _wrap(a: float) -> float:
    return float((a + np.pi / 2) % np.pi - np.pi / 2)


def structure_inflation(rep: LoopReport, alpha_low: float = 1e-6) -> float:
    """Factor on the stated uncertainty when the residual keeps unexplained structure.

    Never below 1: an improbably small chi2 (lower tail below ``alpha_low``) is a groove
    model that does not fit, not a licence to shrink u.

    Correlated residuals carry less information than independent ones: with lag-1
    correlation rho the variance of a fitted slope grows by about (1 + rho) / (1 - rho)
    (AR(1) noise), and an excess chi2/dof scales it further. 1 for a clean fit.
    """
    f = rep.after
    if f.dof > 0 and special.chdtr(f.dof, f.chi2) < alpha_low:
        # The centres scatter far less than their stated sigma: the groove model's shape
        # does not describe this groove. A model misfit never narrows u (a defocus gradient
        # once got x0.4 here and scattered at twice its u): u stays as stated, and the
        # misfit is reported (warnings).
        return 1.0
    if not rep.unexplained_structure:
        return 1.0
    z = (f.residuals / f.sigma)[np.argsort(f.regressors[f.order])]
    zc = z - z.mean()
    rho = float(np.clip(zc[1:] @ zc[:-1] / max(zc @ zc, 1e-300), 0.0, 0.9))
    return float(np.sqrt(max(1.0, f.chi2 / max(f.dof, 1)) * (1 + rho) / (1 - rho)))


def lens_lines(ms: Sequence[MarkMeasurement]) -> list[LineGeometry]:
    """The marks as the lens solver sees them (sigma with the texture's re-read scale)."""
    return [LineGeometry(m.points, m.sigma * np.sqrt(texture_scale(m)), m.chol) for m in ms]


def camera_lens_u(camera: CameraModel, shape: tuple[int, int]) -> np.ndarray:
    """A calibration's standard uncertainties (``align camera``'s ``u``) as the lens vector's
    (:data:`imaging.lens.PARAMS`: k1, k2, p at the half-diagonal, aspect, principal point)."""
    u = camera.u or {}
    R = half_diagonal(shape)
    fx, fy = float(camera.camera_matrix[0, 0]), float(camera.camera_matrix[1, 1])
    a = R / fx

    def g(k: str) -> float:
        v = float(u.get(k, 0.0))
        return v if np.isfinite(v) else 0.0

    return np.array([g("k1") * a**2, g("k2") * a**4, g("p1") * a, g("p2") * a,
                     np.hypot(g("fx") / fx, g("fy") / fy) * fy / fx, g("cx"), g("cy")])


@dataclass(frozen=True)
class CameraLens:
    """What the lens of one camera adds to each of its marks: the lens vector applied to the
    centres before the loop (None: nothing; a camera model already undistorted them), the
    named angle-u terms per mark [rad], the notes, the saved dict; ``coupling``: each
    mark's terms as signed components on the lens's error directions (shared by every mark
    of this lens, :func:`align.lens.angle_coupling`).

    The terms are the coupling's sizes: a term is the root sum of squares of its components
    (``lens_fit.0``, ``lens_fit.1``, ... for a fitted lens's covariance, one each else)."""

    lam: np.ndarray | None
    notes: tuple[str, ...]
    record: Mapping
    max_u_rad: float
    coupling: tuple[dict[str, float], ...] = ()
    model_as: str = "--camera"
    """How the user gives this camera a model: the flag, or session.toml's key."""

    @property
    def terms(self) -> tuple[dict[str, float], ...]:
        """Named standard uncertainties [rad] per mark (the coupling's sizes per term)."""
        return tuple(_term_sizes(c) for c in self.coupling)


def _term_sizes(coupling: Mapping[str, float]) -> dict[str, float]:
    """Root sum of squares per term name (``lens_fit.0`` and ``lens_fit.1`` are ``lens_fit``)."""
    out: dict[str, float] = {}
    for k, v in coupling.items():
        name = k.split(".")[0]
        out[name] = float(np.hypot(out.get(name, 0.0), v))
    return out


def camera_lens(ms: Sequence[MarkMeasurement], camera: CameraModel | None = None,
                ranges: LensRanges | None = None, alpha: float = 1e-3, label: str = ""
                ) -> CameraLens:
    """:func:`_camera_lens`; ``label`` names a session's camera (its messages then name
    session.toml's ``[cameras.LABEL] model``, not ``--camera``)."""
    lens = _camera_lens(ms, camera, ranges, alpha, label)
    return replace(lens, model_as=f"[cameras.{label}] model") if label else lens


def _camera_lens(ms: Sequence[MarkMeasurement], camera: CameraModel | None = None,
                 ranges: LensRanges | None = None, alpha: float = 1e-3, label: str = ""
                 ) -> CameraLens:
    """The lens of one camera from all its marks ``ms`` (one frame, or all its images).

    Without a camera model: identifiability, then the determined parameters fitted jointly
    and the rest carried in u (:func:`align.lens.solve_lens`). With one: the model *is* the
    lens (the centres are already undistorted by it); its u is propagated into every angle,
    nothing is fitted on top, and marks that disagree with it beyond their u are a warning
    naming the camera, the disagreement added to u.
    """
    ranges = ranges or LensRanges()
    max_u = ranges.max_u_arcsec * np.pi / 180 / 3600
    if not ms:
        return CameraLens(None, (), {}, max_u)
    shape = ms[0].image_shape
    R = half_diagonal(shape)
    lines = lens_lines(ms)
    who = f"camera {label}" if label else "camera"
    if camera is None and not np.any(ranges.vector()):
        # Declared distortion-free: nothing to determine, nothing to carry.
        return CameraLens(None, (),
                          {"source": "declared distortion-free", "lines": len(ms),
                           "ranges": ranges.to_dict()}, max_u, tuple({} for _ in ms))
    if camera is None:
        sol, designs = solve_lens(lines, R, ranges, alpha)
        coupling = tuple(angle_coupling(sol, d) for d in designs)
        notes = tuple(f"{who}: {n}" for n in sol.notes)
        return CameraLens(sol.lam if np.any(sol.lam) else None, notes,
                          {"source": "marks", **sol.to_dict()}, max_u, coupling)
    lam_u = camera_lens_u(camera, shape)
    zero = np.zeros_like(lam_u)
    terms_l = [camera_coupling(ln.points, ln.sigma, ln.chol, zero, lam_u, R) for ln in lines]
    p, dlam, designs = check_camera(lines, zero, lam_u, R, ranges, alpha)
    notes = []
    if p < alpha:
        what = ", ".join(f"{k} {v:+.3g}" for k, v in zip(PARAMS, dlam, strict=True) if v)
        notes.append(f"{who}: the lens differs from its calibration (the marks' bows call for "
                     f"{what} on top of it, p = {p:.2g}): u widened by its effect; "
                     "recalibrate the camera (`align camera`)")
        for t, d in zip(terms_l, designs, strict=True):
            t["camera_disagreement"] = float(d.s @ dlam)
    return CameraLens(None, tuple(notes),
                      {"source": "camera model", "p_marks_agree": p,
                       "u_lens_vector": lam_u.tolist()}, max_u, tuple(terms_l))


def _lens_undistorted(m: MarkMeasurement, lam: np.ndarray) -> MarkMeasurement:
    q, s = lens_undistorted(LineGeometry(m.points, m.sigma, m.chol), lam,
                            half_diagonal(m.image_shape))
    regs = dict(m.regressors, x=q[:, 0], y=q[:, 1], r2=(q**2).sum(1))
    return replace(m, points=q, sigma=s, regressors=regs,
                   line=fit_line(q, s, reject_sigma=None, chol=m.chol))


LENS_TERMS = ("lens_", "camera_")


def finish_mark(m: MarkMeasurement, lens: CameraLens, k: int, name: str, index: int,
                alpha: float = 1e-3, group: str = "") -> MarkResult:
    """One mark of a camera whose lens is known (:func:`camera_lens`, ``k`` the mark's place
    in it): undistorted by it, through the loop, the lens's u terms added to the angle.
    ``group`` names the lens solve the mark shares with others (default: the image)."""
    before = m.line.angle_rad
    mu = _lens_undistorted(m, lens.lam) if lens.lam is not None else m
    r = loop_mark(mu, name, index, alpha)
    terms = dict(r.u_terms)
    terms.update(lens.terms[k] if k < len(lens.terms) else {})
    au = float(np.sqrt(r.angle_u_rad**2 + sum(v**2 for k_, v in terms.items()
                                              if k_ not in r.u_terms)))
    lens_u = float(np.sqrt(sum(v**2 for k_, v in terms.items() if k_.startswith(LENS_TERMS))))
    limited = bool(lens_u > lens.max_u_rad)
    notes = list(lens.notes) + list(r.notes)
    if limited:
        worst = max((k_ for k_ in terms if k_.startswith(LENS_TERMS)), key=terms.get)
        notes.append(f"{name} mark {index}: NOT OK: the angle is lens-limited (± "
                     f"{np.rad2deg(lens_u) * 3600:.0f}″ from the lens, mostly {worst}; bound "
                     f"{np.rad2deg(lens.max_u_rad) * 3600:.0f}″): calibrate the camera "
                     f"(`align camera`) and give it with {lens.model_as}")
    coupling = lens.coupling[k] if k < len(lens.coupling) else {}
    return replace(r, angle_before_rad=before, angle_u_rad=au, u_terms=terms,
                   lens=lens.record, notes=tuple(notes), lens_limited=limited,
                   lens_coupling=dict(coupling), lens_group=(group or name) if coupling else "")


def measure_image(image: np.ndarray, name: str = "image", camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None,
                  ranges: LensRanges | None = None) -> list[MarkResult]:
    """Every mark of an in-memory image, each through the loop; failures become entries.

    ``roi`` (x, y, w, h) [px] and ``min_length_px`` restrict the search; ``ranges``: the
    plausible lens (Type B) when no camera model is given.

    Examples
    --------
    A synthetic 400 px mark at 0.1° (``synth`` renders it, with its truth), no lens:

    >>> import numpy as np
    >>> from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
    >>> from align import LensRanges, measure_image
    >>> spec = ImageSpec(marks=(MarkSpec(np.deg2rad(0.1), 5.0, 400.0, 4.0, contrast=-0.6),),
    ...                  width=640, height=480, full_well_e=full_well_for_snr(50, -0.6), seed=1)
    >>> (m,) = measure_image(render_marks(spec, with_crlb=False).image,
    ...                      ranges=LensRanges.none())
    >>> bool(abs(m.angle_rad - np.deg2rad(0.1)) < 3 * m.angle_u_rad), m.lens_limited
    (True, False)
    """
    try:
        measured = measure_frame(image, camera, where=name, max_marks=max_marks,
                                 expect_one=expect_one, roi=roi, min_length_px=min_length_px)
    except ImageInputError as exc:
        return [MarkResult(image=name, found=False, error=str(exc))]
    found = measured.items
    ms = [m for m in found if isinstance(m, MarkMeasurement)]
    # One lens for the frame, all its marks together (identifiability first).
    lens = camera_lens(ms, camera, ranges, alpha)
    out = []
    k = 0
    for i, m in enumerate(found):
        if isinstance(m, ImageInputError):
            out.append(MarkResult(image=name, found=False, error=str(m), index=i))
            continue
        out.append(finish_mark(m, lens, k, name, i, alpha))
        k += 1
    if measured.notes:  # the frame's background (stripes): on each of its marks
        out = [replace(r, notes=measured.notes + r.notes) for r in out]
    return with_families(out, measured.families, measured.unreported,
                         "camera model" if camera is not None else
                         "frame lens" if lens.lam is not None else "none", alpha, image)



DIAL_SPREAD = np.deg2rad(10.0)
"""A group whose lines' directions spread wider than this is a dial, not a family."""


def _wrap_all(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi / 2) % np.pi - np.pi / 2


def with_families(results: list[MarkResult], families: Sequence[Sequence[int]],
                  unreported: int, lens: str, alpha: float = 1e-3,
                  image: np.ndarray | None = None) -> list[MarkResult]:
    """The image's results with each family's :class:`align.family.LineFamily` on its
    measured members, and the count of lines found but not reported on every entry. With
    the ``image``, each member's ends are checked for obstructions (dust, ink:
    :func:`align.family.member_ends`): its length is the visible one, and a hidden end is
    said with the bound it leaves."""
    out = [replace(r, unreported=unreported) for r in results]
    for g in families:
        ok = [i for i in g if out[i].found]
        if len(ok) < 2:
            continue
        lengths: list[tuple[float, float, int]] = []
        if image is not None:
            for i in ok:
                out[i], got = member_ends(image, out[i])
                lengths.append(got)
        ms = [out[i] for i in ok]
        mids = []
        for r in ms:
            if r.measurement is None:
                mids.append(r.offset_px * line_frame(r.angle_rad)[1])
                continue
            # The extent is along the profile's own line (whose angle may sit across
            # +-90 deg from the result's).
            pf = r.measurement.profile
            u, n = line_frame(pf.angle_rad)
            t0, t1 = r.measurement.extent_px
            mids.append(pf.offset_px * n + 0.5 * (t0 + t1) * u)
        # The lens's terms are shared by the members: out of their u for the chi2 of their
        # angles, into the family mean's u (align.family).
        shared = [{k: v for k, v in r.u_terms.items() if k.startswith(LENS_TERMS)} for r in ms]
        own = np.sqrt(np.maximum([r.angle_u_rad**2 - sum(v**2 for v in t.values())
                                  for r, t in zip(ms, shared, strict=True)], 1e-30))
        angles = np.array([r.angle_rad for r in ms])
        if np.ptp(_wrap_all(angles - angles[0])) > DIAL_SPREAD and len(ms) >= 3:
            # Lines that meet at a point (imaging.families.group_dial): a dial.
            dial = line_dial([r.index for r in ms], angles, own,
                             np.array([r.offset_px for r in ms]),
                             np.array([r.offset_u_px for r in ms]), np.array(mids), lens, alpha)
            for i in ok:
                out[i] = replace(out[i], dial=dial)
            continue
        fam = line_family([r.index for r in ms], np.array([r.angle_rad for r in ms]), own,
                          np.array(mids), np.array([r.offset_u_px for r in ms]), lens,
                          len(g) - len(ok), alpha, shared, lengths)
        for i in ok:
            out[i] = replace(out[i], family=fam)
    return out


def measure_camera(images: Sequence[tuple[str | Path, Roi | None]],
                   camera: CameraModel | None = None, alpha: float = 1e-3,
                   expect_one: bool = False, ranges: LensRanges | None = None,
                   label: str = "", on_image: Callable[[int], None] | None = None
                   ) -> list[list[MarkResult]]:
    """All images of one camera with one lens (issue 18): every mark of every image enters
    one plumb-line fit (:func:`camera_lens`), then each goes through its loop. ``images``:
    (path, roi) pairs; one list of results per image, in order; an unreadable image or one
    without a mark is its failed entry, as in :func:`measure_file`."""
    found_all: list[list[MarkMeasurement | ImageInputError]] = []
    said: dict[str, tuple[str, ...]] = {}  # what the reader did to each stored image
    for j, (path, roi) in enumerate(images):
        if on_image is not None:
            on_image(j)
        try:
            got = read_image_notes(path)
            fr = measure_frame(got.pixels, camera, where=str(path), expect_one=expect_one,
                               roi=roi)
            said[str(path)] = tuple(f"{path}: {n}" for n in got.notes) + fr.notes
            found_all.append(list(fr.items))
        except ImageInputError as exc:
            found_all.append([exc])
    ms = [m for f in found_all for m in f if isinstance(m, MarkMeasurement)]
    shapes = {m.image_shape for m in ms}
    lens = camera_lens(ms, camera, ranges, alpha, label) if len(shapes) <= 1 else None
    out, k = [], 0
    for (path, _), found in zip(images, found_all, strict=True):
        res = []
        for i, m in enumerate(found):
            if isinstance(m, ImageInputError):
                res.append(MarkResult(image=str(path), found=False, error=str(m), index=i))
                continue
            if lens is None:  # images of different sizes: one lens each
                one = camera_lens([m], camera, ranges, alpha, label)
                res.append(finish_mark(m, one, 0, str(path), i, alpha,
                                       group=f"{path} mark {i}"))
            else:
                res.append(finish_mark(m, lens, k, str(path), i, alpha,
                                       group=f"camera {label}" if label else "camera"))
            k += 1
        notes = said.get(str(path), ())
        out.append([replace(r, notes=notes + tuple(r.notes)) for r in res] if notes else res)
    return out


def measure_file(path: str | Path, camera: CameraModel | None = None, alpha: float = 1e-3,
                 max_marks: int = 8, expect_one: bool = False, roi: Roi | None = None,
                 min_length_px: float | None = None, ranges: LensRanges | None = None
                 ) -> list[MarkResult]:
    """Every mark in an image file; an unreadable file is one failed entry."""
    try:
        got = read_image_notes(path)
    except ImageInputError as exc:
        return [MarkResult(image=str(path), found=False, error=str(exc))]
    results = measure_image(got.pixels, str(path), camera, alpha, max_marks, expect_one, roi,
                            min_length_px, ranges)
    if not got.notes:
        return results
    # What the reader did to the stored image (orientation applied, signed data offset):
    # in each mark's notes, hence in the JSON and the warnings.
    said = tuple(f"{path}: {n}" for n in got.notes)
    return [replace(r, notes=said + tuple(r.notes)) for r in results]


def measure_files(paths: Sequence[str | Path], camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None,
                  ranges: LensRanges | None = None) -> Iterator[list[MarkResult]]:
    """:func:`measure_file` over a batch, one list per file; nothing escapes one image.

    Bad input is already a failed entry; anything else raised inside one image is a bug, but
    it must not cost the user the other images: it becomes that image's failed entry, marked
    ``internal_error`` ("internal error — please report (<type>: <message>)", the traceback
    in the log), and the batch goes on.
    """
    for path in paths:
        try:
            yield measure_file(path, camera, alpha, max_marks, expect_one, roi, min_length_px,
                               ranges)
        except Exception as exc:  # noqa: BLE001 - deliberate: isolate one image's bug
            bug = internal_error(exc)
            log.error("%s: %s", path, bug, exc_info=exc)
            yield [MarkResult(image=str(path), found=False, internal_error=True,
                              error=str(bug))]
