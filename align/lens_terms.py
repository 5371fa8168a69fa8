"""What one camera's lens adds to each mark's angle: the named u terms and their signed
components shared by the marks of one lens (from a :class:`align.lens.LensSolution` or a
calibrated camera's u), the bow a lens can leave on a mark, and the check of the marks against
a calibrated lens."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.optimize import lsq_linear

from align.lens import LensSolution, _determined
from align.lens_design import DEFAULT_RANGES, LensRanges, LineGeometry, _Design, _design
from align.lens_solution import signed_parts
from imaging import fit_line_only, line_frame
from imaging.lens import PARAMS, undistort_points, undistortion_jacobian


def pp_cross_coupling(sol: LensSolution, design: _Design, scale: float) -> dict[str, float]:
    """The second-order term of an undetermined principal point with a k1 read from the lines
    (applied, fitted free, or determined but not applied), as signed components [rad] shared
    by the marks of one solve (merged into :func:`angle_coupling`'s; keys
    ``lens_pp_cross.0``, ``.1``).

    Each angle's pp coupling is linear about the image centre; the lens's radial field about
    a principal point c [px] off it tilts a line of direction u (normal n) by 2 k1 (n.q)(u.q)
    / R^2 at q = p - c (any length: the chord of k1's bow), whose part of second order,
    2 k1 (n.c)(u.c) / R^2 = 2 k1 [cos 2θ cx cy + sin 2θ (cy^2 - cx^2) / 2] / R^2, is the same
    at every position: with (cx, cy) uniform over ±r, two zero-mean errors uncorrelated with
    the linear terms, of standard uncertainty r^2/3 and r^2 sqrt(2/45). A reversal pair's
    sum cancels the linear pp terms, not these (a roll-like residue of the cx-cy product):
    left out, a fusion reads that residue as a lens parameter and moves E by it. Where k1 is
    undetermined its range already carries s_k1's variation over the pp
    (:func:`align.lens_solution.signed_parts`).
    """
    rng = sol.ranges.vector()
    k1_read = sol.applied[0] or sol.determined[0]  # (applied includes a k1 fitted free)
    if not k1_read or sol.determined[5] or sol.determined[6] or rng[5] <= 0:
        return {}
    if sol.applied[0]:
        k1 = float(np.hypot(sol.lam[0], sol.u_lines[0] if np.isfinite(sol.u_lines[0]) else 0))
    else:
        e = min(abs(sol.estimate[0]), rng[0]) if np.isfinite(sol.estimate[0]) else rng[0]
        k1 = float(np.hypot(e, sol.u_lines[0] if np.isfinite(sol.u_lines[0]) else 0.0))
    r = float(rng[5])
    g = 2.0 * k1 / scale**2
    th = 2.0 * design.angle
    return {"lens_pp_cross.0": g * np.cos(th) * r**2 / 3.0,
            "lens_pp_cross.1": g * np.sin(th) * r**2 * np.sqrt(2.0 / 45.0)}


def lens_bow(line: LineGeometry, lam: np.ndarray, scale: float) -> np.ndarray:
    """The bow each lens parameter leaves on this line, per unit of it: the sagitta [px] of
    the quadratic across the line over the centres' span (as the mark's loop measures a
    bow: b (t - t_m)^2, sagitta b (span / 2)^2), after a straight line absorbed what it can.
    ``lam``: the lens the centres are undistorted by (zeros: raw or already undistorted).
    Non-finite where the lens folds."""
    q, jac = undistortion_jacobian(line.points, lam, scale)
    if not np.all(np.isfinite(jac)):
        return np.full(len(PARAMS), np.inf)
    u, n = line_frame(fit_line_only(q, line.sigma, chol=line.chol)[0])
    E = jac[:, 0, :] * n[0] + jac[:, 1, :] * n[1]
    t = q @ u
    tm = (t.min() + t.max()) / 2
    X = np.column_stack([t - tm, np.ones(len(t)), (t - tm) ** 2])
    beta = np.linalg.lstsq(X, E, rcond=None)[0][2]
    return beta * (np.ptp(t) / 2) ** 2


def bow_reach(sol: LensSolution, z: float) -> np.ndarray:
    """How far each lens parameter may still be from the applied lens (per PARAMS, in its
    unit): its plausible range when the lines leave it undetermined, |estimate| + z u when
    determined but not applied, z u when applied."""
    rng = sol.ranges.vector()
    out = np.zeros(len(PARAMS))
    for j in range(len(PARAMS)):
        uj = sol.u_lines[j]
        if sol.applied[j]:
            out[j] = z * uj if np.isfinite(uj) else rng[j]
        elif sol.determined[j]:
            e = sol.estimate[j] if np.isfinite(sol.estimate[j]) else 0.0
            out[j] = min(abs(e) + z * uj, rng[j]) if np.isfinite(uj) else rng[j]
        else:
            out[j] = rng[j]
    return out


def angle_terms(sol: LensSolution, design: _Design) -> dict[str, float]:
    """Named standard uncertainties [rad] the lens adds to one mark's angle."""
    return {k: float(np.linalg.norm(v)) for k, v in signed_parts(sol, design).items()}


