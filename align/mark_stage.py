"""The line fit along one scribe mark that the residual loop drives, and its candidates.

Declared model: the mark's centres lie on a straight line in the undistorted image (the lens
is the camera's, :mod:`align.camera_lens`). Candidate effects (each a few design columns
with physical meaning):

* ``bent_mark`` — a bow across the mark: (t - t_m)^2 across it. Whether the lens could have
  made it, and how its direction is read (the chord between the groove's ends), is
  :func:`align.marks.loop_mark`'s.
* ``periodic_wiggle`` — a sinusoid along the mark (vibration, rolling shutter) with at least
  2 periods along it; its period is searched on the residual's periodogram (counted as a
  searched parameter). A slower bow is never a wiggle.
* ``illumination_gradient`` — a centre bias proportional to the local background slope across
  the mark (per unit contrast): lighting that is not even across the groove.

``radial_distortion`` (the old per-mark plumb-line k1) remains a :class:`MarkStage` term for
callers that pass it; :func:`align.marks.measure_image` does not offer it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.errors import NotApplicable
from align.loop import Candidate, StageFit, Term, periodogram_test
from imaging import (
    BlockScatter,
    MarkMeasurement,
    block_labels,
    block_phase_columns,
    block_scatter,
    cross_magnification,
    fit_line,
    line_frame,
    undistort,
)

RADIAL = "radial_distortion"
WIGGLE = "periodic_wiggle"
ILLUM = "illumination_gradient"
BEND = "bent_mark"

def half_diagonal(shape: tuple[int, int]) -> float:
    h, w = shape
    return float(np.hypot(w - 1, h - 1) / 2)


K1_MAX = 0.3
"""Largest |k1| at the half-diagonal taken as a lens (30 % at the corner; beyond ~1/3 the
barrel model folds the image, so a larger fitted k1 means the lines do not constrain it)."""


class MarkStage:
    """Line fit along one mark, with extra terms (the stage the loop drives).

    Parameters
    ----------
    m : imaging.MarkMeasurement
        The measured mark: its centres [px], their sigma across the line [px], its profile.

    Attributes
    ----------
    m : imaging.MarkMeasurement
        The mark.
    scale : float
        The image's half-diagonal R [px] (the radial term's normalisation).
    sigma : numpy.ndarray
        Each centre's sigma across the line [px], scaled by the texture's variance factor.
    noise_dof : float or None
        Degrees of freedom of the centres' estimated covariance (None: independent centres
        with their Fisher sigma, nothing estimated).
    u_scale : float
        Factor (>= 1) on the fit's u from the centres' sigma: a JPEG's block scatter's own
        estimate's uncertainty (:func:`jpeg_u_scale`), not in ``sigma`` (the loop's tests).
    """

    def __init__(self, m: MarkMeasurement):
        self.m = m
        self.scale = half_diagonal(m.image_shape)
        ts = texture_scale(m)
        self.sigma = m.sigma * np.sqrt(ts)
        self.noise_dof = noise_dof(m, ts)
        self.u_scale = jpeg_u_scale(m, ts)
        self.blocks = jpeg_blocks_columns(m)
        self._fits: dict[tuple, StageFit] = {}

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
        # The same model is fitted again by the reading of decisions on the edge
        # (align.mark_choice: the loop's last round, each effect left out): kept, not refitted.
        key = tuple((t.name, np.asarray(t.columns, float).tobytes()) for t in terms)
        if key not in self._fits:
            self._fits[key] = self._fit(terms)
        return self._fits[key]

    def _fit(self, terms: Sequence[Term]) -> StageFit:
        m = self.m
        names = [t.name for t in terms]
        k1, angle = 0.0, m.line.angle_rad
        rounds = 4 if RADIAL in names else 1
        for _ in range(rounds):
            q, sig = self.undistorted(k1, angle)
            cols = [(q**2).sum(1, keepdims=True) / self.scale**2 if t.name == RADIAL
                    else _bend_column(q, angle) if t.name == BEND
                    else np.asarray(t.columns, float).reshape(len(q), -1) for t in terms]
            if self.blocks is not None:
                cols.append(self.blocks)  # last: the terms' columns keep their indices
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
                # Sagitta of the fitted bow over the mark, end to end [px]: b (L/2)^2 over the
                # groove's length between its ends, not the centres' span (short of them: a
                # sagitta read 0.55-0.6 of the truth on user 16's webcam marks).
                ends = q
                if m.ends_px is not None and np.all(np.isfinite(m.ends_px)):
                    ends = undistort(m.ends_px, [k1], self.scale) if k1 else m.ends_px
                half = np.ptp(ends @ line_frame(angle)[0]) / 2
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
            payload=dict(zip(("chord_rad", "curvature_per_px", "chord_u_rad",
                              "chord_bound_rad"),
                             _chord_angle(q, lf, terms, m.ends_px, m.chol), strict=True),
                         offset_px=lf.offset_px),
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

    A JPEG (``m.jpeg``, :mod:`imaging.jpeg`) is read the same way: the encoder's
    quantisation moves each centre by a part of its block's error (centres 4 px apart, two
    to a block, correlated within it), scatter at the block scale that the Fisher sigma does
    not hold (its noise is read from a background the encoder smoothed). Neighbour
    differences across and within blocks see that scatter and its correlation, and hardly
    see a bow, a lens or a slow wiggle, which the loop still tests for
    (:func:`jpeg_scatter`: the factor the correlation puts on the angle's variance).
    """
    if len(m.points) <= 10 or (m.chol is None and m.jpeg is None):
        return 1.0
    if m.chol is None:
        return jpeg_scatter(m).factor
    # Whitened both ways along the mark, and averaged: a Cholesky factor whitens causally
    # (each residual given the ones before it), so from the other end the whitened series
    # differs, and u would depend on which end the line starts from (the same pixels
    # rotated by 180 deg). The reversed series' correlation matrix is P R P (P the
    # reversal), factored again.
    z = fit_line(m.points, m.sigma, reject_sigma=None, chol=m.chol).z
    rev = np.linalg.cholesky((m.chol @ m.chol.T)[::-1, ::-1])
    zr = fit_line(m.points[::-1], m.sigma[::-1], reject_sigma=None, chol=rev).z
    ts = float(max(1.0, (np.mean(np.diff(z) ** 2) + np.mean(np.diff(zr) ** 2)) / 4))
    return max(ts, jpeg_correlated_floor(m)) if m.jpeg is not None else ts


