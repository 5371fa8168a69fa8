"""Families of lines: dense sets of short parallel lines (a ruled scale, a grating).

A *family* is at least :data:`MIN_MEMBERS` lines found in one image that run the same way
(directions within :data:`FAMILY_ANGLE`) and lie side by side: each one's middle within
:data:`MAX_GAP` typical gaps of its neighbour across the lines. Once a family is seen, the
image is searched again for lines of that direction down to half the family's typical length
(:data:`MEMBER_FRACTION`) — lines the default ``min_length`` would drop or the block-averaged
search cut short (at a numeral, a dust speck) — and those that fall on the family's ruling
(within :data:`GRID_TOLERANCE` pitch of a multiple of the pitch from its members) join it.
Every family member is reported, whatever ``max_marks`` says; other lines keep that cap, and
what the cap leaves out is counted in :attr:`Detection.unreported`, never dropped silently.
With an explicit ``min_length_px`` (the user's), two parallel lines side by side already seed
the second search, and a family's lines shorter than that are counted as unreported.

A *grating* — many identical lines at a fine pitch, none standing out — is not measured:
the search reads a row of identical lines as a surface's lay (:func:`imaging.detect.
distinctness`) and the groove model needs each line alone in its window.
:func:`imaging.grating.grating_note` recognises one (a sharp peak of the image's power
spectrum) so that the refusal says so, with its pitch and direction.

Geometry as in :mod:`imaging.detect` (pixels relative to the image centre; angles [rad]).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import replace as dc_replace

import numpy as np

from imaging.candidate import may_be_near
from imaging.detect import (
    LENGTH_SLACK,
    MarkCandidate,
    Roi,
    _dedupe,
    _near,
    _overlap,
    _shift,
    default_min_length,
    detect_lines_once,
    line_frame,
    wrap_angle,
)
from imaging.dials import DIAL_MISS_PX, dial_centre, group_dial, line_middle, meets

MIN_MEMBERS = 3
"""Fewest parallel lines side by side that make a family."""
FAMILY_ANGLE = np.deg2rad(2.0)
"""Largest direction difference within a family at detection (the search's angles are good
to ~0.5 deg on short lines); the measured angles are then tested by their chi2."""
MAX_GAP = 3.0
"""Largest gap between neighbouring members, in units of the family's median gap."""
RAW_MEMBERS = 4
"""Fewest parallel unconfirmed candidates side by side that are looked at as a ruling when
the search confirmed no family."""
MEMBER_FRACTION = 0.5
"""A line joins a family from this fraction of the family's median length."""
PIECE_FRACTION = 0.15
"""Pieces of a member cut short (at a numeral, a dust speck) are looked for from this
fraction of the family's median length."""
PIECE_ANGLE = np.deg2rad(10.0)
"""Largest direction difference of such a piece from its member."""
REACH = 20.0, 10.0
"""Least relief window beside a family's line [px]; the second inside a finer pitch
(:func:`_finer_pitch`: 20 reached the next tick at 24 px) or of a family the first search
found (its own window told the members apart at their pitch). Not 10 for every ruling: a
grating's identical lines (10-16 px pitch) were then each confirmed (30 marks, no refusal);
the first search refuses them, and the ruling pass's family keeps 20 px."""
GRID_TOLERANCE = 0.3
"""A joining line lies within this fraction of the pitch of the members' ruling."""


@dataclass(frozen=True)
class Detection:
    """Lines found in one image.

    ``marks``: reported lines (every family member, then the other lines strongest first up
    to ``max_marks``); ``families``: index tuples into ``marks``, one per family, ordered
    across the lines; ``unreported``: lines found but left out (beyond ``max_marks``, or a
    family's lines shorter than an explicit ``min_length_px``).

    Attributes
    ----------
    marks : list of MarkCandidate
        The lines reported.
    families : tuple of tuple of int
        Indexes into ``marks``, one tuple per family.
    unreported : tuple of MarkCandidate
        Lines found but left out.
    """

    marks: list[MarkCandidate]
    families: tuple[tuple[int, ...], ...] = ()
    unreported: tuple[MarkCandidate, ...] = ()


