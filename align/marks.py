"""The residual loop over a scribe-mark line fit, and the per-image result.

Declared model: the mark's centres lie on a straight line in the undistorted image.
Candidate effects (each a few design columns with physical meaning):

* ``radial_distortion`` — the plumb-line principle: a straight line at offset d from the
  principal point (assumed at the image centre) imaged through x_d = x (1 + k1 (r/R)^2) is
  bowed by k1 d (r/R)^2 across itself. R is the image half-diagonal, so k1 is dimensionless;
  OpenCV's k1 = k1 (f/R)^2 for focal length f [px]. Once found, the centres are undistorted
  exactly with the estimate and the line refitted (iterated). A bent mark bows the same way
  in one image; only a camera model or several marks in one image can tell them apart.
* ``periodic_wiggle`` — a sinusoid along the mark (vibration, rolling shutter); its period is
  searched on the residual's periodogram (counted as a searched parameter).
* ``illumination_gradient`` — a centre bias proportional to the local background slope across
  the mark (per unit contrast): lighting that is not even across the groove.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from align.errors import NotApplicable
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
    fit_line,
    line_frame,
    measure_marks,
    read_image,
    undistort,
)

RADIAL = "radial_distortion"
WIGGLE = "periodic_wiggle"
ILLUM = "illumination_gradient"

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
            order="t", effects=effects, payload={"offset_px": lf.offset_px},
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


def _radial(fit: StageFit) -> Term:
    return Term(RADIAL, "1 (k1 at the image half-diagonal)", np.zeros((fit.n, 1)))


def _wiggle(fit: StageFit) -> Term | None:
    t = np.asarray(fit.regressors["t"], float)
    test, omega = periodogram_test(fit.residuals / fit.sigma, t)
    if not np.isfinite(omega):
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
    z = float(np.sqrt(chi2.isf(alpha, 1)))
    if not u * z <= K1_MAX:
        return (f"k1 not identifiable on this mark: it passes {abs(d):.2g} px from the image "
                f"centre, where a radial distortion leaves a line straight (u(k1) = {u:.2g}; "
                f"even the largest lens k1 {K1_MAX} would not stand out of it)")
    if not abs(k1) <= K1_MAX:
        return (f"k1 = {k1:.3g} is beyond any lens (|k1| <= {K1_MAX} at the half-diagonal): "
                "a bow that large is a bent mark, not distortion")
    return None


CANDIDATES: tuple[Candidate, ...] = (
    Candidate(RADIAL, "1", "curvature across the mark growing with distance from the image "
              "centre: lens radial distortion (plumb-line k1) or a bent mark", _radial),
    Candidate(WIGGLE, "px", "periodic wiggle along the mark (vibration / rolling shutter)",
              _wiggle),
    Candidate(ILLUM, "px^2", "centre bias following the local illumination slope across the "
              "mark", _illum),
)


@dataclass(frozen=True)
class FrameDistortion:
    """One radial distortion shared by all marks of a frame (joint weighted plumb-line fit).

    ``k1`` at the image half-diagonal (dimensionless) with standard uncertainty ``k1_u``;
    ``applied``: whether it was significant, explained the lines, and the marks were
    undistorted with it; ``consistent``: whether the lines are straight within their
    uncertainties once it is removed (False: the lines disagree in a way no single radial
    distortion explains — bent marks, or lines that are not straight in the world — and every
    mark's u is inflated by sqrt(chi2/dof)); ``chi2_dof_before``/``after``: all lines'
    straightness; ``p_value`` of the k1 = 0 test.
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


def _undistort_mark(m: MarkMeasurement, k1: float) -> tuple[np.ndarray, np.ndarray]:
    """A mark's centres undistorted by k1 (at the half-diagonal) and their sigma carried
    through the undistortion (see :func:`imaging.cross_magnification`)."""
    if not k1:
        return m.points, m.sigma
    scale = half_diagonal(m.image_shape)
    g = cross_magnification(m.points, [k1], scale, line_frame(m.line.angle_rad)[1])
    return undistort(m.points, [k1], scale), m.sigma * np.abs(g)


def _chi2_lines(ms: Sequence[MarkMeasurement], k1: float, scale: float) -> float:
    out = 0.0
    for m in ms:
        q, s = _undistort_mark(m, k1)
        out += fit_line(q, s, reject_sigma=None, chol=m.chol).chi2
    return out


def frame_distortion(ms: Sequence[MarkMeasurement], alpha: float = 1e-3) -> FrameDistortion:
    """Joint plumb-line k1 over every mark of one frame, weighted by the centres' sigma.

    Variable projection: for a given k1 each line is a weighted straight-line fit, so chi2 is
    a function of k1 alone, minimised by Newton steps from finite differences; u(k1) =
    sqrt(2 / chi2'') at the minimum.
    Significance: chi2 drop against chi2(1) at ``alpha`` and a BIC gain (ln N).
    """
    scale = half_diagonal(ms[0].image_shape)
    n = sum(len(m.points) for m in ms)
    dof = max(n - 2 * len(ms), 1)
    c0 = _chi2_lines(ms, 0.0, scale)
    k1, c1, h, curv = 0.0, c0, 0.01, 0.0
    converged = False
    for _ in range(8):  # Newton on chi2(k1): quadratic near the minimum, not far from it
        cp, cm = _chi2_lines(ms, k1 + h, scale), _chi2_lines(ms, k1 - h, scale)
        curv = (cp - 2 * c1 + cm) / h**2
        if curv <= 0:
            break
        step = -(cp - cm) / (2 * h) / curv
        k1 += step
        if abs(k1) > K1_MAX:
            break  # short or few lines leave k1 unconstrained: no lens bends that much
        c1 = _chi2_lines(ms, k1, scale)
        h = max(min(h, 3 * np.sqrt(2 / curv)), 1e-6)
        if abs(step) < 0.01 * np.sqrt(2 / curv):
            converged = True
            break
    if not converged:
        k1, c1 = 0.0, c0
    drop = c0 - c1
    p = float(chi2.sf(max(drop, 0.0), 1))
    significant = bool(converged and curv > 0 and p < alpha and drop > np.log(n))
    after = (c1 if significant else c0) / max(dof - significant, 1)
    consistent = bool(chi2.sf(after * max(dof - significant, 1), max(dof - significant, 1))
                      >= alpha)
    return FrameDistortion(float(k1), float(np.sqrt(2 / curv)) if curv > 0 else float("inf"),
                           significant and consistent, consistent, len(ms), c0 / dof, after, p)


def _undistorted(m: MarkMeasurement, k1: float) -> MarkMeasurement:
    """The measurement with its centres undistorted by k1 (at the half-diagonal)."""
    q, s = _undistort_mark(m, k1)
    regs = dict(m.regressors, x=q[:, 0], y=q[:, 1], r2=(q**2).sum(1))
    return replace(m, points=q, sigma=s, regressors=regs,
                   line=fit_line(q, s, reject_sigma=None, chol=m.chol))


def _angle_sensitivity(m: MarkMeasurement, k1: float, h: float = 1e-3) -> float:
    """d(angle)/d(k1) of the mark's straight-line fit [rad per unit k1]."""
    a = [fit_line(*_undistort_mark(m, k), reject_sigma=None, chol=m.chol).angle_rad
         for k in (k1 - h, k1 + h)]
    return float(np.arctan2(np.sin(2 * (a[1] - a[0])), np.cos(2 * (a[1] - a[0]))) / 2 / (2 * h))


@dataclass(frozen=True)
class MarkResult:
    """One mark (or one failure) of one image. Angles [rad], lengths [px]."""

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
                "internal_error": bool(d.get("internal_error", False))}
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
                   frame=None if fr is None else FrameDistortion.from_dict(fr))


