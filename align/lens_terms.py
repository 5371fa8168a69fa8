"""What one camera's lens adds to each mark's angle: the named u terms and their signed
components shared by the marks of one lens (from a :class:`align.lens.LensSolution` or a
calibrated camera's u), the bow a lens can leave on a mark, and the check of the marks against
a calibrated lens."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.lens import LensSolution, _determined
from align.lens_design import DEFAULT_RANGES, LensRanges, LineGeometry, _Design, _design
from imaging import fit_line, line_frame
from imaging.lens import PARAMS, distort_points, undistort_points, undistortion_jacobian


def _signed_parts(sol: LensSolution, design: _Design) -> dict[str, np.ndarray]:
    """Each named lens term of one mark's angle as signed components [rad] on the lens's
    own error directions (the same directions for every mark of one solve): see
    :func:`angle_terms` (their norms) and :func:`angle_coupling` (the components)."""
    P = len(PARAMS)
    A = [j for j in range(P) if sol.applied[j]]
    rng = sol.ranges.vector()
    out: dict[str, np.ndarray] = {}
    s = design.s
    if A:
        # The fitted parameters' covariance C = L L^T: s C s^T = |L^T s|^2, and two marks
        # share (L^T s_i) . (L^T s_j) = s_i C s_j^T.
        w, V = np.linalg.eigh(sol.cov_applied)
        L = V * np.sqrt(np.clip(w, 0.0, None))
        out["lens_fit"] = L.T @ s[A]
        if not sol.confirmed:
            # Lens or bend: the angle with the lens applied and without it both stand, and
            # the bow may be part lens, part bend: the truth anywhere between the two
            # readings, uniform (Type B); about the reading given (the lens applied) its
            # standard uncertainty is the difference / sqrt 3 (the difference itself is the
            # bound, not a standard uncertainty).
            out["lens_or_bend"] = np.array([s[A] @ sol.lam[A] / np.sqrt(3)])
    FA = sol.info[np.ix_(A, A)] if A else None
    for j in range(P):
        if sol.applied[j] or rng[j] <= 0:
            continue
        # What the applied parameters absorb of parameter j's bow changes their estimates,
        # hence the angle: the angle's net sensitivity to j.
        seff = float(s[j] - (s[A] @ np.linalg.solve(FA, sol.info[A, j]) if A else 0.0))
        if design.s_pp_var is not None and not sol.determined[j]:
            # Over the principal point's range (uniform) the sensitivity varies about its
            # value at the centre: its mean square, with the sign it has at the centre.
            seff = float(np.copysign(np.sqrt(seff**2 + float(design.s_pp_var[j])), seff))
        if sol.determined[j]:
            # An estimate beyond the range is no lens (a bent mark's bow): the lens itself
            # is within the range.
            e = min(abs(sol.estimate[j]), rng[j]) if np.isfinite(sol.estimate[j]) else 0.0
            out[f"lens_{PARAMS[j]}_small"] = np.array([seff * np.hypot(e, sol.u_lines[j])])
        else:
            out[f"lens_{PARAMS[j]}_range"] = np.array([seff * rng[j] / np.sqrt(3)])
    return out


def lens_bow(line: LineGeometry, lam: np.ndarray, scale: float) -> np.ndarray:
    """The bow each lens parameter leaves on this line, per unit of it: the sagitta [px] of
    the quadratic across the line over the centres' span (as the mark's loop measures a
    bow: b (t - t_m)^2, sagitta b (span / 2)^2), after a straight line absorbed what it can.
    ``lam``: the lens the centres are undistorted by (zeros: raw or already undistorted).
    Non-finite where the lens folds."""
    q, jac = undistortion_jacobian(line.points, lam, scale)
    if not np.all(np.isfinite(jac)):
        return np.full(len(PARAMS), np.inf)
    lf = fit_line(q, line.sigma, reject_sigma=None, chol=line.chol)
    u, n = line_frame(lf.angle_rad)
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
    return {k: float(np.linalg.norm(v)) for k, v in _signed_parts(sol, design).items()}


def angle_coupling(sol: LensSolution, design: _Design) -> dict[str, float]:
    """The lens terms of one mark's angle as signed components [rad]: for two marks of one
    solve, the sum over shared keys of the products is the covariance their angles share
    through the one lens (every mark of a camera sees the same lens error); each mark's own
    sum of squares is the square sum of :func:`angle_terms`."""
    out: dict[str, float] = {}
    for k, v in _signed_parts(sol, design).items():
        if len(v) == 1:
            out[k] = float(v[0])
        else:
            out.update({f"{k}.{i}": float(x) for i, x in enumerate(v)})
    return out


def camera_coupling(points_ideal: np.ndarray, sigma: np.ndarray, chol: np.ndarray | None,
                    lam: np.ndarray, lam_u: np.ndarray, scale: float) -> dict[str, float]:
    """Signed angle components [rad] of a calibrated camera's own u (one per lens parameter):
    their sizes are a mark's named terms ``camera_<p>``, their products between two marks of
    the camera the covariance the calibration's error puts between their angles.

    ``points_ideal``: the mark's centres already undistorted by the camera; ``lam``/``lam_u``:
    the camera as a lens vector and its standard uncertainties (from ``align camera``)."""
    raw = distort_points(points_ideal, lam, scale)
    d = _design(LineGeometry(raw, sigma, chol), lam, scale)
    return {f"camera_{p}": float(d.s[j] * lam_u[j])
            for j, p in enumerate(PARAMS) if lam_u[j] > 0}


def check_camera(lines: Sequence[LineGeometry], lam: np.ndarray, lam_u: np.ndarray,
                 scale: float, ranges: LensRanges = DEFAULT_RANGES, alpha: float = 1e-3
                 ) -> tuple[float, np.ndarray, list[_Design]]:
    """Whether the marks agree with a calibrated lens: the determined correction to the
    camera's lens from the lines, and its chi2 probability against the lines' u plus the
    camera's u. Returns (p-value, the correction dlam, each mark's design at the camera)."""
    designs = [_design(ln, lam, scale) for ln in lines]
    p, dlam = _camera_departure(designs, lam_u, ranges, alpha)
    return p, dlam, designs


def _camera_departure(designs: Sequence[_Design], lam_u: np.ndarray, ranges: LensRanges,
                      alpha: float) -> tuple[float, np.ndarray]:
    """:func:`check_camera` over the marks' ``designs``: (p-value, correction dlam)."""
    z = float(-special.ndtri(alpha / 2))
    rng = ranges.vector()
    P = len(PARAMS)
    F = sum(d.G.T @ d.G for d in designs)
    b = sum(d.G.T @ d.z for d in designs)
    det = _determined(F, rng, z)
    dlam = np.zeros(P)
    if not det:
        return 1.0, dlam
    D = np.ix_(det, det)
    dlam[det] = -np.linalg.solve(F[D], b[det])
    C = np.linalg.inv(F[D]) + np.diag(lam_u[det] ** 2)
    stat = float(dlam[det] @ np.linalg.solve(C, dlam[det]))
    return float(special.chdtrc(len(det), stat)), dlam