def _position(c: MarkCandidate, ref: float) -> float:
    """Where a line's middle lies across the direction ``ref`` [px]."""
    return float(line_middle(c) @ line_frame(ref)[1])


def replace_shift(c: MarkCandidate, shift: np.ndarray) -> MarkCandidate:
    """A coarse candidate of a roi search in the whole image's frame."""
    return _shift(c, shift) if shift.any() else c


def group_families(cands: list[MarkCandidate], min_members: int = MIN_MEMBERS,
                   miss_px: float = 0.0) -> list[list[int]]:
    """Families among candidates (indices, ordered across the lines; see the module doc).

    ``miss_px``: a line also runs the family's way when its ends lie within this of the
    family's direction through its middle [px] (a short line's detected direction is
    poor: the dense ruler's 48 px ticks, confirmed on the ruling, came out 2.5 deg off and
    fell out of their family, or made one of their own)."""

    def along(i: int, ref: float) -> bool:
        d = abs(wrap_angle(cands[i].angle_rad - ref))
        return bool(d < FAMILY_ANGLE or np.sin(d) * cands[i].length_px / 2 <= miss_px)

    left = list(range(len(cands)))
    out = []
    while left:
        seed = max(left, key=lambda i: cands[i].strength)
        ref = cands[seed].angle_rad
        same = [i for i in left if cands[i].dark == cands[seed].dark and along(i, ref)]
        # The family's direction from all of them (a short seed's own is off by up to ~1
        # deg), and its lines again about that.
        ref = wrap_angle(ref + float(np.median([wrap_angle(cands[i].angle_rad - ref)
                                                for i in same])))
        same = [i for i in left if i == seed or (cands[i].dark == cands[seed].dark
                and along(i, ref))]
        left = [i for i in left if i != seed]
        if len(same) < min_members:
            continue
        same.sort(key=lambda i: _position(cands[i], ref))
        pos = np.array([_position(cands[i], ref) for i in same])
        gaps = np.diff(pos)
        med = float(np.median(gaps))
        # Runs of lines with no gap wider than MAX_GAP median gaps: the seed's run.
        cuts = np.flatnonzero(gaps > MAX_GAP * med) + 1
        for run in np.split(np.array(same), cuts):
            rp = np.array([_position(cands[i], ref) for i in run])
            # Lines closer than two widths are the two edges of one thing (or one line found
            # twice), not a ruling.
            close = rp.size > 1 and np.min(np.diff(rp)) < max(
                8.0, 2 * max(cands[i].thickness_px for i in run))
            if seed in run and len(run) >= min_members and not close:
                out.append([int(i) for i in run])
                left = [i for i in left if i not in run]
    return out


def _ruling(cands: list[MarkCandidate], members: list[int], ref: float
            ) -> tuple[float, float]:
    """(origin, pitch) [px] of the members' ruling: positions = origin + pitch k."""
    pos = np.array([_position(cands[i], ref) for i in members])
    g0 = float(np.min(np.diff(pos)))
    k = np.rint((pos - pos[0]) / g0)
    pitch, origin = np.polyfit(k, pos, 1)
    return float(origin), float(pitch)


FINE_LINES = 3
"""Fewest lines on a ruling finer than the members' that make it the family's."""