def jpeg_correlated_floor(m: MarkMeasurement) -> float:
    """Variance factor on a decoded JPEG's centres, correlated by its background's replicas
    (``m.chol``), that gives the line's angle the u its own block-correlated scatter gives
    it on the independent fit (:func:`jpeg_scatter`): its floor (1: not a JPEG, or no
    correlation).

    On a decoded JPEG the Fisher sigma comes from pixels the encoder smoothed (0.017 px on
    a quality-90 crop of user 13's, 0.022 before coding), the replicas beside the mark
    see that as excess variance (x1.9) and their correlation is taken with it: white within
    its noise there (lags 1-3 within +-0.1), but its tapered estimate at every lag up to
    the mark's length turned the angle's u to 0.76 of the independent fit's (6.8" for 9.0")
    on a mark whose error is the noise's (-22.7"). The background's correlation is the
    encoder's smoothing of a flat field, not the edge's; the mark's own centres read their
    scatter with the blocks' correlation, and u is not below that reading.
    """
    if m.jpeg is None or m.chol is None or len(m.points) <= 10:
        return 1.0
    gls = fit_line(m.points, m.sigma, reject_sigma=None, chol=m.chol).angle_u_rad
    plain = fit_line(m.points, m.sigma, reject_sigma=None).angle_u_rad
    if not gls > 0:
        return 1.0
    return float(jpeg_scatter(m).factor * (plain / gls) ** 2)