def loop_mark(m: MarkMeasurement, image: str = "", index: int = 0, alpha: float = 1e-3,
              candidates: Sequence[Candidate] = CANDIDATES) -> MarkResult:
    """Run the residual loop over one measured mark."""
    rep = run_loop(MarkStage(m), candidates, alpha=alpha,
                   admissible=functools.partial(radial_admissible, alpha=alpha))
    a, au = rep.after.quantities["angle_rad"]
    d, du = rep.after.quantities["offset_px"]
    infl = structure_inflation(rep)
    au, du = au * infl, du * infl
    return MarkResult(
        image=image, found=True, index=index, angle_rad=a, angle_u_rad=au, offset_px=d,
        offset_u_px=du, length_px=m.length_px, width_px=m.profile.width_px,
        blur_px=m.profile.blur_px, dark=m.candidate.dark, n_points=len(m.points),
        n_rejected=m.n_rejected, angle_before_rad=rep.before.quantities["angle_rad"][0],
        loop=rep, measurement=m, uncertainty_inflation=infl)


def structure_inflation(rep: LoopReport, alpha_low: float = 1e-6) -> float:
    """Factor on the stated uncertainty when the residual keeps unexplained structure.

    Below 1 when chi2 is improbably small (lower tail below ``alpha_low``): the stated
    sigma overstates the centres' scatter, and u is scaled down to it.

    Correlated residuals carry less information than independent ones: with lag-1
    correlation rho the variance of a fitted slope grows by about (1 + rho) / (1 - rho)
    (AR(1) noise), and an excess chi2/dof scales it further. 1 for a clean fit.
    """
    f = rep.after
    if f.dof > 0 and chi2.cdf(f.chi2, f.dof) < alpha_low:
        # The centres scatter far less than their stated sigma: the groove model's shape
        # (hence its Fisher information) does not describe this groove. Never return that
        # u as is (it was 10^5 arcsec once): scale it to the scatter (Birge ratio < 1).
        return float(np.sqrt(f.chi2 / f.dof))
    if not rep.unexplained_structure:
        return 1.0
    z = (f.residuals / f.sigma)[np.argsort(f.regressors[f.order])]
    zc = z - z.mean()
    rho = float(np.clip(zc[1:] @ zc[:-1] / max(zc @ zc, 1e-300), 0.0, 0.9))
    return float(np.sqrt(max(1.0, f.chi2 / max(f.dof, 1)) * (1 + rho) / (1 - rho)))