def _finer_pitch(members: list[MarkCandidate], pool: list[MarkCandidate], ref: float,
                 origin: float, pitch: float, shift: np.ndarray) -> float:
    """The family's pitch [px] once the lines beside its members are counted: ``pitch`` /
    m when lines of its direction and polarity lie at whole steps of pitch / m (m >= 2).

    A ruler's short ticks at a pitch under the relief window are alike their neighbours
    there: the first search confirms only the long ticks (every 5th: their ruling 5
    pitches), and a half-step test on it joined the ticks near half-steps (5 of 19 lines,
    "pitch 73 px" at 24 px). The finer step is the median gap between neighbouring lines,
    members and candidates together: on a ruling with most lines present, the pitch."""
    u, n = line_frame(ref)
    q_m = np.array([float(line_middle(c) @ n) for c in members])
    t_m = np.array([float(line_middle(c) @ u) for c in members])
    step = abs(pitch)
    lo, hi = q_m.min() - step * MAX_GAP, q_m.max() + step * MAX_GAP
    q = []
    for c in pool:
        p = line_middle(c) + shift
        if (c.dark == members[0].dark and abs(wrap_angle(c.angle_rad - ref)) < FAMILY_ANGLE
                and lo < float(p @ n) < hi
                and t_m.min() - step < float(p @ u) < t_m.max() + step):
            q.append(float(p @ n))
    if len(q) < FINE_LINES:
        return pitch
    allq = np.sort(np.concatenate([q_m, q]))
    gaps = np.diff(allq)
    gaps = gaps[gaps > 3.0]  # one line found twice
    if gaps.size < FINE_LINES:
        return pitch
    m = int(np.rint(step / float(np.median(gaps))))
    if m < 2:
        return pitch
    fine = pitch / m
    k = (np.array(q) - origin) / fine
    on = np.abs(k - np.rint(k)) < GRID_TOLERANCE
    between = on & (np.abs(k / m - np.rint(k / m)) > GRID_TOLERANCE / m)
    return fine if np.count_nonzero(between) >= FINE_LINES else pitch


FADE_SIGMA = 3.0
"""The coarser ridge filter [block px]: a ridge fades about this before each end."""
SHORT_MEMBER = 0.9
"""A member shorter than this fraction of the family's median length is searched over the
members' common stretch (:func:`_span_members`)."""


def _span_members(found: list[MarkCandidate], group: Sequence[int], fade: float = 0.0
                  ) -> None:
    """Members cut short by the search (a bright speck or a numeral across them, and the
    piece beyond too short or too faint to be a candidate of its own) searched over the
    stretch most members share: the median of their ends along the family's direction.

    Only the search's extent grows: the measurement's own end finder
    (:func:`imaging.profile.groove_extent`) and the groove model's test per segment then
    say where the groove is; a line truly shorter than its neighbours keeps its own ends
    (the segments beyond it hold no groove and are left out)."""
    u_ref = line_frame(found[group[0]].angle_rad)[0]
    ends = []
    for i in group:
        c = found[i]
        u, n = line_frame(c.angle_rad)
        s = float(np.sign(u @ u_ref)) or 1.0
        ends.append(sorted((s * c.t_start_px, s * c.t_end_px)))
    lo, hi = np.median(np.array(ends), axis=0)
    typical = float(np.median([found[i].length_px for i in group]))
    for i, (a, b) in zip(group, ends, strict=True):
        c = found[i]
        s = float(np.sign(line_frame(c.angle_rad)[0] @ u_ref)) or 1.0
        if c.length_px < SHORT_MEMBER * typical:
            a, b = min(a, float(lo)), max(b, float(hi))
        t0, t1 = sorted((s * (a - fade), s * (b + fade)))
        found[i] = dc_replace(c, t_start_px=t0, t_end_px=t1)


def joined_pieces(pieces: list[MarkCandidate], gap_px: float, span_px: float
                  ) -> list[MarkCandidate]:
    """Pairs of pieces of one line (a speck across its middle cut the ridge in two, each
    piece under the family's floor: a dense ruler's 70 px tick seen as 18 + 16 px) as one
    candidate: same polarity, each along the other (:data:`PIECE_ANGLE`, 3 px), apart by
    less than ``gap_px`` and together no longer than ``span_px``; its line through both
    middles (each piece's own direction is poor), its extent their union. Each piece is
    used once, the strongest pairs first; the search's confirmation then judges them."""
    out, used = [], set()
    order = sorted(range(len(pieces)), key=lambda i: -pieces[i].strength)
    # Only the pairs that may lie along each other both ways reach the scalar tests
    # (building.jpg's ~270 pieces made ~35k of them, ~0.1 s CPU, for the few that do).
    may = may_be_near(pieces, PIECE_ANGLE, 3.0)
    may &= may.T
    may = may[np.ix_(order, order)]
    for x, i in enumerate(order):
        for j in (order[y] for y in x + 1 + np.flatnonzero(may[x, x + 1:])):
            a, b = pieces[i], pieces[j]
            if i in used or j in used or a.dark != b.dark or _overlap(a, b):
                continue
            if not (_near(a, b, PIECE_ANGLE, 3.0) and _near(b, a, PIECE_ANGLE, 3.0)):
                continue
            ma, mb = line_middle(a), line_middle(b)
            d = mb - ma
            if float(np.hypot(*d)) < 1.0:
                continue
            ang = float(np.arctan2(-d[1], d[0]))  # (x right, y down: +y turns -angle)
            ang = wrap_angle(ang)
            u, n = line_frame(ang)
            ts = [float(ma @ u) + s * a.length_px / 2 for s in (-1, 1)] + \
                 [float(mb @ u) + s * b.length_px / 2 for s in (-1, 1)]
            gap = float(np.hypot(*d)) - (a.length_px + b.length_px) / 2
            if gap >= gap_px or max(ts) - min(ts) > span_px:
                continue
            out.append(dc_replace(a, angle_rad=ang, offset_px=float(0.5 * (ma + mb) @ n),
                                  t_start_px=min(ts), t_end_px=max(ts),
                                  strength=a.strength + b.strength))
            used |= {i, j}
    return out


