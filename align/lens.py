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
(|value| > z u) and it lies within the plausible range; the rest are set to zero. A k1
whose sign stays open may instead be fitted free with the lines (the angle marginalised over
it, not applied as the lens), when that gives the angles the smaller u
(:func:`_marginalise`).

The angle of each mark then carries, as named terms:

* ``lens_fit``: the fitted parameters' covariance (applied or fitted free) propagated into
  the angle (Type A), with how far the undetermined principal point (uniform over its range)
  moves them;
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

A given camera model replaces all this: its covariance is propagated instead (``camera_model``),
and the lines only test it (see :func:`align.lens_terms.check_camera`). The ranges and each
mark's design are :mod:`align.lens_design`'s; the terms above are :mod:`align.lens_terms`'s.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.lens_design import (
    DEFAULT_RANGES,
    LensFolds,
    LensRanges,
    LineGeometry,
    _Design,
    _DesignCache,
    gauss_newton,
)
from align.lens_exact import plausible_exact
from align.lens_pp import _pp_probe_s, _pp_probes, _pp_spread
from align.lens_solution import LensSolution, lens_angle_var
from imaging.lens import PARAMS

__all__ = ["LensFolds", "LensRanges", "LensSolution", "LineGeometry", "lens_angle_var",
           "solve_lens"]


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
    There a parameter whose sign the other lines leave open stays carried in u (no free fit:
    the bent line's own angle is read by its loop).
    """
    cache = _DesignCache(lines, scale)
    rng = ranges.vector()
    memo: list[tuple[float, float, np.ndarray]] = []

    def exact(lam: np.ndarray, applied: Sequence[bool]) -> tuple[float, float, np.ndarray]:
        # The exact test of all the lines about the lens solved (:func:`_solve` asks when the
        # linearised one disagrees, to word its note; the bent-line search below): made once.
        if not memo:
            memo.append(plausible_exact(cache, lam, applied, rng))
        return memo[0]

    sol, designs, free_fit, fits = _solve(cache, ranges, alpha, iters,
                                          exact=exact if len(lines) >= 3 else None)
    if len(lines) < 3 or _plausible(sol, designs, alpha) >= alpha:
        return free_fit()
    p, chi2, lam = exact(sol.lam, sol.applied)
    if p >= alpha:
        # No line is bent: a lens within every range explains them all (the lines' own
        # free fit may still leave the ranges, and says so; the angles carry it in u). Said
        # here unless the linearised test's note (not confirmed) said it already.
        sf, df = free_fit()
        if not sol.confirmed:
            return sf, df
        note = (f"a lens within every plausible range explains all {len(lines)} lines' bows "
                f"(chi2 {chi2:.1f}, p {p:.2g}; k1 {lam[0]:+.3f}, k2 {lam[1]:+.3f}, principal "
                f"point ({lam[5]:+.0f}, {lam[6]:+.0f}) px): no mark is bent")
        return replace(sf, notes=(note, *sf.notes)), df
    best: tuple[float, int, LensSolution] | None = None
    for k in range(len(lines)):
        try:
            sk, dk, _, _ = _solve(cache.without(k), ranges, alpha, iters, fits)
        except LensFolds:
            continue
        p = _plausible(sk, dk, alpha)
        if p < alpha:  # (the same exact test as for all the lines, started from theirs)
            p = plausible_exact(cache.without(k), sk.lam, sk.applied, rng, start=lam)[0]
        if p >= alpha and (best is None or p > best[0]):
            best = (p, k, sk)
    if best is None:
        return free_fit()
    _, k, sk = best
    # The lines but k solved again from zero: the warm starts above only rank the lines (a
    # Gauss-Newton stop leaves the lens ~1e-3 of its range from where zero's path ends),
    # the lens given is the one from zero, whatever the other lines' fits were.
    sk = _solve(cache.without(k), ranges, alpha, iters)[0]
    try:
        ds = cache.all(sk.lam)
    except LensFolds:
        return free_fit()
    det = [j for j in range(len(PARAMS)) if sk.determined[j]]
    probes = _pp_probe_s(cache, sk.lam, det, ranges.vector())
    dof = len(lines) - int(sum(sol.applied))
    note = (f"line {k} of {len(lines)}: its bow fits no lens that the other line(s) agree on "
            f"(all lines: no plausible lens, chi2 {chi2:.1f} on {dof} dof): a "
            "bent mark, left out of the lens")
    # A lens beyond the ranges may explain every line as well as one bent mark does: with a
    # line to spare the lines cannot tell them apart, and the note says both (the bent
    # reading is the one within the ranges the user declared).
    pw, chi2w, lw = plausible_exact(cache, sol.lam, sol.applied, 2 * rng)
    # A parameter of that fit on its bound (twice its range) is where the search stopped,
    # not the best lens beyond the ranges: that lies further out, and was not found (no
    # value to declare). (building.jpg: k1 +0.600 on the bound of 2 x 0.3.)
    edge = [PARAMS[j] for j in range(len(PARAMS))
            if rng[j] > 0 and abs(lw[j]) >= 2 * rng[j] * (1 - 1e-6)]
    fit = f"k1 {lw[0]:+.3f}, k2 {lw[1]:+.3f}, chi2 {chi2w:.1f}"
    if pw >= alpha:
        note = (f"no lens within the plausible ranges fits these {len(lines)} lines (chi2 "
                f"{chi2:.1f} on {dof} dof); one fits all but line {k}, and " + (
                    f"one at the edge of twice the ranges fits all ({fit}; {', '.join(edge)} "
                    "on that bound: the best lens lies further out, not found): a lens far "
                    "beyond the ranges (calibrate the camera)" if edge else
                    f"one beyond them fits all ({fit}): a lens beyond the ranges (declare "
                    "it: --lens k1=..., or calibrate the camera)")
                + f" or a bent mark (line {k}, left out of the lens)")
    sk = replace(sk, notes=(note, *sk.notes), n_lines=len(lines), bent_lines=(k,))
    return sk, [replace(d, s_pp_var=v) for d, v in zip(ds, probes, strict=True)]


def _plausible(sol: LensSolution, designs: Sequence[_Design], alpha: float) -> float:
    """p-value of the lines' bows left once the applied lens and every other parameter within
    its plausible range explain what they can (1 with no line to spare)."""
    rng = sol.ranges.vector()
    others = [j for j in range(len(PARAMS)) if not sol.applied[j] and rng[j] > 0]
    bz = _bows_left(designs, others, rng, [j for j in range(len(PARAMS)) if sol.applied[j]])
    dof = len(bz) - sum(sol.applied)
    return float(special.chdtrc(dof, float(bz @ bz))) if dof > 0 else 1.0


def _solve(cache: _DesignCache, ranges: LensRanges, alpha: float, iters: int,
           starts: Mapping[tuple[int, ...], np.ndarray] | None = None,
           exact: Callable[[np.ndarray, Sequence[bool]], tuple[float, float, np.ndarray]]
           | None = None) -> tuple[LensSolution, list[_Design],
                      Callable[[], tuple[LensSolution, list[_Design]]],
                      dict[tuple[int, ...], np.ndarray]]:
    """:func:`solve_lens` over all of the lines of ``cache``: the solution with every
    parameter whose sign the lines leave open carried in u, its designs, and the call that
    returns the solution the angles are read under (:func:`_marginalise`: made only for the
    solution given, not for the lines' leave-one-out tests), and its Gauss-Newton fits per
    applied set: ``starts`` for the leave-one-out solves (all lines but one: the fit of
    all of them is a step or two from theirs, where zero took five and more). ``exact``:
    the exact plausibility test (:func:`align.lens_exact.plausible_exact` about a lens
    vector and its applied parameters), asked when the linearised bow test disagrees: a
    lens within every range that explains all the lines names no mark bent."""
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    P = len(PARAMS)
    lam = np.zeros(P)
    lines, scale = cache.lines, cache.scale
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
        lam = fits[tuple(applied)] = gauss_newton(cache, applied, rng, iters,
                                                   (starts or {}).get(tuple(applied)))
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
        # Applied only with its sign determined under every principal point the lines allow
        # (a radial term's bow scales with the line's distance from the principal point).
        bound = _p_with_decentring(rng, lam, u_lines, det, scale, z)
        # The spread (>= 0) only adds to z u: where no parameter passes without it, none is
        # kept whatever it is, and its probes (four designs of every line, most of a
        # leave-one-out solve's CPU: building.jpg's bows put k1 beyond any lens in each) are
        # not made. Its u is then never read: the applied set is empty next.
        keep = []
        if any(abs(lam[j]) > z * u_lines[j] and abs(lam[j]) <= bound[j] for j in applied):
            spread, spread_u = _pp_spread(cache, lam, applied, det, rng)
            spread_for = list(applied)
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
    n_pts = sum(len(ln.points) for ln in lines)
    c2 = float(sum(d.z @ d.z for d in designs))
    dof = max(n_pts - 2 * len(lines) - len(applied), 1)
    # A bow is a lens only if the camera's other lines agree: the lines' bows left after the
    # lens, and after what the undetermined parameters can make within their ranges, must
    # be noise (chi2 over lines - fitted parameters). With no line to spare (one mark, or as
    # many marks as parameters) a lens and a bent mark are the same bow.
    undet = [j for j in range(P) if j not in det and rng[j] > 0]
    bz = _bows_left(designs, undet, rng, applied)
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
            said = (f"the lines' bows disagree with one lens (chi2 {bow_chi2:.1f} on "
                    f"{bow_dof} dof; mark {worst} worst, {bz[worst]:+.1f} u)")
            # Far from zero the bows are not linear in the lens: the exact test's word.
            ex = exact(lam_out, [j in applied for j in range(P)]) if exact else None
            if ex is None or ex[0] < alpha:
                notes.append(f"{said}: a bent mark; u covers the lens and no lens")
            else:
                p, chi2, lam_x = ex
                notes.append(f"{said} (linearised about the lens fitted), but a lens within "
                             f"every plausible range explains them all (chi2 {chi2:.1f}, p "
                             f"{p:.2g}; k1 {lam_x[0]:+.3f}, principal point "
                             f"({lam_x[5]:+.0f}, {lam_x[6]:+.0f}) px): no mark is bent; u "
                             "covers the lens and no lens")
    sol = LensSolution(lam_out, tuple(j in det for j in range(P)),
                       tuple(j in applied for j in range(P)), u_lines, est, cov, ranges,
                       len(lines), c2 / dof, tuple(notes), F, bool(confirmed), bow_chi2,
                       bow_dof)

    def free_fit() -> tuple[LensSolution, list[_Design]]:
        # (The sensitivities' spread over the principal point's range only for the solution
        # given: the leave-one-out tests of solve_lens read the bows alone.)
        s_pp_var = _pp_probe_s(cache, lam_out, det, rng)
        ds = [replace(d, s_pp_var=v) for d, v in zip(designs, s_pp_var, strict=True)]
        s, ds = _marginalise(cache, sol, ds, iters, bound)
        return replace(s, notes=s.notes + _carried_notes(s, bound)), ds

    return replace(sol, notes=sol.notes + _carried_notes(sol, bound)), designs, free_fit, fits


def _carried_notes(sol: LensSolution, bound: np.ndarray) -> tuple[str, ...]:
    """The notes on the parameters the angles carry in u rather than apply: determined but
    not applied (sign open, or beyond any lens: ``bound``), fitted free, not determined."""
    rng = sol.ranges.vector()
    out = []
    for j, p in enumerate(PARAMS):
        e, u = sol.estimate[j], sol.u_lines[j]
        if sol.free[j]:
            out.append(f"lens {p} fitted free with each angle ({sol.lam[j]:.3g} ± {u:.2g} "
                       "from the lines, its sign not determined: not applied as the lens): "
                       "the angle marginalised over it (u from the joint covariance, "
                       "lens_fit), smaller than carrying it over its range")
        elif sol.determined[j] and not sol.applied[j]:
            why = (f"beyond any lens (|{p}| <= {bound[j]:.3g}"
                   + (", the principal point's range included" if bound[j] > rng[j] else "")
                   + "): not a lens"
                   if np.isfinite(e) and abs(e) > bound[j] else "sign not determined")
            out.append(f"lens {p} = {e:.3g} ± {u:.2g} from the lines: {why}; not applied, "
                       "carried in u")
    und = [p for j, p in enumerate(PARAMS)
           if not sol.determined[j] and not sol.free[j] and rng[j] > 0]
    if und:
        out.append(f"lens {', '.join(und)} not determined by these {sol.n_lines} line(s): "
                   "carried in u over their plausible range")
    return tuple(out)


FREE_CANDIDATES = (0,)
"""The parameters (indices into PARAMS) the solver may fit free when their sign is open: k1,
the one whose bow a single mark can see (k2 at the half-diagonal is the same bow at one
mark's scale, p and aspect bow a line far less; the principal point has its own probes)."""


def _marginalise(cache: _DesignCache, sol: LensSolution, designs: list[_Design], iters: int,
                 bound: np.ndarray) -> tuple[LensSolution, list[_Design]]:
    """The estimator of the angles with the smaller u: a parameter whose sign the lines do
    not determine (:data:`FREE_CANDIDATES`) carried over its range (or as its estimate +- u),
    as ``sol`` has it, or fitted free with the lines, the angle read at its estimate (clipped
    to the plausible range: the lens is within it) with u from the joint covariance (the
    angle marginalised over it: Type A, through the angle's sensitivity to it). Which one
    does not depend on the data's values, only on the lines' geometry and noise (their
    information matrix), so the choice biases nothing: min u, per mark for one mark, by the
    marks' summed variance for a lens shared by several (one lens vector per camera). The
    free fit is no claim about the lens: its sign is not determined, so it is not reported
    as applied (``free``), and the parameters applied before keep their signs or the free
    fit is not taken. A parameter the lines put beyond any lens (``|estimate| > bound``, the
    note's "not a lens": a bent mark's or clutter's bow) is no candidate: fitted free it would
    sit clipped at the range's edge, a lens the lines contradict (a 4000 x 3000 scene's
    k1 = 12.9 +- 0.045 read that way turned one angle 8 deg)."""
    rng = sol.ranges.vector()
    est = np.where(np.isfinite(sol.estimate), np.abs(sol.estimate), 0.0)
    cand = [j for j in FREE_CANDIDATES if not sol.applied[j] and rng[j] > 0
            and not (sol.determined[j] and est[j] > bound[j])]
    if not cand:
        return sol, designs
    P = len(PARAMS)
    A = [j for j in range(P) if sol.applied[j]]
    A2 = sorted(A + cand)
    det = [j for j in range(P) if sol.determined[j]]
    if not _conditioned(sol.info, A2, rng):
        return sol, designs  # the lines see no bow of it at all: nothing to fit it from
    lam = gauss_newton(cache, A2, rng, max(iters, 8), start=sol.lam)
    lam[cand] = np.clip(lam[cand], -rng[cand], rng[cand])
    if np.any(np.sign(lam[A]) != np.sign(sol.lam[A])):
        return sol, designs
    try:
        ds = cache.all(lam)
        spread_u = _pp_spread(cache, lam, A2, det, rng)[1]
    except LensFolds:
        return sol, designs
    if not np.all(np.isfinite(spread_u[A2])):
        return sol, designs
    F = sum(d.G.T @ d.G for d in ds)
    if not _conditioned(F, A2, rng):
        return sol, designs
    cov = np.linalg.inv(F[np.ix_(A2, A2)]) + np.diag(spread_u[A2] ** 2)
    u_lines = sol.u_lines.copy()
    u_lines[cand] = np.sqrt(np.diag(cov))[[A2.index(j) for j in cand]]
    free = tuple(j in cand for j in range(P))
    # The lens-or-bend reading is of a lens claimed (its sign determined): it stays the
    # applied parameters' (none: confirmed, nothing claimed).
    alt = replace(sol, lam=lam, applied=tuple(j in A2 for j in range(P)), u_lines=u_lines,
                  cov_applied=cov, info=F, free=free, confirmed=sol.confirmed or not A)
    ds = [replace(d, s_pp_var=v) for d, v in zip(ds, _pp_probe_s(cache, lam, det, rng),
                                                  strict=True)]
    v_carry = sum(lens_angle_var(sol, d) for d in designs)
    v_free = sum(lens_angle_var(alt, d) for d in ds)
    return (alt, ds) if v_free < v_carry else (sol, designs)


def _bows_left(designs: Sequence[_Design], undet: Sequence[int], rng: np.ndarray,
               fitted: Sequence[int] = ()) -> np.ndarray:
    """Each line's bow [its u] left once the undetermined parameters ``undet`` explain what
    they can within their ranges: ridge least squares with each one's plausible range as
    its prior standard deviation (so a bow they could make is not a disagreement, and one
    beyond their reach stays). The parameters' bows are read in each line's own bow
    direction (``w``); the ridge's prior term is spread over the lines, so the squared sum
    is the penalised chi2.

    The ``fitted`` parameters (those the lens at the designs was fitted in) move with them,
    free: their fit absorbed the undetermined ones' bows as they stood at zero, and a
    principal point elsewhere in its range changes what they absorb. Held at their fit,
    straight lines through a lens inside every range were called bent (k1 fitted -0.131
    about the centre, the true -0.167 about a principal point 36 px off: chi2 30 on 3 dof,
    5.2 with k1 moving too)."""
    bz = np.array([d.bow_z for d in designs])
    if not undet:
        return bz
    cols = [*fitted, *undet]
    B = np.array([d.w @ d.G[:, cols] for d in designs])
    prior = np.concatenate([np.zeros(len(fitted)), 1.0 / rng[list(undet)] ** 2])
    delta = np.linalg.lstsq(B.T @ B + np.diag(prior), B.T @ bz, rcond=None)[0]
    left = bz - B @ delta
    pen = float(delta @ (prior * delta))
    # Spread the prior's share over the lines (their sum of squares is the statistic).
    return left * np.sqrt(1.0 + pen / max(float(left @ left), 1e-300))


def _bow_test(cache: _DesignCache, lam: np.ndarray, k: int, undet: Sequence[int],
              rng: np.ndarray) -> tuple[float, int] | None:
    """The lines' bows left at ``lam`` (``k`` parameters fitted; ``undet`` as in
    :func:`_bows_left`, the fitted ones held: which parameters the lines need, not whether a
    line is bent): (chi2, dof), None when the lens folds the image or no line is to spare."""
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
                lam_full = gauss_newton(cache, full, rng, 5)
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
        lam_p = gauss_newton(cache, full, rng, 8, start=probe, search=True)
        if np.any(np.sign(lam_p[full]) != np.sign(lam[full])):
            t = _bow_test(cache, lam_p, len(full), [j for j in undet if j not in (5, 6)], rng)
            # (None: that lens folds the image, so it explains nothing)
            if t is not None and special.chdtrc(t[1], t[0]) >= alpha:
                return False
    return True


def _conditioned(F: np.ndarray, idx: list[int], rng: np.ndarray) -> bool:
    """Whether the information ``F`` over the parameters ``idx`` (range-normalised) can be
    inverted: a parameter whose bow no line shows (a mark through the centre sees no k1)
    makes it singular."""
    Fs = F[np.ix_(idx, idx)] * np.outer(rng[idx], rng[idx])
    return bool(np.all(np.isfinite(Fs)) and np.linalg.cond(Fs) < 1e12)