def jpeg_scatter(m: MarkMeasurement) -> BlockScatter:
    """A JPEG mark's centres' scatter with its correlation within the 8x8 blocks
    (:func:`imaging.block_scatter`), read from the straight line's whitened residuals. The
    blocks' pattern is left in (not :func:`jpeg_blocks_columns`): every fit of the centres
    takes this sigma, and the camera's bow test fits no such columns."""
    lf = fit_line(m.points, m.sigma, reject_sigma=None)
    t = m.points @ line_frame(lf.angle_rad)[0]
    X = np.column_stack([np.ones_like(t), t - t.mean()]) / m.sigma[:, None]
    h = np.linalg.pinv(X)[1]  # the slope's weights on the whitened centres
    return block_scatter(lf.z, block_labels(_raw_centres(m), m.jpeg.phase), h)


def _raw_centres(m: MarkMeasurement) -> np.ndarray:
    """The centres' raw pixel coordinates (x, y; pixel centres at integers), on the
    profile's line at each centre's ``t`` (their distance from it, hundredths of a px,
    moves no block)."""
    u, n = line_frame(m.profile.angle_rad)
    raw = m.profile.offset_px * n + np.asarray(m.regressors["t"], float)[:, None] * u
    return raw + (np.array(m.image_shape[::-1], float) - 1) / 2


def jpeg_blocks_columns(m: MarkMeasurement) -> np.ndarray | None:
    """A JPEG mark's block-pattern columns (:func:`imaging.block_phase_columns`), fitted
    with its line as known nuisance terms: the pattern is the encoder's, not structure the
    model lacks. None: not a JPEG (or no pattern the centres' phases determine).

    The centres' raw pixel coordinate along the axis the mark runs with is taken on the
    profile's line at each centre's ``t`` (their distance from it, hundredths of a px, moves
    no phase)."""
    if m.jpeg is None:
        return None
    u = line_frame(m.profile.angle_rad)[0]
    axis = 0 if abs(u[0]) >= abs(u[1]) else 1
    cols = block_phase_columns(_raw_centres(m)[:, axis])
    return cols if cols.shape[1] else None


def noise_dof(m: MarkMeasurement, scale: float) -> float | None:
    """Degrees of freedom of a textured mark's estimated centre covariance (None: the
    centres are independent with their Fisher sigma, nothing estimated).

    The correlation comes from the replicas (their spectrum estimate's equivalent dof); when
    :func:`texture_scale` re-read the amplitude from the mark (``scale`` > 1), that estimate
    adds its own relative variance: mean of squared neighbour differences of n white z has
    variance 3 / n relative, i.e. 2 n / 3 dof, and relative variances add (2/nu each).
    """
    tex = m.centres.texture
    if m.jpeg is not None and scale > 1.0 and (m.chol is None
                                                or scale == jpeg_correlated_floor(m)):
        # The JPEG's scatter re-read from the mark: the factor's own dof, the one the
        # angle's u takes (imaging.block_factor_dof: rho's spread with s^2's).
        return jpeg_scatter(m).dof
    if m.chol is None or tex is None or not np.isfinite(tex.dof):
        return None
    if scale <= 1.0:
        return float(tex.dof)
    return float(1.0 / (1.0 / tex.dof + 1.5 / max(len(m.points) - 1, 1)))


def jpeg_u_scale(m: MarkMeasurement, scale: float) -> float:
    """Factor (>= 1) on a JPEG mark's angle and offset u where its block scatter, read from
    the mark, set the centres' variance (``scale``, as in :func:`noise_dof`): sqrt of the
    scatter's ``u_factor`` over its ``factor`` (:func:`imaging.block_scatter`), the factor's
    estimate carried with its uncertainty (1 otherwise).

    Only u takes it: the loop's tests take the centres' sigma from the estimate itself,
    with its dof (:func:`noise_dof`: an F test's denominator carries the estimate's spread
    there; a widened sigma as well would count it twice and blunt the tests).
    """
    if m.jpeg is None or scale <= 1.0 or not (m.chol is None
                                              or scale == jpeg_correlated_floor(m)):
        return 1.0
    bs = jpeg_scatter(m)
    return float(np.sqrt(bs.u_factor / bs.factor))