def measure_image(image: np.ndarray, name: str = "image", camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None
                  ) -> list[MarkResult]:
    """Every mark of an in-memory image, each through the loop; failures become entries.

    ``roi`` (x, y, w, h) [px] and ``min_length_px`` restrict the search.
    """
    try:
        found = measure_marks(image, camera, where=name, max_marks=max_marks,
                              expect_one=expect_one, roi=roi, min_length_px=min_length_px)
    except ImageInputError as exc:
        return [MarkResult(image=name, found=False, error=str(exc))]
    ms = [m for m in found if isinstance(m, MarkMeasurement)]
    frame = None
    candidates: Sequence[Candidate] = CANDIDATES
    if len(ms) >= 2 and camera is None:
        # Several marks, one lens: distortion is a property of the frame, fitted jointly;
        # each mark's own loop may then not invent a distortion of its own (a bent mark
        # shows as unexplained structure instead, and its u is inflated).
        frame = frame_distortion(ms, alpha)
        candidates = tuple(c for c in CANDIDATES if c.name != RADIAL)
    out = []
    for i, m in enumerate(found):
        if isinstance(m, ImageInputError):
            out.append(MarkResult(image=name, found=False, error=str(m), index=i))
            continue
        if frame is None:
            out.append(loop_mark(m, name, i, alpha))
            continue
        before = m.line.angle_rad
        mu = _undistorted(m, frame.k1) if frame.applied else m
        r = loop_mark(mu, name, i, alpha, candidates)
        # The shared k1 is uncertain: carry it into every angle corrected with it. (Not
        # applied, the declared model holds, as for a single mark: no lens distortion.)
        extra = _angle_sensitivity(m, frame.k1) * frame.k1_u if frame.applied else 0.0
        au = float(np.hypot(r.angle_u_rad, extra))
        if not frame.consistent:
            au *= max(1.0, np.sqrt(frame.chi2_dof_after) / r.uncertainty_inflation)
        out.append(replace(r, angle_before_rad=before, frame=frame, angle_u_rad=au))
    return out


def measure_file(path: str | Path, camera: CameraModel | None = None, alpha: float = 1e-3,
                 max_marks: int = 8, expect_one: bool = False, roi: Roi | None = None,
                 min_length_px: float | None = None) -> list[MarkResult]:
    """Every mark in an image file; an unreadable file is one failed entry."""
    try:
        img = read_image(path)
    except ImageInputError as exc:
        return [MarkResult(image=str(path), found=False, error=str(exc))]
    return measure_image(img, str(path), camera, alpha, max_marks, expect_one, roi,
                         min_length_px)


def measure_files(paths: Sequence[str | Path], camera: CameraModel | None = None,
                  alpha: float = 1e-3, max_marks: int = 8, expect_one: bool = False,
                  roi: Roi | None = None, min_length_px: float | None = None
                  ) -> Iterator[list[MarkResult]]:
    """:func:`measure_file` over a batch, one list per file; nothing escapes one image.

    Bad input is already a failed entry; anything else raised inside one image is a bug, but
    it must not cost the user the other images: it becomes that image's failed entry, marked
    ``internal_error`` ("internal error — please report (<type>: <message>)", the traceback
    in the log), and the batch goes on.
    """
    for path in paths:
        try:
            yield measure_file(path, camera, alpha, max_marks, expect_one, roi, min_length_px)
        except Exception as exc:  # noqa: BLE001 - deliberate: isolate one image's bug
            bug = internal_error(exc)
            log.error("%s: %s", path, bug, exc_info=exc)
            yield [MarkResult(image=str(path), found=False, internal_error=True,
                              error=str(bug))]