def angle_coupling(sol: LensSolution, design: _Design) -> dict[str, float]:
    """The lens terms of one mark's angle as signed components [rad]: for two marks of one
    solve, the sum over shared keys of the products is the covariance their angles share
    through the one lens (every mark of a camera sees the same lens error); each mark's own
    sum of squares is the square sum of :func:`angle_terms`."""
    out: dict[str, float] = {}
    for k, v in signed_parts(sol, design).items():
        if len(v) == 1:
            out[k] = float(v[0])
        else:
            out.update({f"{k}.{i}": float(x) for i, x in enumerate(v)})
    return out


def lens_cov(lam_u: np.ndarray) -> np.ndarray:
    """The calibrated lens's covariance in the lens vector (per PARAMS, in their units):
    ``lam_u`` as given when it is one ((P, P): a camera model's joint covariance,
    :func:`align.camera_lens.camera_lens_cov`), else its standard uncertainties taken as
    independent (a camera file before format 4)."""
    a = np.asarray(lam_u, float)
    return a if a.ndim == 2 else np.diag(a**2)


def check_camera(lines: Sequence[LineGeometry], lam: np.ndarray, lam_u: np.ndarray,
                 scale: float, ranges: LensRanges = DEFAULT_RANGES, alpha: float = 1e-3
                 ) -> tuple[float, np.ndarray, list[_Design]]:
    """Whether the marks agree with a calibrated lens: the determined correction to the
    camera's lens from the lines, and its chi2 probability against the lines' u plus the
    camera's u (``lam_u``: standard uncertainties per PARAMS, or the joint covariance,
    :func:`lens_cov`). Returns (p-value, the correction dlam, each mark's design at the
    camera)."""
    designs = [_design(ln, lam, scale) for ln in lines]
    p, dlam = camera_departure(designs, lam_u, ranges, alpha)
    return p, dlam, designs


def _normal(designs: Sequence[_Design], rng: np.ndarray, z: float
            ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The marks' normal equations for a lens change (F, b) and the parameters they
    determine within the plausible ranges ``rng`` at ``z`` (:func:`align.lens._determined`)."""
    F = sum(d.G.T @ d.G for d in designs)
    b = sum(d.G.T @ d.z for d in designs)
    return F, b, _determined(F, rng, z)


def _change_cov(F: np.ndarray, det: list[int], lam_u: np.ndarray) -> np.ndarray:
    """The covariance of the change the marks read for the determined parameters ``det``:
    their noise, F_DD^-1, plus the calibration's error (``lam_u``, :func:`lens_cov`). The
    change read for the determined parameters also carries the calibration's error in the
    others, through the marks' bows they share (F's off-diagonal block):
    dlam_D = e_D + F_DD^-1 F_DU e_U."""
    P = F.shape[0]
    D = np.ix_(det, det)
    A = np.zeros((len(det), P))
    A[:, det] = np.eye(len(det))
    und = [j for j in range(P) if j not in det]
    A[:, und] = np.linalg.solve(F[D], F[np.ix_(det, und)])
    return np.linalg.inv(F[D]) + A @ lens_cov(lam_u) @ A.T


def camera_departure(designs: Sequence[_Design], lam_u: np.ndarray, ranges: LensRanges,
                      alpha: float) -> tuple[float, np.ndarray]:
    """:func:`check_camera` over the marks' ``designs``: (p-value, correction dlam)."""
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    P = len(PARAMS)
    F, b, det = _normal(designs, rng, z)
    dlam = np.zeros(P)
    if not det:
        return 1.0, dlam
    D = np.ix_(det, det)
    dlam[det] = -np.linalg.solve(F[D], b[det])
    C = _change_cov(F, det, lam_u)
    stat = float(dlam[det] @ np.linalg.solve(C, dlam[det]))
    return float(special.chdtrc(len(det), stat)), dlam