def lone_departures(designs: Sequence[_Design], lam_u: np.ndarray,
                    ranges: LensRanges = DEFAULT_RANGES, alpha: float = 1e-3
                    ) -> tuple[int, ...]:
    """The marks without which the rest agree with the calibrated lens (leave-one-out): a
    departure only one mark calls for is that mark's bow (a bent mark), not the lens's — a
    changed lens bows every mark it reaches, so the departure must stand without any one of
    them. A single mark is alone when its departure is beyond any plausible lens
    (``ranges``). Empty when the departure stands without each mark in turn, or falls without
    any of several (the marks agree on it, or share it)."""
    if len(designs) < 2:
        # One mark cannot show that marks agree: its departure is the lens's only if a lens
        # could make it (within the plausible ranges); beyond them it is the mark's bow.
        p, dlam = _camera_departure(designs, lam_u, ranges, alpha)
        beyond = p < alpha and bool(np.any(np.abs(dlam) > ranges.vector()))
        return (0,) if beyond else ()
    out = []
    for k in range(len(designs)):
        rest = [d for i, d in enumerate(designs) if i != k]
        if _camera_departure(rest, lam_u, ranges, alpha)[0] >= alpha:
            out.append(k)
    if len(out) > 1:
        # The departure falls without any of several marks: the culprit is the one that
        # departs on its own; when none or several do, they share it (a weak but common
        # departure is the lens's: four images of one camera through a lens its model misses).
        out = [k for k in out if _camera_departure([designs[k]], lam_u, ranges, alpha)[0]
               < alpha]
    return tuple(out) if len(out) == 1 else ()


def undistorted(line: LineGeometry, lam: np.ndarray, scale: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """A mark's centres undistorted by ``lam`` and their sigma scaled by the undistortion's
    magnification across the line (a centre moved 1 px across the raw line moves this much
    across the undistorted one)."""
    q = undistort_points(line.points, lam, scale)
    if not np.any(lam):
        return q, line.sigma
    lf = fit_line(q, line.sigma, reject_sigma=None, chol=line.chol)
    n = line_frame(lf.angle_rad)[1]
    q2 = undistort_points(line.points + 0.5 * n, lam, scale)
    g = np.abs((q2 - q) @ n) / 0.5
    return q, line.sigma * g
