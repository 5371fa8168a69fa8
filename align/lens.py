"""One camera's lens from its marks: what the lines determine, what is fitted, what is carried.

The marks of one camera (one frame, or every image of a camera in a session) are straight
grooves, so their centres, undistorted by the right lens, lie on straight lines (the
plumb-line principle). The lens vector is :data:`imaging.lens.PARAMS` (k1, k2, p1, p2 at the
image half-diagonal, pixel aspect - 1, principal-point offset [px]).

Identifiability comes before estimation. For each mark the perpendicular displacement each
lens parameter causes along the mark is computed at the mark's own position (its length, its
distance from the centre, where the foot of the perpendicular from the centre lies); the part
a straight line can absorb (offset and tilt) is projected out, and what remains is the bow the
parameter leaves, whitened by the centres' noise. Summed over the camera's marks this is the
Fisher information F of the lens from the lines. A parameter is *determined* when its
marginal u from F is small enough that the largest plausible value (its Type B range) would
stand out of it at the loop's level (z u < range); only determined parameters are fitted,
jointly (Gauss-Newton from zero). A fitted value is applied only when its sign is determined
(|value| > z u) and it lies within the plausible range; the rest are set to zero.

The angle of each mark then carries, as named terms:

* ``lens_fit``: the fitted parameters' covariance propagated into the angle (Type A), with
  how far the undetermined principal point (uniform over its range) moves them;
* ``lens_<p>_small``: a determined parameter not applied (its sign undetermined): its
  estimate and u as an rms (Type A);
* ``lens_<p>_range``: an undetermined parameter: uniform over its plausible range, range/sqrt 3,
  times the angle's sensitivity to it *after* the fitted parameters absorbed what they can of
  it, for radial terms the rms of that sensitivity over the principal point's range (Type B,
  the way the goniometer carries an undetermined Earth rate);
* ``lens_or_bend``: a lens no other line confirms: the angle with it minus without it, the
  truth uniform between them, / sqrt 3 (Type B).

Every Type B term is a standard uncertainty of its stated distribution (uniform over a range:
half-width / sqrt 3), never the bound itself: over lenses drawn from the ranges the tool is
given, the normalised errors have RMS ~1 (``tests/align/lens_grid.py``'s ``plausible`` class).

A given camera model replaces all this: its covariance is propagated instead (``camera_<p>``),
and the lines only test it (see :func:`align.lens_terms.check_camera`). The ranges and each
mark's design are :mod:`align.lens_design`'s; the terms above are :mod:`align.lens_terms`'s.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.lens_design import (
    DEFAULT_RANGES,
    LensFolds,
    LensRanges,
    LineGeometry,
    _Design,
    _DesignCache,
)
from imaging.lens import PARAMS

__all__ = ["LensFolds", "LensRanges", "LensSolution", "LineGeometry", "solve_lens"]


@dataclass(frozen=True)
class LensSolution:
    """The lens of one camera from its marks (see the module docstring).

    Attributes
    ----------
    lam : numpy.ndarray
        The applied lens vector over ``PARAMS`` (zeros where not applied) — dimensionless (pp
        in [px]).
    determined, applied : tuple of bool
        Per parameter; unit —.
    u_lines : numpy.ndarray
        Each parameter's marginal u from the lines (inf: not determined) — dimensionless (pp
        in [px]).
    estimate : numpy.ndarray
        The fitted value of each determined parameter (nan otherwise) — dimensionless (pp in
        [px]).
    cov_applied : numpy.ndarray
        Covariance of the applied parameters [products of their units].
    ranges : LensRanges
        The plausible ranges used; unit —.
    n_lines : int
        Marks that entered the fit — dimensionless.
    chi2_dof : float
        χ²/dof of the lines' fit — dimensionless.
    notes : tuple of str
        What the reader must know (one line each); unit —.
    info : numpy.ndarray
        The lines' information matrix over ``PARAMS`` [1/products of the units].
    confirmed : bool
        The lines confirm the lens applied; unit —.
    bow_chi2 : float
        χ² of the marks' bows about the lens — dimensionless.
    bow_dof : int
        Its degrees of freedom — dimensionless.
    bent_lines : tuple of int
        The line whose bow no lens the other lines agree on explains (left out of the fit,
        a bent mark) — dimensionless.
    """

    lam: np.ndarray
    determined: tuple[bool, ...]
    applied: tuple[bool, ...]
    u_lines: np.ndarray
    estimate: np.ndarray
    cov_applied: np.ndarray
    ranges: LensRanges
    n_lines: int
    chi2_dof: float
    notes: tuple[str, ...] = ()
    info: np.ndarray = field(default_factory=lambda: np.zeros((len(PARAMS), len(PARAMS))))
    confirmed: bool = True
    bow_chi2: float = 0.0
    bow_dof: int = 0
    bent_lines: tuple[int, ...] = ()

    def to_dict(self) -> dict:
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        return {"model": "brown-conrady at the half-diagonal", "lines": self.n_lines,
                "confirmed_by_other_lines": self.confirmed,
                "bow_chi2": float(self.bow_chi2), "bow_dof": self.bow_dof,
                "bent_lines": list(self.bent_lines),
                "chi2_dof": num(self.chi2_dof), "ranges": self.ranges.to_dict(),
                "parameters": {p: {"determined": self.determined[j],
                                   "applied": self.applied[j], "value": float(self.lam[j]),
                                   "estimate": num(self.estimate[j]),
                                   "u_from_lines": num(self.u_lines[j])}
                               for j, p in enumerate(PARAMS)},
                "notes": list(self.notes)}


def _determined(F: np.ndarray, rng: np.ndarray, z: float) -> list[int]:
    """The lens parameters (indices into PARAMS) the lines' information ``F`` determines:
    drop the worst-determined until every one left would tell its largest plausible value
    (``rng``) from zero at the two-sided level whose normal quantile is ``z``."""
    det = [j for j in range(len(rng)) if rng[j] > 0]
    while det:
        u = _marginal_u(F, det, rng)
        worst = int(np.argmax(u / rng[det]))
        if z * u[worst] < rng[det[worst]]:
            break
        det.pop(worst)
    return det


def _marginal_u(F: np.ndarray, idx: list[int], rng: np.ndarray) -> np.ndarray:
    """Marginal u of the parameters ``idx`` from information F (range-normalised inversion
    with a tiny ridge, so a null direction reads as u far beyond the range)."""
    Fs = F[np.ix_(idx, idx)] * np.outer(rng[idx], rng[idx])
    C = np.linalg.inv(Fs + 1e-10 * np.eye(len(idx)))
    return np.sqrt(np.clip(np.diag(C), 0, None)) * rng[idx]


def solve_lens(lines: Sequence[LineGeometry], scale: float, ranges: LensRanges = DEFAULT_RANGES,
               alpha: float = 1e-3, iters: int = 5) -> tuple[LensSolution, list[_Design]]:
    """The lens of one camera from the marks ``lines`` (all of its images), ``scale`` = R.

    Parameters
    ----------
    lines : sequence of LineGeometry
        Each mark's centres [px] and their sigma [px], all images of the camera.
    scale : float
        The half-diagonal R [px] normalising the radial terms.
    ranges : LensRanges
        The plausible lens (Type B): each parameter's range (k1, k2, p [-], aspect [-],
        principal point [px]).
    alpha : float
        Significance of the tests (a parameter applied, a bow a lens).
    iters : int
        Rounds of the applied set (Gauss-Newton, then the sign test).

    Returns
    -------
    LensSolution
        The applied lens vector, which parameters the lines determine, their u, the notes.
    list of _Design
        Each mark's design at the applied lens (its angle sensitivities [rad per unit]).

    A bow is a lens only if the other lines agree. When no plausible lens explains all the
    lines' bows (:func:`_plausible`) but one fits all the others, the line left out is a
    bent mark: the lens comes from the others (its own loop then names the bend), rather
    than one bent mark dragging the camera's lens beyond any lens and every angle with it.
    """
    sol, designs = _solve(lines, scale, ranges, alpha, iters)
    if len(lines) < 3 or _plausible(sol, designs, alpha) >= alpha:
        return sol, designs
    best: tuple[float, int, LensSolution] | None = None
    for k in range(len(lines)):
        rest = [ln for i, ln in enumerate(lines) if i != k]
        try:
            sk, dk = _solve(rest, scale, ranges, alpha, iters)
        except LensFolds:
            continue
        p = _plausible(sk, dk, alpha)
        if p >= alpha and (best is None or p > best[0]):
            best = (p, k, sk)
    if best is None:
        return sol, designs
    _, k, sk = best
    cache = _DesignCache(lines, scale)
    try:
        ds = cache.all(sk.lam)
    except LensFolds:
        return sol, designs
    det = [j for j in range(len(PARAMS)) if sk.determined[j]]
    probes = _pp_probe_s(cache, sk.lam, det, ranges.vector())
    note = (f"line {k} of {len(lines)}: its bow fits no lens that the other line(s) agree on "
            f"(all lines: no plausible lens, chi2 {sol.bow_chi2:.1f} on {sol.bow_dof} dof): a "
            "bent mark, left out of the lens")
    sk = replace(sk, notes=(note, *sk.notes), n_lines=len(lines), bent_lines=(k,))
    return sk, [replace(d, s_pp_var=v) for d, v in zip(ds, probes, strict=True)]


def _plausible(sol: LensSolution, designs: Sequence[_Design], alpha: float) -> float:
    """p-value of the lines' bows left once the applied lens and every other parameter within
    its plausible range explain what they can (1 with no line to spare)."""
    rng = sol.ranges.vector()
    others = [j for j in range(len(PARAMS)) if not sol.applied[j] and rng[j] > 0]
    bz = _bows_left(designs, others, rng)
    dof = len(bz) - sum(sol.applied)
    return float(special.chdtrc(dof, float(bz @ bz))) if dof > 0 else 1.0


def _solve(lines: Sequence[LineGeometry], scale: float, ranges: LensRanges, alpha: float,
           iters: int) -> tuple[LensSolution, list[_Design]]:
    """:func:`solve_lens` over all of ``lines``."""
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    P = len(PARAMS)
    lam = np.zeros(P)
    cache = _DesignCache(lines, scale)
    designs = cache.all(lam)
    F0 = sum(d.G.T @ d.G for d in designs)
    det = _determined(F0, rng, z)
    notes: list[str] = []
    est = np.full(P, np.nan)
    u_lines = np.full(P, np.inf)
    applied = list(det)
    spread, spread_u, spread_for = np.zeros(P), np.zeros(P), list(applied)
    fits: dict[tuple[int, ...], np.ndarray] = {}
    for _ in range(3):  # until the applied set is stable (a dropped sign changes the others)
        lam = fits[tuple(applied)] = _gauss_newton(cache, applied, rng, iters)
        try:
            designs = cache.all(lam)
        except LensFolds:  # the estimate folds the image: no lens, refused below
            lam[applied] = np.where(np.abs(lam[applied]) > rng[applied], lam[applied],
                                    2 * rng[applied])
            designs = cache.all(np.zeros(P))
        F = sum(d.G.T @ d.G for d in designs)
        if det:
            u = _marginal_u(F, det, rng)
            u_lines[det] = u
        spread, spread_u = _pp_spread(cache, lam, applied, det, rng)
        spread_for = list(applied)
        # Applied only with its sign determined under every principal point the lines allow
        # (a radial term's bow scales with the line's distance from the principal point).
        bound = _p_with_decentring(rng, lam, u_lines, det, scale, z)
        keep = [j for j in applied
                if abs(lam[j]) > spread[j] + z * u_lines[j] and abs(lam[j]) <= bound[j]]
        est[applied] = lam[applied]
        if keep == applied:
            break
        applied = keep
    lam_out = np.zeros(P)
    lam_out[applied] = lam[applied]
    needed = _needed(cache, lam_out, applied, det, fits, est, rng, alpha, bound)
    if needed is not None:
        # The lines determine these parameters and need them: without them their bows
        # disagree with one lens, with them they agree. Only the principal point's range
        # (carried in u below) left their sign open: a lens the lines call for is applied,
        # and only what no lens explains is a bend.
        lam_out, chi_without, chi_with = needed
        added = [j for j in det if lam_out[j] and j not in applied]
        notes.append(f"lens {', '.join(PARAMS[j] for j in added)} applied: the lines need "
                     f"it (their bows without it chi2 {chi_without[0]:.1f} on "
                     f"{chi_without[1]} dof, with it {chi_with[0]:.1f} on {chi_with[1]}), with "
                     "the same sign wherever the principal point is in its range; that range "
                     "is carried in u")
        applied = sorted(applied + added)
        spread_for = []
    if not applied:
        spread_u = np.zeros(P)
    elif spread_for != applied:  # the applied set changed after its last spread
        spread_u = _pp_spread(cache, lam_out, applied, det, rng)[1]
    designs = cache.all(lam_out)
    F = sum(d.G.T @ d.G for d in designs)
    cov = np.linalg.inv(F[np.ix_(applied, applied)]) if applied else np.zeros((0, 0))
    if applied:  # the principal point's range (uniform, Type B) moves the estimate
        cov = cov + np.diag(spread_u[applied] ** 2)
        u_lines = np.where(np.isfinite(u_lines), np.hypot(u_lines, spread_u), u_lines)
    s_pp_var = _pp_probe_s(cache, lam_out, det, rng)
    n_pts = sum(len(ln.points) for ln in lines)
    c2 = float(sum(d.z @ d.z for d in designs))
    dof = max(n_pts - 2 * len(lines) - len(applied), 1)
    for j in det:
        if j not in applied:
            e = est[j]
            why = (f"beyond any lens (|{PARAMS[j]}| <= {bound[j]:.3g}"
                   + (", the principal point's range included" if bound[j] > rng[j] else "")
                   + "): not a lens"
                   if np.isfinite(e) and abs(e) > bound[j] else "sign not determined")
            notes.append(f"lens {PARAMS[j]} = {e:.3g} ± {u_lines[j]:.2g} from the lines: {why}; "
                         "not applied, carried in u")
    # A bow is a lens only if the camera's other lines agree: the lines' bows left after the
    # lens, and after what the undetermined parameters can make within their ranges, must
    # be noise (chi2 over lines - fitted parameters). With no line to spare (one mark, or as
    # many marks as parameters) a lens and a bent mark are the same bow.
    undet = [j for j in range(P) if j not in det and rng[j] > 0]
    bz = _bows_left(designs, undet, rng)
    bow_dof = len(lines) - len(applied)
    bow_chi2 = float(bz @ bz)
    confirmed = True
    if applied:
        confirmed = bow_dof > 0 and special.chdtrc(bow_dof, bow_chi2) >= alpha
        if bow_dof <= 0:
            notes.append(f"the bow of {len(lines)} line(s) fits {len(applied)} lens "
                         "parameter(s) with no line to spare: a lens and a bent mark are the "
                         "same bow here; u covers both (add marks elsewhere in the frame, or "
                         "calibrate the camera)")
        elif not confirmed:
            worst = int(np.argmax(np.abs(bz)))
            notes.append(f"the lines' bows disagree with one lens (chi2 {bow_chi2:.1f} on "
                         f"{bow_dof} dof; mark {worst} worst, {bz[worst]:+.1f} u): a bent mark; "
                         "u covers the lens and no lens")
    und = [PARAMS[j] for j in range(P) if j not in det and rng[j] > 0]
    if und:
        notes.append(f"lens {', '.join(und)} not determined by these {len(lines)} line(s): "
                     "carried in u over their plausible range")
    sol = LensSolution(lam_out, tuple(j in det for j in range(P)),
                       tuple(j in applied for j in range(P)), u_lines, est, cov, ranges,
                       len(lines), c2 / dof, tuple(notes), F, bool(confirmed), bow_chi2,
                       bow_dof)
    return sol, [replace(d, s_pp_var=v) for d, v in zip(designs, s_pp_var, strict=True)]


def _gauss_newton(cache: _DesignCache, applied: list[int], rng: np.ndarray, iters: int,
                  start: np.ndarray | None = None) -> np.ndarray:
    """The lens vector fitting the parameters ``applied`` to the lines' bows (Gauss-Newton
    from ``start``, zero by default, the other entries held there; stopped, and left for the
    caller to refuse, running away beyond any range or where no step improves the fit)."""
    lam = np.zeros(len(PARAMS)) if start is None else start.copy()
    if not applied:
        return lam
    A = np.ix_(applied, applied)
    try:
        designs = cache.all(lam)
    except LensFolds:
        return lam
    cost = sum(float(d.z @ d.z) for d in designs)
    for _ in range(iters):
        F = sum(d.G.T @ d.G for d in designs)
        b = sum(d.G.T @ d.z for d in designs)
        step = -np.linalg.solve(F[A], b[applied])
        # The step linearised at zero overshoots a strong lens's higher terms (k2 -0.16
        # for -0.04 after a k1 -0.17): halved until the lines fit better (and the lens
        # does not fold), so that a lens is judged beyond its range only where the fit
        # itself ends up there.
        for _ in range(8):
            trial = lam.copy()
            trial[applied] += step
            try:
                t_designs = cache.all(trial)
            except LensFolds:
                step = step / 2
                continue
            t_cost = sum(float(d.z @ d.z) for d in t_designs)
            if t_cost <= cost:
                break
            step = step / 2
        else:
            break  # no step improves: stay
        lam, designs, cost = trial, t_designs, t_cost
        if np.any(np.abs(lam[applied]) > 10 * rng[applied]):
            break  # running away, beyond any lens: refused by the caller
        if np.all(np.abs(step) < 1e-3 * rng[applied]):
            break
    return lam


def _bows_left(designs: Sequence[_Design], undet: Sequence[int], rng: np.ndarray
               ) -> np.ndarray:
    """Each line's bow [its u] left once the undetermined parameters ``undet`` explain what
    they can within their ranges: ridge least squares with each one's plausible range as
    its prior standard deviation (so a bow they could make is not a disagreement, and one
    beyond their reach stays). The parameters' bows are read in each line's own bow
    direction (``w``); the ridge's prior term is spread over the lines, so the squared sum
    is the penalised chi2."""
    bz = np.array([d.bow_z for d in designs])
    if not undet:
        return bz
    B = np.array([d.w @ d.G[:, undet] for d in designs])
    prior = 1.0 / rng[list(undet)] ** 2
    delta = np.linalg.solve(B.T @ B + np.diag(prior), B.T @ bz)
    left = bz - B @ delta
    pen = float(delta @ (prior * delta))
    # Spread the prior's share over the lines (their sum of squares is the statistic).
    return left * np.sqrt(1.0 + pen / max(float(left @ left), 1e-300))


def _bow_test(cache: _DesignCache, lam: np.ndarray, k: int, undet: Sequence[int],
              rng: np.ndarray) -> tuple[float, int] | None:
    """The lines' bows left at ``lam`` (``k`` parameters fitted; ``undet`` as in
    :func:`_bows_left`): (chi2, dof), None when the lens folds the image or no line is to
    spare."""
    try:
        bz = _bows_left(cache.all(lam), undet, rng)
    except LensFolds:
        return None
    dof = len(bz) - k
    return (float(bz @ bz), dof) if dof > 0 else None


def _p_with_decentring(rng: np.ndarray, lam: np.ndarray, u: np.ndarray, det: list[int],
                       scale: float, z: float) -> np.ndarray:
    """How large each parameter may plausibly be about the image centre: its range, and for
    p1, p2 also what a radial lens about a principal point within its range makes there.
    k1 about a point (cx, cy) [px] off the centre is, to first order, k1 about the centre
    plus p1 = -k1 cy / R, p2 = -k1 cx / R (all at the half-diagonal R = ``scale``): a
    pincushion lens with the principal point 10 px off read as a p "beyond any lens". k1 is
    the lines' (its estimate + z u, within its range) when they determine it, else its
    range."""
    out = rng.astype(float).copy()
    k1 = (min(abs(lam[0]) + z * u[0], rng[0]) if 0 in det and np.isfinite(u[0])
          else rng[0])
    out[2] += k1 * rng[6] / scale  # p1 from cy
    out[3] += k1 * rng[5] / scale  # p2 from cx
    return out


def _needed(cache: _DesignCache, lam: np.ndarray, applied: list[int], det: list[int],
            fits: Mapping[tuple[int, ...], np.ndarray], est: np.ndarray, rng: np.ndarray,
            alpha: float, bound: np.ndarray
            ) -> tuple[np.ndarray, tuple[float, int], tuple[float, int]] | None:
    """The lens with more of the determined parameters, when the applied ones alone leave
    the lines' bows disagreeing (chi2 test at ``alpha``) and the larger set explains them
    within every parameter's ``bound`` (:func:`_p_with_decentring`): the fewest added
    parameters that do, the best fit among those. Returns (that lens, the bow test without,
    with); None otherwise."""
    extra = [j for j in det if j not in applied]
    if not extra:
        return None
    undet = [j for j in range(len(PARAMS)) if j not in det and rng[j] > 0]
    without = _bow_test(cache, lam, len(applied), undet, rng)
    if without is None or special.chdtrc(without[1], without[0]) >= alpha:
        return None
    for size in range(1, len(extra) + 1):
        best = None
        for add in itertools.combinations(extra, size):
            full = sorted(applied + list(add))
            lam_full = fits.get(tuple(full))
            if lam_full is None:
                lam_full = _gauss_newton(cache, full, rng, 5)
            if not np.all(np.abs(lam_full[full]) <= bound[full]):
                continue
            out = np.zeros(len(PARAMS))
            out[full] = lam_full[full]
            with_ = _bow_test(cache, out, len(full), undet, rng)
            if with_ is not None and special.chdtrc(with_[1], with_[0]) >= alpha and (
                    best is None or with_[0] < best[2][0]) and _same_sign_over_pp(
                    cache, out, full, det, undet, rng, alpha):
                best = (out, without, with_)
        if best is not None:
            return best
    return None


def _same_sign_over_pp(cache: _DesignCache, lam: np.ndarray, full: list[int], det: list[int],
                       undet: list[int], rng: np.ndarray, alpha: float) -> bool:
    """Whether no principal point in its range lets a lens with another sign of any of the
    parameters ``full`` explain the lines: refitted with the principal point at each corner
    of its range, every fit that explains the bows keeps the signs of ``lam``."""
    for probe in _pp_probes(np.zeros(len(PARAMS)), det, rng):
        lam_p = _gauss_newton(cache, full, rng, 8, start=probe)
        if np.any(np.sign(lam_p[full]) != np.sign(lam[full])):
            t = _bow_test(cache, lam_p, len(full), [j for j in undet if j not in (5, 6)], rng)
            # (None: that lens folds the image, so it explains nothing)
            if t is not None and special.chdtrc(t[1], t[0]) >= alpha:
                return False
    return True


def _pp_probes(lam: np.ndarray, det: list[int], rng: np.ndarray) -> list[np.ndarray]:
    """The lens at the corners of the principal point's range (where the lines leave it
    undetermined): radial terms act about the principal point, so their effect on a line
    near the image centre depends on where it is, a second-order effect a derivative at the
    image centre misses."""
    free = [j for j in (5, 6) if j not in det and rng[j] > 0]
    if not free:
        return []
    out = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            p = lam.copy()
            for j, sg in zip((5, 6), (sx, sy), strict=True):
                if j in free:
                    p[j] = sg * rng[j]
            out.append(p)
    return out


def _uniform_msq(corners: Sequence[np.ndarray], centre: np.ndarray) -> np.ndarray:
    """Mean square of a function of the principal point, uniform over its range (the Type B
    distribution every range is taken as), from its values at the centre and at the four
    corners of :func:`_pp_probes` (order (-,-), (-,+), (+,-), (+,+)).

    The function is taken as the quadratic through those five points, c (x^2 + y^2) / 2 +
    gx x + gy y + h x y about the centre (x, y in units of the range): over the uniform square
    its mean is s0 + c/3 and its variance c^2 2/45 + gx^2/3 + gy^2/3 + h^2/9 (the largest of
    the corners would be a bound, not a standard uncertainty). Where any corner is not
    finite (the lens folds there), inf."""
    v = np.asarray(corners, float)
    if not len(v):
        return centre**2
    if not np.all(np.isfinite(v)):
        return np.full_like(centre, np.inf)
    mm, mp, pm, pp = v
    c = (mm + mp + pm + pp) / 4 - centre
    gx = (pm + pp - mm - mp) / 4
    gy = (mp + pp - mm - pm) / 4
    h = (pp + mm - mp - pm) / 4
    return (centre + c / 3) ** 2 + c**2 * 2 / 45 + gx**2 / 3 + gy**2 / 3 + h**2 / 9


def _pp_spread(cache: _DesignCache, lam: np.ndarray, applied: list[int], det: list[int],
               rng: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far the applied estimates move when the principal point is put at the corners of
    its range (one linearised step from ``lam`` each): the largest |move| (a bound: the
    sign test) and its standard uncertainty with the principal point uniform over its range
    (:func:`_uniform_msq`); inf where the lens then folds."""
    P = len(PARAMS)
    if not applied:
        return np.zeros(P), np.zeros(P)
    A = np.ix_(applied, applied)
    moves = []
    for p in _pp_probes(lam, det, rng):
        m = np.zeros(P)
        try:
            ds = cache.all(p)
        except LensFolds:
            m[applied] = np.inf
            moves.append(m)
            continue
        F = sum(d.G.T @ d.G for d in ds)
        b = sum(d.G.T @ d.z for d in ds)
        m[applied] = np.linalg.solve(F[A], b[applied])
        moves.append(m)
    if not moves:
        return np.zeros(P), np.zeros(P)
    return np.max(np.abs(moves), axis=0), np.sqrt(_uniform_msq(moves, np.zeros(P)))


def _pp_probe_s(cache: _DesignCache, lam: np.ndarray, det: list[int], rng: np.ndarray
                ) -> list[np.ndarray]:
    """Each line's variance of d angle / d lam over the principal point's range, uniform
    [rad^2/unit^2]: only the radial terms act about the principal point, so only theirs is
    not zero (inf where the lens folds at a corner)."""
    P = len(PARAMS)
    radial = np.zeros(P)
    radial[:2] = 1.0
    probes = _pp_probes(lam, det, rng)
    if not probes:
        return [np.zeros(P) for _ in cache.lines]

    def radial_s(k: int, p: np.ndarray) -> np.ndarray:
        full = cache.cached(k, p)  # its radial columns are the radial-only design's
        try:
            return full.s * radial if full is not None else cache.one(k, p, (0, 1)).s * radial
        except LensFolds:
            return np.full(P, np.inf)

    out = []
    for k in range(len(cache.lines)):
        s0 = radial_s(k, lam)
        if not np.all(np.isfinite(s0)):
            out.append(np.full(P, np.inf))
            continue
        var = _uniform_msq([radial_s(k, p) for p in probes], s0) - s0**2
        out.append(np.clip(var, 0.0, None))
    return out