LINEAR_SHARE = 0.25
"""The share of a mark's departure (in its noise units) a plausible lens may leave and still
make it: the design is linear in the change, and a change as large as the plausible ranges
(k1 0.3 at the half-diagonal, a model of the wrong sign: twice that) moves the bow by terms
of second order, a fraction of the bow of that order (the real lens through its sign-flipped
model: 2.5 %; a bent mark that needs k1 +1.3 on top of an exact model: ~65 %)."""


def _plausible_fits(designs: Sequence[_Design], lam_u: np.ndarray, ranges: LensRanges,
                    alpha: float, model: np.ndarray | None) -> bool:
    """Whether a plausible lens — the camera's ``model`` (lens vector) plus a change, within
    ``ranges`` widened to the model's own values — makes the marks' departure as well as the
    best change does, within its uncertainty: the nearest such lens to the best change (in
    the change's covariance plus the calibration's, a box-bounded least squares) is inside
    the change's confidence region at ``alpha``, or leaves under :data:`LINEAR_SHARE` of
    it. The whole lens, not the change alone: a
    model with k1 and k2 of the wrong sign needs a change of twice the lens's, which the
    true (plausible) lens makes; one mark determines k1 and k2 only together, so the best
    change alone may lie beyond the ranges when a plausible one fits as well."""
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    base = np.zeros(len(PARAMS)) if model is None else np.asarray(model, float)
    F, b, det = _normal(designs, rng, z)
    if not det:
        return True
    D = np.ix_(det, det)
    dlam = -np.linalg.solve(F[D], b[det])
    # The change's covariance as the check's (:func:`camera_departure`): the calibration's
    # error in the undetermined parameters aliases into the determined ones.
    C = _change_cov(F, det, lam_u)
    W = np.linalg.cholesky(np.linalg.inv(C)).T  # |W v|^2 = v' C^-1 v
    bound = np.maximum(rng, np.abs(base))[det]
    fit = lsq_linear(W, W @ dlam, bounds=(-bound - base[det], bound - base[det]))
    return (float(special.chdtrc(len(det), 2 * fit.cost)) >= alpha
            or np.sqrt(2 * fit.cost) <= LINEAR_SHARE * float(np.linalg.norm(W @ dlam)))


def lone_departures(designs: Sequence[_Design], lam_u: np.ndarray,
                    ranges: LensRanges = DEFAULT_RANGES, alpha: float = 1e-3,
                    model: np.ndarray | None = None) -> tuple[int, ...]:
    """The marks without which the rest agree with the calibrated lens (leave-one-out): a
    departure only one mark calls for is that mark's bow (a bent mark), not the lens's — a
    changed lens bows every mark it reaches, so the departure must stand without any one of
    them. A single mark is alone when the lens its departure calls for — the camera's
    ``model`` (lens vector, default 0) plus the change — is beyond any plausible lens
    (``ranges``, widened to the model's own values). Empty when the departure stands without
    each mark in turn, or falls without any of several (the marks agree on it, or share it)."""
    if len(designs) < 2:
        # One mark cannot show that marks agree: its departure is the lens's only if a lens
        # could make it (within the plausible ranges); beyond them it is the mark's bow.
        p, _ = camera_departure(designs, lam_u, ranges, alpha)
        beyond = p < alpha and not _plausible_fits(designs, lam_u, ranges, alpha, model)
        return (0,) if beyond else ()
    out = []
    for k in range(len(designs)):
        rest = [d for i, d in enumerate(designs) if i != k]
        if camera_departure(rest, lam_u, ranges, alpha)[0] >= alpha:
            out.append(k)
    if len(out) > 1:
        # The departure falls without any of several marks: the culprit is the one that
        # departs on its own; when none or several do, they share it (a weak but common
        # departure is the lens's: four images of one camera through a lens its model misses).
        out = [k for k in out if camera_departure([designs[k]], lam_u, ranges, alpha)[0]
               < alpha]
    if len(out) == 1 and _shared(out[0], designs, lam_u, ranges, alpha):
        return ()
    return tuple(out) if len(out) == 1 else ()


