"""A coarse mark found by the search, and how two of them compare (one mark found twice,
pieces along one line); regions of interest.

Geometry convention (whole package): x = column, y = row (down), pixel centres at integers,
coordinates relative to the image centre ((W-1)/2, (H-1)/2). A line has angle a in
(-pi/2, pi/2] from +x towards -y, direction u = (cos a, -sin a), normal n = (sin a, cos a),
offset d = n . p, position along it t = u . p.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from imaging.crossing import MIN_CROSSING, crossing_stretch
from imaging.errors import ImageInputError


@dataclass(frozen=True)
class MarkCandidate:
    """A coarse mark: line (angle [rad], offset [px]), extent along it [px], polarity,
    strength (contrast x length) and mean ridge contrast (in units of the response noise).

    ``fused``: (t [px], separation [px]) where the line is seen to be two grooves that part
    on either side of it (two marks crossing at a shallow angle, fused into one ridge along
    their bisector; :func:`imaging.crossing.fused_crossing`); None: one groove.

    Attributes
    ----------
    angle_rad : float
        Direction of the line, (-pi/2, pi/2] [rad] (x right, y up).
    offset_px : float
        Signed distance of the line from the image centre [px].
    t_start_px, t_end_px : float
        Extent along the line [px].
    dark : bool
        A groove darker than the surface.
    thickness_px : float
        Width of the ridge response [px].
    strength : float
        Contrast x length (ranks the candidates).
    contrast : float
        Mean ridge contrast, in units of the response noise — dimensionless.
    fused : tuple of float or None
        (t [px], separation [px]) of two fused grooves, None for one groove.
    """

    angle_rad: float
    offset_px: float
    t_start_px: float
    t_end_px: float
    dark: bool
    thickness_px: float
    strength: float
    contrast: float = float("inf")
    fused: tuple[float, float] | None = None

    @property
    def length_px(self) -> float:
        return self.t_end_px - self.t_start_px


def line_frame(angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction u and normal n of a line at ``angle_rad`` in (x right, y down) pixels.

    Parameters
    ----------
    angle_rad : float
        The line's direction [rad].

    Returns
    -------
    u, n : ndarray
        Unit vectors (2,) along and across the line (dimensionless).
    """
    return (np.array([np.cos(angle_rad), -np.sin(angle_rad)]),
            np.array([np.sin(angle_rad), np.cos(angle_rad)]))


_WRAP_ULPS = 4 * np.finfo(float).eps
"""[rad] How near -pi/2 a wrapped direction counts as -pi/2 itself (a few ulps of pi/2)."""


def wrap_angle(angle_rad: float) -> float:
    """Wrap a line direction to (-pi/2, pi/2].

    Parameters
    ----------
    angle_rad : float
        A line's direction [rad].

    Returns
    -------
    float
        The same line's direction in (-pi/2, pi/2] [rad].
    """
    a = float((angle_rad + np.pi / 2) % np.pi - np.pi / 2)
    # Only -pi/2 itself (to rounding) becomes +pi/2: a relative tolerance here (np.isclose's
    # 1e-5, i.e. 3.2") snapped every line up to 3" past vertical onto exactly 90 deg.
    return np.pi / 2 if a <= -np.pi / 2 + _WRAP_ULPS else a


Roi = tuple[int, int, int, int]


def check_roi(values: object, where: str = "roi") -> Roi:
    """A region of interest (x, y, w, h) [px] from 4 numbers, or an ImageInputError naming
    ``where``: x = column and y = row of the top-left corner, w x h at least 16 x 16 px.

    Parameters
    ----------
    values : object
        Four whole numbers (x, y, w, h) [px].
    where : str
        The flag or key it came from (``--roi``, ``[images] roi``), for the message.

    Returns
    -------
    Roi
        (x, y, w, h) [px].

    Raises
    ------
    ImageInputError
        Not four whole numbers, a negative corner, or smaller than 16 x 16 px.
    """
    try:
        parts = [float(v) for v in values]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        parts = []
    if len(parts) != 4 or any(v != int(v) for v in parts) or min(parts[:2]) < 0 or \
            min(parts[2:]) < 16:
        text = ",".join(map(str, values)) if isinstance(values, list | tuple) else values
        raise ImageInputError(f"{where} = {text!r}: expected four whole numbers X,Y,W,H "
                              "(top-left column and row, width and height >= 16 px)")
    x, y, w, h = (int(v) for v in parts)
    return x, y, w, h


def _shift(c: MarkCandidate, s: np.ndarray) -> MarkCandidate:
    """The candidate in a frame whose centre lies at -s from the current one [px]."""
    u, n = line_frame(c.angle_rad)
    return replace(c, offset_px=float(c.offset_px + s @ n), t_start_px=float(c.t_start_px + s @ u),
                   t_end_px=float(c.t_end_px + s @ u))