JOIN_PASSES = 4
"""Most passes of :func:`_join` (each with the family's typical length as it then stands)."""


def _near_step(q: float, anchors: np.ndarray, pitch: float) -> bool:
    """Whether position ``q`` [px] lies a whole (or half) step of the local pitch from the
    nearest of the family's lines (``anchors``, sorted positions), at most :data:`MAX_GAP`
    steps away.

    Through a lens the ruling is not uniform in the image (barrel distortion: a 1600 x 1200
    scale at 54 px pitch read 50 px at the frame's sides, k1 -0.15): a ruling fitted to
    lines on one side misses those across the middle by more than its tolerance. The local
    pitch is the nearest line's gap to its neighbour on the far side from ``q`` (else on
    ``q``'s side), in whole steps of ``pitch``."""
    if anchors.size < 2:
        return False
    j = int(np.argmin(np.abs(anchors - q)))
    d = q - anchors[j]
    far = j - 1 if d > 0 else j + 1
    near = j + 1 if d > 0 else j - 1
    nb = far if 0 <= far < anchors.size else near
    gap = abs(float(anchors[nb] - anchors[j]))
    local = gap / max(1.0, float(np.rint(gap / pitch)))
    if abs(local / pitch - 1) > 0.25:
        local = pitch
    k = d / local
    return abs(k) <= MAX_GAP + GRID_TOLERANCE and abs(2 * k - np.rint(2 * k)) < GRID_TOLERANCE


def _join(found: list[MarkCandidate], members: list[MarkCandidate],
          pool: list[MarkCandidate], on_ruling, half_way, position, search, pitch: float,
          floor: float, least: float = REACH[0]) -> None:
    """Lines of ``pool`` (coarse candidates) on the family's ruling, from ``floor`` px long,
    confirmed and added to ``found`` (a piece of a member the first search joined otherwise
    is that member: the longer one stays).

    The seeds are the lines the first search confirmed: on a scale whose short graduations
    sit at a pitch under its relief window those are the long and medium ones, alike nothing
    beside them, and half their median length is about the short ones' whole length (a
    1600 x 1200 scale at 54 px pitch: short lines of 147 px seen as 78-108 px ridges, 4 of 29
    missed). The family's typical line is what its members are once joined: after each pass
    the floor is half their median length, and lines between the new floor and the old one
    are looked at again; lines joined in one pass are the next pass's neighbours to step
    from (:func:`_near_step`), at most :data:`JOIN_PASSES` passes. ``position``: a line's
    place across the family [px]; ``least``: the least relief window [px].
    """
    lengths = [m.length_px for m in members]
    anchors = sorted(position(m) for m in members)
    tried = [False] * len(pool)
    for _ in range(JOIN_PASSES):
        extra = []
        for k, c in enumerate(pool):
            if not tried[k] and c.length_px >= floor and on_ruling(c, np.array(anchors)):
                tried[k] = True
                extra.append(c)
        if not extra:
            return
        # The relief beside a member is judged between it and its neighbours: the next
        # graduation is no machining streak.
        step = abs(pitch) / (2 if any(half_way(c) for c in extra) else 1)
        reach = float(np.clip(step - max(o.thickness_px for o in members) - 6, least, 60))
        for c in search.confirm(extra, reach):
            twin = next((j for j, o in enumerate(found) if o.dark == c.dark
                         and _near(c, o, FAMILY_ANGLE, max(6.0, o.thickness_px))
                         and _overlap(c, o)), None)
            if twin is None:
                found.append(c)
            elif c.length_px > found[twin].length_px:
                found[twin] = c
            else:
                continue
            lengths.append(c.length_px)
            anchors.append(position(c))
        anchors.sort()
        floor = min(floor, MEMBER_FRACTION * float(np.median(lengths)))