def _shared(k: int, designs: Sequence[_Design], lam_u: np.ndarray, ranges: LensRanges,
            alpha: float) -> bool:
    """Whether the other marks show the bow the change mark ``k`` calls for (the changed lens
    at least as likely as straight marks, from :func:`_predict`): a departure they share, if
    too weak in them to stand without ``k``, is the lens's, not ``k``'s bend. Not shared
    when ``k`` alone determines no change to predict from, or one beyond any lens."""
    rest = [d for i, d in enumerate(designs) if i != k]
    pr = _predict([designs[k]], rest, lam_u, ranges.vector(), float(-special.ndtri(alpha / 2)))
    if pr is None or pr.beyond or pr.separation == 0.0:
        return False
    # The others' bow along the prediction, t: N(0, var_bend) if they are straight, N(sep,
    # var_lens) if the lens changed as k calls for (one mark's change is loosely determined:
    # var_lens is wide, so "within its u" alone would call every lone bend shared). Shared
    # when the lens reading is at least as likely as the straight one.
    ll_lens = (pr.t - pr.separation) ** 2 / pr.var_lens + np.log(pr.var_lens)
    ll_bend = pr.t**2 / pr.var_bend + np.log(pr.var_bend)
    return bool(ll_lens <= ll_bend)


@dataclass(frozen=True)
class LensOrBends:
    """Which of two explanations of marks that depart from a calibrated lens the data hold:
    the lens changed (every mark then shows the bow the change predicts at its position) or
    the departing marks are bent (the others straight, the calibration kept).

    Attributes
    ----------
    verdict : str
        ``lens`` (one changed lens predicts every mark from the others' bows, and the marks
        that do not depart show the bow it predicts for them), ``bends`` (they are straight
        and do not show the bow the departing marks' change predicts for them, or no
        plausible lens makes the departing marks' bows), ``undecided`` (both fit: the other
        marks are too near the centre, too short or too few to tell them apart) or
        ``neither`` (no one lens predicts every mark, and no straight mark shows the
        calibration holds: bent marks and a changed lens cannot be told apart).
    departing : tuple of int
        The marks that depart from the calibration on their own (the bent ones if bent).
    dlam : numpy.ndarray
        The lens change (per PARAMS, in its unit) the agreeing marks call for (the lens
        reading).
    separation : float
        How far apart the two explanations put the other marks' bow, in its standard
        uncertainty (the test's power: small means the data cannot tell).
    seen : float
        The other marks' bow along the predicted one, in units of the predicted (1: as
        the lens change predicts, 0: straight).
    """

    verdict: str
    departing: tuple[int, ...]
    dlam: np.ndarray
    separation: float = 0.0
    seen: float = float("nan")
    dropped: tuple[int, ...] = ()
    """Departing marks that do not fit the changed lens the others agree on (bent on top
    of it, when the verdict is ``lens``)."""


@dataclass(frozen=True)
class _Prediction:
    """What a lens change fitted from some marks predicts for others: the separation |g| of
    "straight" and "bowed as predicted" and the others' bow along g, t [sd], with the
    variance of t under each."""

    separation: float
    t: float
    var_bend: float
    var_lens: float
    beyond: bool


def _predict(fit: Sequence[_Design], test: Sequence[_Design], lam_u: np.ndarray,
             rng: np.ndarray, z: float) -> _Prediction | None:
    """The change the ``fit`` marks call for, tested on the ``test`` marks (None: the fit
    marks determine no lens parameter)."""
    F, b, det = _normal(fit, rng, z)
    if not det:
        return None
    D = np.ix_(det, det)
    C = np.linalg.inv(F[D])
    dlam = -np.linalg.solve(F[D], b[det])
    # A change beyond any plausible lens (by more than its own u) is no lens's.
    beyond = bool(np.any(np.abs(dlam) - z * np.sqrt(np.diag(C)) > rng[det]))
    g = [d.G[:, det] @ dlam for d in test]
    sep = float(np.sqrt(sum(gi @ gi for gi in g)))
    if sep == 0.0:
        return _Prediction(0.0, 0.0, 1.0, 1.0, beyond)
    # The test marks' whitened residual z along the predicted correction g: t = -g.z/|g| is
    # N(0, 1 + the calibration's own u along g) if they are straight under the calibration,
    # N(|g|, 1 + the change's estimation variance along g) if the lens changed.
    t = -sum(gi @ d.z for gi, d in zip(g, test, strict=True)) / sep
    h = sum(d.G.T @ gi for gi, d in zip(g, test, strict=True)) / sep
    return _Prediction(sep, float(t), 1.0 + float(h @ lens_cov(lam_u) @ h),
                       1.0 + float(h[det] @ C @ h[det]), beyond)