def _dedupe(cands: list[MarkCandidate]) -> list[MarkCandidate]:
    """The same mark found at two scales or twice: keep the strongest.

    Only of one polarity: a dark mark and the bright strip of background beside it (between
    it and a padded border, say) are two things, and the strip must not replace the mark.
    """
    tol = np.deg2rad(3)
    out: list[MarkCandidate] = []
    # The kept ones' direction, normal, offset, reach and polarity as arrays (grown by
    # doubling): each candidate is tested against all of them at once with a slack of
    # 1e-6 (rad, px) for the rounding, and the exact scalar test runs only on those left.
    # building.jpg's ~400 candidates made ~70k scalar tests (~0.4 s CPU) before.
    cap = max(len(cands), 1)
    ang, off = np.empty(cap), np.empty(cap)
    nrm, reach = np.empty((cap, 2)), np.empty(cap)
    dark = np.empty(cap, bool)
    for c in cands:
        k = len(out)
        if k:
            u, n = line_frame(c.angle_rad)
            mid = c.offset_px * n + 0.5 * (c.t_start_px + c.t_end_px) * u
            d = np.abs((c.angle_rad - ang[:k] + np.pi / 2) % np.pi - np.pi / 2)
            may = (dark[:k] == c.dark) & (d < tol + 1e-6)
            may &= np.abs(nrm[:k] @ mid - off[:k]) < reach[:k] + 1e-6
            if any(_near(c, out[j], tol, max(6.0, out[j].thickness_px)) and _overlap(c, out[j])
                   for j in np.flatnonzero(may)):
                continue
        ang[k], off[k], nrm[k] = c.angle_rad, c.offset_px, line_frame(c.angle_rad)[1]
        reach[k], dark[k] = max(6.0, c.thickness_px), c.dark
        out.append(c)
    return out


def _near(c: MarkCandidate, o: MarkCandidate, tol_angle: float, tol_px: float) -> bool:
    """Whether c lies along o: directions within tol_angle, c's middle within tol_px of o's
    line. (Comparing offsets instead would multiply a small angle difference by the lever
    arm from the image centre.)"""
    if abs(wrap_angle(c.angle_rad - o.angle_rad)) >= tol_angle:
        return False
    u, n = line_frame(c.angle_rad)
    mid = c.offset_px * n + 0.5 * (c.t_start_px + c.t_end_px) * u
    return abs(float(mid @ line_frame(o.angle_rad)[1]) - o.offset_px) < tol_px


def may_be_near(cands: Sequence[MarkCandidate], tol_angle: float, tol_px: float
                ) -> np.ndarray:
    """Whether each candidate may lie along each other (:func:`_near`), for all pairs at once.

    Parameters
    ----------
    cands : sequence of MarkCandidate
        The candidates (n).
    tol_angle : float
        Largest difference of directions [rad].
    tol_px : float
        Largest distance of one's middle from the other's line [px].

    Returns
    -------
    ndarray
        (n, n) bool: ``[i, j]`` False where ``_near(cands[i], cands[j], ...)`` is surely
        False (a necessary condition with a slack of 1e-6 rad and px for the rounding of
        these sums against the scalar test's, which decides those left).
    """
    ang = np.array([c.angle_rad for c in cands], dtype=float)
    off = np.array([c.offset_px for c in cands], dtype=float)
    mid_t = np.array([0.5 * (c.t_start_px + c.t_end_px) for c in cands], dtype=float)
    u = np.column_stack([np.cos(ang), -np.sin(ang)]).reshape(-1, 2)
    n = np.column_stack([np.sin(ang), np.cos(ang)]).reshape(-1, 2)
    mid = off[:, None] * n + mid_t[:, None] * u
    d = np.abs((ang[:, None] - ang[None, :] + np.pi / 2) % np.pi - np.pi / 2)
    return (d < tol_angle + 1e-6) & (np.abs(mid @ n.T - off[None, :]) < tol_px + 1e-6)


def _overlap(c: MarkCandidate, o: MarkCandidate) -> bool:
    """Whether two nearly coincident candidates share part of their length."""
    if abs(c.angle_rad - o.angle_rad) > np.pi / 2:  # directions opposite: t runs backwards
        return -c.t_end_px < o.t_end_px and o.t_start_px < -c.t_start_px
    return c.t_start_px < o.t_end_px and o.t_start_px < c.t_end_px


def require_single(cands: list[MarkCandidate], where: str) -> MarkCandidate:
    """The one mark an image is expected to hold, or a clear error."""
    if not cands:
        raise ImageInputError(f"{where}: no mark found (no long straight line stands out)")
    if len(cands) > 1 and cands[1].strength > 0.5 * cands[0].strength:
        raise ImageInputError(
            f"{where}: two competing marks (strengths {cands[0].strength:.0f} and "
            f"{cands[1].strength:.0f}) where one was expected")
    return cands[0]