def detect_lines(image: np.ndarray, min_length_px: float | None = None, max_marks: int = 8,
                 roi: Roi | None = None, top: float | None = None,
                 families: bool = True, noise_full: float | None = None,
                 block_means: np.ndarray | None = None) -> Detection:
    """Every line of :func:`imaging.detect.detect_marks`, with families completed.

    Parameters as :func:`~imaging.detect.detect_marks`; ``families``: False finds lines one
    by one only (no second pass; every line under the ``max_marks`` cap).

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN].
    min_length_px : float, optional
        Shortest line reported [px] (default: the detector's own).
    max_marks : int
        Most lines reported (family members not counted against it).
    roi : Roi, optional
        (x, y, w, h) [px] searched.
    top : float, optional
        The image's full scale [DN] (else from the image).
    families : bool
        Complete families of lines (a second pass).
    noise_full, block_means : float, ndarray, optional
        The searched image's pixel noise and block means, when the caller has them
        (:func:`imaging.detect.detect_lines_once`).

    Returns
    -------
    Detection
        The lines, their families and those left out.
    """
    search = detect_lines_once(image, min_length_px, roi=roi, top=top, noise_full=noise_full,
                               block_means=block_means)
    found = list(search.marks)
    # A --min-length above the short lines of a scale leaves only its long ones: two of
    # them side by side seed the search too, and the family's lines below that length are
    # then counted as found but not reported (never dropped unsaid).
    groups = group_families(found, 2 if min_length_px is not None else MIN_MEMBERS) \
        if families else []
    first_seen = [list(g) for g in groups]  # (the ruling pass below may replace them)
    if families and not groups and (not found or (len(found) == 2
                                                  and group_families(found, 2))):
        # Lines at a pitch under the relief window beside each line are alike their
        # neighbours there, and the search refuses them all as a lay. A regular ruling of
        # them among the unconfirmed candidates is confirmed with the window inside the
        # pitch (only when nothing was found, or just two parallel lines side by side — a
        # scale whose other lines a lens bent or a speck marked, 2 of 8 found at 640 x 480
        # with k1 -0.15 —: it costs a second pass over the candidates, and a photograph's
        # many lines, regular window edges among them, are no ruling).
        seed_len = LENGTH_SLACK * (min_length_px if min_length_px is not None
                                   else default_min_length(search.image.shape))
        raw = search.candidates(seed_len)
        for g in group_families(raw, RAW_MEMBERS):
            origin, pitch = _ruling(raw, g, raw[g[0]].angle_rad)
            q = np.array([_position(raw[i], raw[g[0]].angle_rad) for i in g])
            k = (q - origin) / pitch
            if np.max(np.abs(k - np.rint(k))) > GRID_TOLERANCE:
                continue  # not a ruling: streaks of a surface's lay fall anywhere
            reach = float(np.clip(abs(pitch) - max(raw[i].thickness_px for i in g) - 6,
                                  REACH[0], 60))
            got = search.confirm([raw[i] for i in g], reach)
            if len(got) >= MIN_MEMBERS:
                found += [c for c in got if not any(
                    o.dark == c.dark and _near(c, o, FAMILY_ANGLE, max(6.0, o.thickness_px))
                    and _overlap(c, o) for o in found)]
        found = _dedupe(sorted(found, key=lambda c: -c.strength))
        groups = group_families(found, 2 if min_length_px is not None else MIN_MEMBERS)
    for g in groups:
        ref = found[g[0]].angle_rad
        typical = float(np.median([found[i].length_px for i in g]))
        longest = max(found[i].length_px for i in g)
        origin, pitch = _ruling(found, g, ref)
        lo = min(_position(found[i], ref) for i in g) - pitch * (GRID_TOLERANCE + 0.5)
        hi = max(_position(found[i], ref) for i in g) + pitch * (GRID_TOLERANCE + 0.5)
        shift = search.shift
        members = [found[i] for i in g]
        pieces = search.candidates(PIECE_FRACTION * typical)
        # A finer ruling's lines (short ticks: 70 px seen 44-52) join from a quarter length.
        floor = MEMBER_FRACTION * MEMBER_FRACTION * typical
        fine = _finer_pitch(members, [c for c in pieces if c.length_px >= floor], ref, origin,
                            pitch, shift)
        fine_ruling = int(fine != pitch)
        # The first search confirmed these members with its own window, the nearest two one
        # pitch apart (the ruling's pitch is their least gap, _ruling): lines at that pitch
        # stand out each alone, and the others are judged with the window inside it. (A
        # scale at 22 px through k1 -0.15: 10 neighbouring lines found first; with 20 px the
        # window reached the next line and the 10 others were all refused as a lay.)
        inner = int(fine_ruling or g in first_seen)
        floor, pitch = (floor if fine_ruling else MEMBER_FRACTION * typical), fine

        def on_ruling(c: MarkCandidate, anchors: np.ndarray, ref=ref, origin=origin,
                      pitch=pitch, members=members, shift=shift, lo=lo, hi=hi) -> bool:
            # Coarse candidates are in the search's (roi) frame: compare in the image's.
            p = line_middle(c) + shift
            q = float(p @ line_frame(ref)[1])
            k = (q - origin) / pitch
            return (c.dark == members[0].dark
                    and abs(wrap_angle(c.angle_rad - ref)) < FAMILY_ANGLE
                    # A ruling of 3 or more extends over the frame; two lines fix none
                    # (their gap may be any multiple of the pitch): lines near them only.
                    # (Or half-way: every other graduation alike its neighbours was refused
                    # as a lay, the ruling seen at twice its pitch.)
                    and ((abs(2 * k - np.rint(2 * k)) < GRID_TOLERANCE
                          or _near_step(q, anchors, pitch)) if len(members) >= 3
                         else lo - pitch * MAX_GAP < q < hi + pitch * MAX_GAP))

        def half_way(c: MarkCandidate, ref=ref, origin=origin, pitch=pitch,
                     shift=shift) -> bool:
            k = (float((line_middle(c) + shift) @ line_frame(ref)[1]) - origin) / pitch
            return abs(k - np.rint(k)) > GRID_TOLERANCE

        # Pieces along a member (it was cut at a numeral or a dust speck) extend it, across
        # a gap under half the typical length, to at most the longest member's length (the
        # ridge fades over a speck's halo): its measurement then spans the whole graduation
        # (the segments under the speck fail the groove model and are left out there).
        for c in pieces:
            c = replace_shift(c, shift)
            for j, o in enumerate(found):
                # A short piece's direction is poor (a 20 px piece: several degrees); its
                # middle on the member's line is what counts.
                if not (o.dark == c.dark and _near(c, o, PIECE_ANGLE, 3.0)):
                    continue
                u = line_frame(o.angle_rad)[0]
                cu = float(line_middle(c) @ u)
                lo_c, hi_c = cu - c.length_px / 2, cu + c.length_px / 2
                gap = max(lo_c - o.t_end_px, o.t_start_px - hi_c)
                t0, t1 = min(o.t_start_px, lo_c), max(o.t_end_px, hi_c)
                if gap < MEMBER_FRACTION * typical and t1 - t0 <= 1.1 * longest:
                    found[j] = dc_replace(o, t_start_px=t0, t_end_px=t1)
        # Lines that join: the second search's, and the first's it split differently (a
        # numeral's strokes beside a line's end become pieces there, none as long).
        # (Frozen, so hashable: one set, not ~36 x 345 comparisons of their fields.)
        seen = set(pieces)
        pool = pieces + [c for c in search.first if c not in seen]
        # A line cut in two by a speck across its middle, neither piece up to the floor.
        pool += joined_pieces([c for c in pieces if c.length_px < floor],
                              MEMBER_FRACTION * typical, 1.1 * longest)
        _join(found, members, pool, on_ruling, half_way,
              lambda c, ref=ref: _position(c, ref), search, pitch, floor, REACH[inner])
    if groups:
        found = _dedupe(sorted(found, key=lambda c: -c.strength))
        # (Their lines were confirmed on the ruling: a short one's direction is good to
        # about the coarse search's pixel at its ends.)
        groups = group_families(found, miss_px=float(search.f))
        for g in groups:
            # Every member's ridge faded a filter width before each end: a short tick (70
            # px, seen 50) with dust beside it kept under 10 segments that fit (3 of 19).
            _span_members(found, g, FADE_SIGMA * search.f)
    faded = {id(found[i]) for g in groups for i in g}  # (their length, less that, is seen)
    if families:
        # Lines meeting at a point (a dial's graduations): a group too, every one reported,
        # completed by a second search down to half their typical length (as a family's).
        used = {i for g in groups for i in g}
        dial = group_dial(found, [i for i in range(len(found)) if i not in used])
        if dial:
            p = dial_centre(found, dial)
            typical = float(np.median([found[i].length_px for i in dial]))
            shift = search.shift
            extra = [c for c in search.candidates(MEMBER_FRACTION * typical)
                     if c.dark == found[dial[0]].dark
                     and meets(replace_shift(c, shift), p)[0]]
            for c in search.confirm(extra):
                if not any(o.dark == c.dark and _near(c, o, FAMILY_ANGLE,
                                                      max(6.0, o.thickness_px))
                           and _overlap(c, o) for o in found):
                    found.append(c)
            # Two graduations on one diameter are one straight line to the search, joined
            # across the dial's middle: cut at the inner circle, each is a graduation.
            inner = min(float(np.hypot(*(line_middle(found[i]) - p))) - found[i].length_px / 2
                        for i in dial)
            for j, c in enumerate(list(found)):
                if j in used or c.dark != found[dial[0]].dark:
                    continue
                u, n = line_frame(c.angle_rad)
                tp = float(p @ u)
                miss = abs(float(p @ n) - c.offset_px)
                if (miss < DIAL_MISS_PX + 2 and inner > 10
                        and c.t_start_px < tp - inner < tp + inner < c.t_end_px):
                    cut = 0.9 * inner
                    found[j] = dc_replace(c, t_end_px=tp - cut)
                    found.append(dc_replace(c, t_start_px=tp + cut))
            # The parallel families' members first (their order kept), then the others.
            kept = sorted(used)
            others = [c for i, c in enumerate(found) if i not in used]
            found = [found[i] for i in kept] + _dedupe(sorted(others, key=lambda c: -c.strength))
            remap = {old: new for new, old in enumerate(kept)}
            groups = [[remap[i] for i in g] for g in groups]
            dial = group_dial(found, list(range(len(used), len(found))))
            if dial:
                groups = [*groups, dial]
    short: list[int] = []
    if min_length_px is not None:
        # The user's shortest line holds for families too: their shorter members are said.
        short = [i for g in groups for i in g if found[i].length_px - 2 * FADE_SIGMA * search.f
                 * (id(found[i]) in faded) < LENGTH_SLACK * min_length_px]
        groups = [[i for i in g if i not in short] for g in groups]
        groups = [g for g in groups if len(g) >= 2]
    in_family = {i for g in groups for i in g}
    others = [i for i in range(len(found)) if i not in in_family and i not in short]
    keep = [i for g in groups for i in g] + others[:max_marks]
    index = {old: new for new, old in enumerate(keep)}
    return Detection([found[i] for i in keep],
                     tuple(tuple(index[i] for i in g) for g in groups),
                     tuple(found[i] for i in others[max_marks:] + short))