def _explained(F: np.ndarray, b: np.ndarray, idx: Sequence[int]) -> float:
    """How much of the marks' chi2 (information ``F``, ``b``) a lens change over the
    parameters ``idx`` takes away: b^T F^-1 b over them."""
    if not idx:
        return 0.0
    D = np.ix_(idx, idx)
    return float(b[idx] @ np.linalg.solve(F[D], b[idx]))


def _agreement(k: int, with_: Sequence[int], designs: Sequence[_Design],
               Fb: Sequence[tuple[np.ndarray, np.ndarray]], rng: np.ndarray, z: float
               ) -> tuple[float, float]:
    """How well mark ``k`` agrees with the lens change the marks ``with_`` call for: the
    p-value of one change fitted to both against each's own (the chi2 the joint fit adds,
    on as many degrees of freedom as parameters both determine), and the chi2 per degree of
    freedom. A mark that determines none of them on its own is tested by its bow: the
    quadratic across it left after the others' change, against its noise and the change's
    u. ``Fb``: each mark's (G^T G, G^T z).

    The joint fit is over every parameter either side determines: where both determine the
    same ones this is the chi2 of their two estimates' difference; where one side also
    determines k2, the other's k1 is not read with k2 held at 0 (a change of k1 on top of a
    model bows a long mark at the frame's corner with a k2 part too: two straight 240/220 px
    marks then 'disagreed' at chi2 12.2 on one dof and a changed lens was called 'neither';
    1.4 now)."""
    F = sum(Fb[i][0] for i in with_)
    b = sum(Fb[i][1] for i in with_)
    det = _determined(F, rng, z)
    Fk, bk = Fb[k]
    det_k = _determined(Fk, rng, z)
    both = [j for j in det_k if j in det]
    if not both:
        P = len(rng)
        dl, Cr = np.zeros(P), np.zeros((P, P))
        if det:
            D = np.ix_(det, det)
            dl[det] = -np.linalg.solve(F[D], b[det])
            Cr[D] = np.linalg.inv(F[D])
        d = designs[k]
        wG = d.w @ d.G
        r = float(d.w @ d.z + wG @ dl)
        stat = r**2 / (1.0 + float(wG @ Cr @ wG))
        return float(special.chdtrc(1, stat)), stat
    union = sorted(set(det) | set(det_k))
    stat = max(_explained(Fk, bk, det_k) + _explained(F, b, det)
               - _explained(F + Fk, b + bk, union), 0.0)
    return float(special.chdtrc(len(both), stat)), stat / len(both)


MAX_DROPPED = 4
"""Most departing marks tried as bent on top of a changed lens (the subsets searched grow
as 2^this)."""


def _agreeing(designs: Sequence[_Design], departing: Sequence[int], rng: np.ndarray,
              z: float, alpha: float) -> list[int] | None:
    """The largest set of marks that agree on one lens change (each with the rest, at
    ``alpha``), dropping only departing marks (up to :data:`MAX_DROPPED`; a mark that does
    not depart is straight under the calibration and stays), at least two; among sets of
    that size the one that agrees best. None: no such set."""
    Fb = [(d.G.T @ d.G, d.G.T @ d.z) for d in designs]
    n = len(designs)
    for r in range(min(len(departing), MAX_DROPPED) + 1):
        best, best_p = None, -1.0
        for drop in itertools.combinations(departing, r):
            keep = [k for k in range(n) if k not in drop]
            if len(keep) < 2:
                continue
            p = min(_agreement(k, [i for i in keep if i != k], designs, Fb, rng, z)[0]
                    for k in keep)
            if p >= alpha and p > best_p:
                best, best_p = keep, p
        if best is not None:
            return best
    return None