def _bend_column(q: np.ndarray, angle: float) -> np.ndarray:
    """A bow across the mark: (t - t_mid)^2 along it [px^2] (t_mid the middle of the
    span, so the column leaves the line through the chord's middle)."""
    t = q @ line_frame(angle)[0]
    return ((t - (t.min() + t.max()) / 2) ** 2)[:, None]


END_WINDOW = 8
"""A bent mark's ends are read over 1/this of its span at each end: short enough that a
straight line through the centres there meets the groove's curvature within ~1 % of its
sagitta, long enough to average the centres' noise."""


def _chord_angle(q: np.ndarray, lf, terms: Sequence[Term], ends: np.ndarray | None = None,
                 chol: np.ndarray | None = None) -> tuple[float, float, float, float]:
    """Angle of the chord between the groove's own positions at its ``ends`` (the measured
    centres' span when None), the fitted curve's curvature, the chord's standard
    uncertainty from the centres' noise, and the bound on how far the ends' extrapolation
    beyond the last centres may turn it [rad, 1/px, rad, rad]: how a bent mark's direction is
    read end to end, and how far a mark whose residual keeps structure may turn from its fit.

    The bow is b (t - t_m)^2 across the line, so the fitted curve's chord between t0 and t1
    turns from the fitted line by b (t0 + t1 - 2 t_m). A groove of another shape (an S: its
    ends on one line, a bow the parabola averages away) is not that curve near its ends, so
    each end is moved across the line by the centres' misfit there (a straight line through
    the residuals of the last :data:`END_WINDOW`-th of the span, taken at the end): the
    chord is the groove's, not the model's."""
    u, _ = line_frame(lf.angle_rad)
    t = q @ u
    tm = (t.min() + t.max()) / 2
    t0, t1 = (t.min(), t.max()) if ends is None else tuple(ends @ u)
    bent = any(tt.name == BEND for tt in terms)
    b = float(lf.beta[MarkStage._col_index(terms, BEND)]) if bent else 0.0
    w = np.ptp(t) / END_WINDOW
    r, s = lf.residuals_px, lf.sigma_px
    R = None if chol is None else chol @ chol.T
    lo, hi = (t0, t1) if t0 <= t1 else (t1, t0)
    shift, var, amb = [], 0.0, 0.0
    for near, te in ((t <= t.min() + w, lo), (t >= t.max() - w, hi)):
        idx = np.flatnonzero(near)
        if len(idx) < 5:  # too few centres to read an end: the model's curve stands
            shift.append(0.0)
            continue
        # The misfit near this end, a straight line in t, taken at the groove's end (its
        # slope matters: an S leaves the parabola at a slant there, and a window's mean
        # would sit a slope times half the window off the end).
        X = np.column_stack([np.ones(len(idx)), t[idx] - te, (t[idx] - te) ** 2])
        g = np.linalg.pinv(X[:, :2] / s[idx, None])[0] / s[idx]  # the end value's weights
        shift.append(float(g @ r[idx]))
        cov = np.outer(s[idx], s[idx]) * (R[np.ix_(idx, idx)] if R is not None
                                          else np.eye(len(idx)))
        var += float(g @ cov @ g)
        # The groove's end lies beyond the last centres (its tip is not read): how far a
        # curving misfit may carry it from the straight extrapolation — the quadratic's
        # value there against the line's (a bound, Type B).
        # Only what stands beyond that difference's own noise (2 sigma) counts: on a groove
        # the model fits, the quadratic's extrapolation is noise, not a curve.
        dg = np.linalg.pinv(X / s[idx, None])[0] / s[idx] - g
        amb += max(0.0, abs(float(dg @ r[idx])) - 2 * float(np.sqrt(dg @ cov @ dg)))
    d0, d1 = (shift[0], shift[1]) if t0 <= t1 else (shift[1], shift[0])
    span = max(abs(t1 - t0), 1.0)
    turn = b * (t0 + t1 - 2 * tm) + (d1 - d0) / (t1 - t0 if t1 != t0 else 1.0)
    return float(lf.angle_rad - turn), 2 * b, float(np.sqrt(var) / span), amb / span


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