def _drop_fused(cands: list[MarkCandidate]) -> list[MarkCandidate]:
    """Fused ridges of two crossing marks that were themselves found: not a mark.

    Where two marks cross at a shallow angle their grooves fuse into one ridge along the
    bisector: a third line, between the two in direction, that lies within a groove's reach
    of both over its whole length (a mark there could not be measured apart from them)."""
    return unfused(cands, fused_covers(cands))


def unfused(cands: list[MarkCandidate], covers: list[list[int]]) -> list[MarkCandidate]:
    """The lines of ``cands`` that are no fused ridge, given :func:`fused_covers` of them
    (or of a longer list of the same lines in the same order, its indices mapped to these
    and those not among them left out: coverage is a test of each pair alone)."""
    return [c for c, s in zip(cands, covers, strict=True)
            if not _straddled(c, [cands[j] for j in s])]


def fused_covers(cands: list[MarkCandidate]) -> list[list[int]]:
    """Per line of ``cands``, the indices (in order) of the others, of its polarity and not
    fused themselves, that lie within a groove's reach of it over its whole length: those
    whose ridges may fuse into it (:func:`_drop_fused`)."""
    # Per line, the lines that cover it first, then whether two of them lie on either side
    # of it in direction: n^2 coverage tests, not a test per triple (n^3: building.jpg's
    # ~400 candidates took ~100 s CPU that way).
    if not cands:
        return []
    angle = np.array([o.angle_rad for o in cands])
    offset = np.array([o.offset_px for o in cands])
    half = np.array([max(6.0, 2 * o.thickness_px) for o in cands])
    out = []
    for c in cands:
        whole = (c.t_start_px, c.t_end_px)
        # A line covers c only if its window stretch, 2 half / sin of the angle between
        # them, spans c's length less the slack at both ends, and (_may_cover) where its
        # line lies within half of c's does (necessary conditions, so the few left are
        # tested in full).
        sin = np.abs(np.sin(angle - c.angle_rad))
        with np.errstate(divide="ignore"):
            may = 2 * half / sin >= (whole[1] - whole[0] - 2 * half) - 1e-6
        may &= _may_cover(c, angle, offset, half)
        # (those that may, in order: building.jpg's ~400 candidates made ~160k Python
        # iterations over the others, ~0.1 s CPU, to reach the few that may)
        out.append([j for j in np.flatnonzero(may).tolist()
                    if (o := cands[j]) is not c and o.dark == c.dark and o.fused is None
                    and _covers(c, o, max(6.0, 2 * o.thickness_px), whole)])
    return out


def _may_cover(c: MarkCandidate, angle: np.ndarray, offset: np.ndarray, half: np.ndarray
               ) -> np.ndarray:
    """Whether each line (``angle`` [rad], ``offset`` [px], ``half`` its window [px]) can
    cover c (:func:`_covers`), for all at once: it crosses c's direction by at least
    :data:`imaging.crossing.MIN_CROSSING`, and the stretch of c along which its whole line
    lies within ``half`` of c (crossing_stretch's, before that is cut to either extent)
    spans c's extent less ``half`` at both ends. Necessary, with a 1e-6 px slack for the
    rounding of these sums against crossing_stretch's: building.jpg's ~400 candidates made
    ~130k full tests, ~2.7 s CPU, that this leaves out without changing which are kept."""
    rel = angle - c.angle_rad
    sin, cos = -np.sin(rel), np.cos(rel)  # o's direction on c's normal and on c's direction
    ok = np.abs(sin) >= np.sin(MIN_CROSSING) * (1 - 1e-9)
    sin = np.where(ok, sin, 1.0)
    d0 = offset * cos - c.offset_px  # o's point at s = 0, from c's line
    s1, s2 = (-half - d0) / sin, (half - d0) / sin
    t0 = offset * np.sin(rel)  # that point along c
    t1, t2 = t0 + s1 * cos, t0 + s2 * cos
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    return (ok & (lo <= c.t_start_px + half + 1e-6) & (hi >= c.t_end_px - half - 1e-6))


def _straddled(c: MarkCandidate, side: list[MarkCandidate]) -> bool:
    """Whether c's direction lies strictly between those of two lines of ``side`` (an
    earlier o1 and a later o2 with wrap(c - o1) and wrap(o2 - c) of one sign)."""
    before_pos = before_neg = False
    for o in side:
        d2 = wrap_angle(o.angle_rad - c.angle_rad)
        if (before_pos and d2 > 0) or (before_neg and d2 < 0):
            return True
        d1 = wrap_angle(c.angle_rad - o.angle_rad)
        before_pos, before_neg = before_pos or d1 > 0, before_neg or d1 < 0
    return False


def _covers(c: MarkCandidate, o: MarkCandidate, half_px: float,
            whole: tuple[float, float]) -> bool:
    """Whether line o lies within half_px of c over c's whole extent (o's ridge may stop
    where the fused one begins: its groove counts on through the fused stretch)."""
    got = crossing_stretch(c, o, half_px, extend=True)
    return got is not None and got[0] <= whole[0] + half_px and got[1] >= whole[1] - half_px