def _departs(d: _Design, lam_u: np.ndarray, ranges: LensRanges, alpha: float) -> bool:
    """Whether one mark departs from the calibrated lens on its own: the change it alone
    calls for stands, or its bow (the quadratic across it, which a mark that determines no
    lens parameter on its own still shows) is beyond its noise and the calibration's u."""
    if camera_departure([d], lam_u, ranges, alpha)[0] < alpha:
        return True
    wG = d.w @ d.G
    var = 1.0 + float(wG @ lens_cov(lam_u) @ wG)
    return abs(d.bow_z) > float(-special.ndtri(alpha / 2)) * np.sqrt(var)


def lens_or_bends(designs: Sequence[_Design], lam_u: np.ndarray,
                  ranges: LensRanges = DEFAULT_RANGES, alpha: float = 1e-3
                  ) -> LensOrBends | None:
    """Tell a changed lens from several bent marks (None: fewer than two marks, or no mark
    departs on its own, so a departure is the marks' shared one: the lens's).

    A change of the lens bows every mark by what its position predicts (distance from the
    principal point, foot of the perpendicular, length); a bent mark bends whatever its
    position. Two explanations, each tested:

    * bends: the change the departing marks call for (:func:`_predict`), on the marks that
      do not depart — straight (t ~ 0) or bowed as predicted (t ~ separation)? Untestable
      without such marks.
    * a changed lens: marks that agree (:func:`_agreement`, each with the others) on one change
      within the plausible ranges, found by dropping the worst departing mark in turn (a
      departing mark may be bent on top of a changed lens; a mark that does not depart may
      not be dropped: it is straight under the calibration); the change must stand (the
      agreeing marks depart from the calibration together), and the marks that do not
      depart must show the bow it predicts for them.
    """
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    n = len(designs)
    if n < 2:
        return None
    departing = tuple(k for k in range(n) if _departs(designs[k], lam_u, ranges, alpha))
    if not departing:
        return None
    keep = _agreeing(designs, departing, rng, z, alpha)
    dlam = np.zeros(len(PARAMS))
    lens_fits = False
    if keep is not None:
        p_keep, dlam = camera_departure([designs[i] for i in keep], lam_u, ranges, alpha)
        pk = _predict([designs[i] for i in keep], [], lam_u, rng, z)
        # The change must stand (the agreeing marks depart together) and be a lens's.
        lens_fits = p_keep < alpha and not (pk is not None and pk.beyond)
    dropped = () if keep is None else tuple(k for k in range(n) if k not in keep)
    others = [designs[k] for k in range(n) if k not in departing]
    pr = (_predict([designs[k] for k in departing], others, lam_u, rng, z) if others
          else None)
    if pr is None:
        # No straight mark to test the bends by (or the departing marks determine nothing).
        return LensOrBends("lens" if lens_fits else "neither", departing, dlam,
                           dropped=dropped)
    bends_fit = abs(pr.t) <= z * np.sqrt(pr.var_bend)
    # The other marks show the bow the departing marks' change predicts for them, within
    # its u: they cannot rule the changed lens out, so a bend is no more than one reading
    # (the other camera's model on user 12's rig: two of three marks read as bent beside a
    # third that showed +0.58 of a 3.2 sigma prediction, or -0.91 of 1.3 sigma; their
    # angles kept the calibration, 6.8 and 8.0 u off).
    lens_seen = not pr.beyond and abs(pr.t - pr.separation) <= z * np.sqrt(pr.var_lens)
    if bends_fit and lens_seen and not lens_fits and keep is None:
        dlam = camera_departure(designs, lam_u, ranges, alpha)[1]
    verdict = ("undecided" if bends_fit and (lens_fits or lens_seen) else "bends" if bends_fit
               else "lens" if lens_fits else "neither")
    seen = pr.t / pr.separation if pr.separation else float("nan")
    return LensOrBends(verdict, departing, dlam, pr.separation, seen, dropped=dropped)


def undistorted(line: LineGeometry, lam: np.ndarray, scale: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """A mark's centres undistorted by ``lam`` and their sigma scaled by the undistortion's
    magnification across the line (a centre moved 1 px across the raw line moves this much
    across the undistorted one)."""
    q = undistort_points(line.points, lam, scale)
    if not np.any(lam):
        return q, line.sigma
    n = line_frame(fit_line_only(q, line.sigma, chol=line.chol)[0])[1]
    q2 = undistort_points(line.points + 0.5 * n, lam, scale)
    g = np.abs((q2 - q) @ n) / 0.5
    return q, line.sigma * g
