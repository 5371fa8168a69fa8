"""A kink along one mark: two straight grooves meeting at an angle, seen as one line.

Two scribed strokes that share an end point at a few degrees (a "V", a bent-line corner) are
found as one groove; its straight fit, its chord and a bow (:data:`align.mark_stage.BEND`)
all read a direction that is neither stroke's. The test here: a broken line (a hinge
max(0, t - t_b) added to the line and the bow) against the line and the bow, its break t_b
searched over the middle of the mark. The supremum of the F statistic over t_b is not
F-distributed (the break is searched; Andrews 1993): its null distribution is simulated with
the mark's own design (its points along the line, its whitening) — a hand-written step, no
library gives the sup-F null of a given design. A bow (a circular arc) is in the null model,
so a bent mark does not fire it, and so is a wiggle of at least 2 periods along the mark
where one is significant (:func:`align.lens_wiggle.without_wiggle`).

When the kink is significant the mark is two marks: :func:`split_kinked` cuts it at the
break into two measurements, each measured as its own mark (its own loop, its own u), with
a note saying so. A part that cannot be read on its own (too few centres), or a kink
:func:`align.marks.loop_mark` still finds after the loop, leaves the mark not ok.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import linalg, special

from align.lens_design import LineGeometry
from align.lens_wiggle import without_wiggle
from align.mark_stage import MarkStage
from imaging import (
    CameraModel,
    ImageInputError,
    MarkMeasurement,
    fit_line,
    line_frame,
    measure_candidate,
)

TRIM = 0.15
"""The break is searched between these fractions of the span from each end (Andrews' pi0:
near an end a hinge is a single point's worth of data and the sup-F diverges)."""

N_BREAKS = 101
"""Breaks tried over the searched span (the grid of the supremum)."""

N_SIM = 2000
"""Simulated null draws of the supremum (seeded: the test is deterministic)."""

MIN_POINTS = 30
"""Fewer centres than this: no kink test (a part would have too few to read a line)."""


@dataclass(frozen=True)
class Kink:
    """The best broken line along a mark and its test.

    Attributes
    ----------
    t_px : float
        Where the break lies along the mark, from the mark's middle [px].
    sup_f : float
        The supremum over the searched breaks of the F statistic — dimensionless.
    p : float
        Its p-value under no kink (simulated null of the supremum) — dimensionless.
    turn_rad : float
        The change of direction at the break of the best broken line [rad].
    """

    t_px: float
    sup_f: float
    p: float
    turn_rad: float = 0.0


KINK_MIN_RAD = float(np.deg2rad(1.0))
"""The smallest turn taken for two strokes [rad]. The test's null holds a line and a bow;
smooth departures beyond them (a lens's cubic bow, a groove's shape along a near-axis mark)
fit a hinge of a few tenths of a degree at tiny p (a clean session's near-vertical mark:
0.17 deg, p 6e-10). Below 1 deg a departure is left to the loop's structure terms (u
inflated, the chord-vs-fit term), as before the kink test; the kinks it is for (two strokes
of a V, a bent-line corner) turn by degrees."""


def _whiten(cols: np.ndarray, sigma: np.ndarray, chol: np.ndarray | None) -> np.ndarray:
    w = cols / sigma[:, None]
    return w if chol is None else linalg.solve_triangular(chol, w, lower=True)


def _sup_f(H: np.ndarray, Z: np.ndarray, dof: int) -> np.ndarray:
    """sup over the (orthonormalised) hinge columns H of the 1-column F, per column of the
    residuals Z."""
    c = H.T @ Z
    rss = np.sum(Z * Z, axis=0)
    return np.max(c**2 / np.maximum(rss - c**2, 1e-300) * dof, axis=0)


def kink_test(m: MarkMeasurement, sigma: np.ndarray, seed: int = 0) -> Kink | None:
    """The broken-line test along a mark (None: too few centres to test).

    Parameters
    ----------
    m : imaging.MarkMeasurement
        The mark: its centres [px] and the Cholesky factor of their correlation.
    sigma : numpy.ndarray
        Each centre's sigma across the line [px] (the loop's, texture included).
    seed : int
        Seed of the simulated null.

    Returns
    -------
    Kink or None
        The best break [px], its sup-F and p-value.
    """
    q = m.points
    n_pts = len(q)
    if n_pts < MIN_POINTS:
        return None
    u, nrm = line_frame(m.line.angle_rad)
    t, e = q @ u, q @ nrm
    tm = (t.min() + t.max()) / 2
    null = [np.ones(n_pts), t - tm, (t - tm) ** 2 / np.ptp(t)]
    # A wiggle of >= 2 periods along the mark is in the null model too: a hinge takes up a
    # shaking camera's wiggle (0.3 px, 2.4 periods: sup-F 30, p 1.6e-4) as well as a V.
    wig = without_wiggle(LineGeometry(q, sigma, m.chol))[1]
    if wig is not None:
        om = 2 * np.pi / wig.period_px
        null += [np.sin(om * t), np.cos(om * t)]
    X0 = _whiten(np.column_stack(null), sigma, m.chol)
    Q0, _ = np.linalg.qr(X0)
    tb = np.quantile(t, np.linspace(TRIM, 1 - TRIM, N_BREAKS))
    H = _whiten(np.maximum(0.0, t[:, None] - tb[None, :]), sigma, m.chol)
    H -= Q0 @ (Q0.T @ H)
    h_norm = np.linalg.norm(H, axis=0)
    H /= h_norm
    z = _whiten(e[:, None], sigma, m.chol)
    z -= Q0 @ (Q0.T @ z)
    dof = n_pts - X0.shape[1] - 1
    c = (H.T @ z)[:, 0]
    f = c**2 / np.maximum(float(z[:, 0] @ z[:, 0]) - c**2, 1e-300) * dof
    # Where the break lies: the best broken line against the straight line alone (the bow
    # in the null model takes up much of a V whose break is near the middle, and blurs its
    # place; the test keeps the bow so that a circular arc does not fire it).
    Q1, _ = np.linalg.qr(X0[:, :2])
    H1 = _whiten(np.maximum(0.0, t[:, None] - tb[None, :]), sigma, m.chol)
    H1 -= Q1 @ (Q1.T @ H1)
    z1 = _whiten(e[:, None], sigma, m.chol)
    k = int(np.argmax((H1.T @ (z1 - Q1 @ (Q1.T @ z1)))[:, 0] ** 2
                      / np.maximum(np.sum(H1 * H1, axis=0), 1e-300)))
    # The turn: the hinge's slope change [px/px] at the test's own best break, with the bow
    # in the model (against the line alone a lens's cubic bow reads as a turn of degrees).
    j = int(np.argmax(f))
    turn = float(np.arctan(c[j] / max(float(h_norm[j]), 1e-300)))
    # The null: white residuals of the same design (the whitened centres are independent
    # under the model); F is scale-free, so a mis-stated sigma does not move it.
    Z = np.random.default_rng(seed).standard_normal((n_pts, N_SIM))
    Z -= Q0 @ (Q0.T @ Z)
    sims = _sup_f(H, Z, dof)
    # Below the simulation's resolution, the tail is extrapolated with an effective number
    # of independent breaks fitted where the simulation is good (its 90 % point): the single
    # break's F tail raised to that power.
    f_sup = float(np.max(f))
    p1 = float(special.fdtrc(1, dof, f_sup))
    c90 = float(np.quantile(sims, 0.9))
    m_eff = max(1.0, np.log(0.1) / np.log1p(-float(special.fdtrc(1, dof, c90))))
    p_ext = float(-np.expm1(m_eff * np.log1p(-p1))) if p1 < 1 else 1.0
    p_sim = (1 + int(np.sum(sims >= f_sup))) / (N_SIM + 1)
    p = p_sim if p_sim > 20 / N_SIM else min(p_sim, p_ext)
    return Kink(t_px=float(tb[k] - tm), sup_f=f_sup, p=p, turn_rad=turn)


MIN_PART = 20
"""Fewest centres a part of a kinked mark needs to be measured on its own."""


def _part(m: MarkMeasurement, idx: np.ndarray, sigma: np.ndarray) -> MarkMeasurement | None:
    """The mark's centres ``idx`` as a measurement of their own (None: too few left)."""
    if len(idx) < MIN_PART:  # (a break near an end, beyond the guard: no part to fit)
        return None
    chol = None if m.chol is None else np.linalg.cholesky((m.chol @ m.chol.T)[np.ix_(idx, idx)])
    lf = fit_line(m.points[idx], sigma[idx], reject_sigma=None if chol is not None else 4.5,
                  chol=chol)
    idx = idx[lf.used]
    if len(idx) < MIN_PART:
        return None
    if not lf.used.all():  # outliers of the part (the stroke's tip, dust) left out
        lf = fit_line(m.points[idx], sigma[idx], reject_sigma=None)
    u, _ = line_frame(lf.angle_rad)
    t = m.points[idx] @ u
    up, _ = line_frame(m.profile.angle_rad)
    ends = np.array([m.points[idx][np.argmin(t)], m.points[idx][np.argmax(t)]])
    te = np.sort(ends @ up)
    return replace(m, points=m.points[idx], sigma=m.sigma[idx], line=lf, chol=chol,
                   regressors={k: np.asarray(v)[idx] for k, v in m.regressors.items()},
                   extent_px=(float(te[0]), float(te[1])), ends_px=ends,
                   n_rejected=m.n_rejected + int(len(lf.used) - len(idx)))


def kink_testable(m: MarkMeasurement) -> bool:
    """Whether the kink test's null holds for the mark: its simulated null draws the centres'
    noise as the fit's covariance states it, which a JPEG encoder's 8 x 8 blocks do not (they
    move the centres with the edge's place in the grid: a near-axis mark in a quality-50 JPEG
    showed "kinks" of 0.03-0.11 deg at p 5e-4 to 4e-12). Those marks carry the blocks' effect
    in u (``jpeg_blocks``) and are not split."""
    return m.jpeg is None


def _remeasured(image: np.ndarray, m: MarkMeasurement, part: MarkMeasurement, side: int,
                 tb: float, guard: float, camera: CameraModel | None, where: str
                 ) -> MarkMeasurement:
    """A part of a kinked mark measured again from ``image`` as its own groove: its own band
    fit (profile, noise model) along its own line, the centres beyond ``guard`` of the break
    ``tb`` on its ``side`` (-1: before, +1: after, along the whole mark's line) kept.

    The whole mark's band fit is the one groove model of both strokes: its profile fits
    neither where they part (segments' pixel chi2/dof 1.6-1.9 on 5-8 deg V's), the noise
    model estimated from those residuals swells, and the parts' centres carried sigma 1.5-2.2x
    their scatter (line chi2/dof 0.2-0.44, RMS z 0.54 over benchmarks/kinked_marks.py's
    scenes). The part as it was is returned when it cannot be measured again."""
    sel = np.isin(m.centres.t, part.regressors["t"])
    raw = m.centres.xy[sel]  # the part's centres in the raw image (relative to its centre)
    lf = fit_line(raw, m.centres.sigma[sel], reject_sigma=None)
    u, _ = line_frame(lf.angle_rad)
    t = raw @ u
    cand = replace(m.candidate, angle_rad=lf.angle_rad, offset_px=lf.offset_px,
                   t_start_px=float(t.min()), t_end_px=float(t.max()), fused=None)
    # The other stroke out of the image (its side of the joint set to the groove's
    # background level): measured with it, the part's groove ran on into it (a 5 deg V's
    # strokes stay within one groove width for ~50 px from the joint), its band fit was the
    # V's again and a part was read as a bent mark. (Set to 0, read as clipped, the band
    # fit's profile degenerated: width 0.15 px, blur 5.5 px.)
    h, w = image.shape
    ys, xs = np.mgrid[0:h, 0:w]
    um, _ = line_frame(m.line.angle_rad)
    along = (xs - (w - 1) / 2) * um[0] + (ys - (h - 1) / 2) * um[1]
    try:
        again = measure_candidate(np.where(side * (along - tb) > 0, image,
                                           m.profile.background_dn), cand, camera, where,
                                  around=m.around)
    except ImageInputError:
        return part
    ta = again.points @ um
    keep = np.flatnonzero(side * (ta - tb) > guard)
    return _part(again, keep, again.sigma) or part


def split_kinked(m: MarkMeasurement, alpha: float = 1e-3, image: np.ndarray | None = None,
                 camera: CameraModel | None = None, where: str = "image"
                 ) -> tuple[tuple[MarkMeasurement, ...], Kink | None]:
    """The mark, or its two straight parts when a kink is significant at ``alpha``.

    Tested only when the straight line leaves a chi2 improbable at ``alpha`` (a kink of
    either part's u leaves the line's chi2 far out; a clean mark costs no test). The
    centres within the groove's blurred width of the break, where the two strokes'
    profiles overlap, belong to neither part.

    ``image`` (with the ``camera`` model it was measured with, if any): each part is
    measured again from it as its own groove (:func:`_remeasured`); None: the parts keep
    the whole mark's centres and sigma.

    Returns
    -------
    tuple of MarkMeasurement, Kink or None
        The measurement(s) (one: no kink, or a part too short to read) and the kink found.
    """
    lf = m.line
    if not kink_testable(m) or lf.dof <= 0 or special.chdtrc(lf.dof, lf.chi2) >= alpha:
        return (m,), None
    kink = kink_test(m, MarkStage(m).sigma)
    if kink is None or kink.p >= alpha or abs(kink.turn_rad) < KINK_MIN_RAD:
        return (m,), kink
    u, _ = line_frame(m.line.angle_rad)
    t = m.points @ u
    tb = (t.min() + t.max()) / 2 + kink.t_px
    guard = m.profile.width_px + 3 * m.profile.blur_px
    parts = [_part(m, np.flatnonzero(sel), m.sigma)
             for sel in (t < tb - guard, t > tb + guard)]
    if any(p is None for p in parts):
        return (m,), kink
    if image is not None:
        # The strokes share an end point: where the parts' lines meet is the joint (the
        # break's place, from the hinge's grid, was 10-20 px off it on 5 deg V's, and a
        # part measured again took that much of the other stroke: read as bent).
        n0, n1 = (line_frame(p.line.angle_rad)[1] for p in parts)
        joint = np.linalg.solve(np.array([n0, n1]), [p.line.offset_px for p in parts])
        tj = float(joint @ u)
        parts = [_remeasured(image, m, p, side, tj, guard, camera, where)
                 for p, side in zip(parts, (-1, 1), strict=True)]
    return tuple(parts), kink
