"""The principal point's range in the lens solve: where the lines leave the principal point
undetermined, radial terms act about a point anywhere in its range, so the solver probes the
range's corners (how far the fitted lens moves, how each mark's angle sensitivity varies) and
carries the spread as a uniform (Type B) distribution. Used by :mod:`align.lens`.

Where the lens folds along a mark with the principal point at a corner of that range (a
strong k1 and a long mark far from the centre), that principal point is impossible for
those marks: the lines are seen unfolded. The probes are then taken on the largest centred
fraction of the range (:data:`PP_FRACTIONS`) where the lens folds none of them
(:func:`pp_corners`), and the spread is that smaller square's; before, one folding corner
made the whole spread, and every angle's u, infinite."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from align.lens_design import LensFolds, _DesignCache
from imaging.lens import PARAMS, undistort_points

PP_FRACTIONS = (1.0, 0.75, 0.5, 0.25)
"""The fractions of the principal point's range tried, largest first, for the corners at which
the lens folds no mark (:func:`pp_corners`)."""


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


def _folds(cache: _DesignCache, lam: np.ndarray) -> bool:
    """Whether the lens ``lam`` folds the image along any of the cache's lines (an
    undistortion of its centres not finite: :func:`imaging.lens.undistort_points`)."""
    return any(not np.all(np.isfinite(undistort_points(ln.points, lam, cache.scale)))
               for ln in cache.lines)


def pp_corners(cache: _DesignCache, lam: np.ndarray, det: list[int], rng: np.ndarray
               ) -> list[np.ndarray]:
    """The corners of :func:`_pp_probes` on the largest fraction of the principal point's
    range (of :data:`PP_FRACTIONS`) at none of which the lens ``lam`` folds a line: a
    principal point where it would is impossible for these marks. A lens folding them even at
    the smallest fraction gets the full range's corners (its spread then inf)."""
    for f in PP_FRACTIONS:
        out = _pp_probes(lam, det, rng * f)
        if not any(_folds(cache, p) for p in out):
            return out
    return _pp_probes(lam, det, rng)


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
    for p in pp_corners(cache, lam, det, rng):
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
    not zero (over the range shrunk as :func:`pp_corners` does; inf where the lens folds at a
    corner even then)."""
    P = len(PARAMS)
    radial = np.zeros(P)
    radial[:2] = 1.0
    probes = pp_corners(cache, lam, det, rng)
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
