"""A frame's families and dials among its measured marks (:mod:`imaging.families` grouped
them), with what the frame's one lens leaves on them.

The lens's share: the frame's lens (a camera model, the lens the lines determined, or the
plausible range of what they leave undetermined — :mod:`align.camera_lens`) is one for every
member, so its u moves them together. On a family's pitch it enters through each member's
position: every lens parameter j, at its standard u u_j (:func:`lens_u_vector`), moves the
members' middles by J_i u_j (J_i the undistortion's Jacobian at the middle,
:func:`imaging.lens.undistortion_jacobian`), and the pitch by the least-squares slope of
those moves over the ruling steps; the parameters add in quadrature. On a dial's increment it
enters through the members' angles: the increment is a weighted sum of them, so its share per
lens error direction is that sum of the members' signed couplings
(:attr:`align.mark_result.MarkResult.lens_coupling`), and the directions add in quadrature.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from align.camera_lens import CAMERA_MODEL, LENS_TERMS, claimed_lens, undistorted_mark
from align.family import line_family, member_ends, shading_shift
from align.lens import LensRanges
from align.line_dial import line_dial
from align.mark_result import MarkResult
from align.mark_stage import half_diagonal
from imaging import MarkMeasurement, Roi, detect_lines, line_frame
from imaging.families import MIN_MEMBERS
from imaging.grating import grating_regions
from imaging.lens import PARAMS, distort_points, undistortion_jacobian

__all__ = ["DIAL_SPREAD", "family_note", "grating_notes", "lens_or_bend_vector", "lens_u_vector",
           "offset_lens_u", "with_families"]


def lens_u_vector(record: Mapping | None) -> np.ndarray:
    """Standard u of each lens parameter (:data:`imaging.lens.PARAMS` order, at the
    half-diagonal) that the frame's lens record (``MarkResult.lens``) leaves: a camera
    model's own u; for a lens from the lines, an applied parameter's u from them, a
    determined one not applied its |estimate| (within the range) and u together, an
    undetermined one its plausible range as a uniform (range / sqrt 3) — as each mark's
    angle carries them (:func:`align.lens_terms.angle_coupling`); zeros when declared
    distortion-free or unknown."""
    out = np.zeros(len(PARAMS))
    if not record:
        return out
    if record.get("source") == CAMERA_MODEL:
        return np.asarray(record.get("u_lens_vector", out), float)
    if record.get("source") != "marks" or "parameters" not in record:
        return out
    rng = LensRanges.from_dict(record.get("ranges", {})).vector()

    def num(v: object) -> float:
        return float("nan") if v is None else float(v)  # type: ignore[arg-type]

    for j, p in enumerate(PARAMS):
        q = record["parameters"].get(p, {})
        ul, est = num(q.get("u_from_lines")), num(q.get("estimate"))
        if q.get("applied"):
            out[j] = ul if np.isfinite(ul) else rng[j]
        elif q.get("determined"):
            e = min(abs(est), rng[j]) if np.isfinite(est) else 0.0
            out[j] = float(np.hypot(e, ul if np.isfinite(ul) else 0.0))
        else:
            out[j] = rng[j] / np.sqrt(3)
    return out


def lens_or_bend_vector(record: Mapping | None) -> np.ndarray:
    """The applied lens parameters (:data:`imaging.lens.PARAMS` order) when no other line
    confirms them (``confirmed_by_other_lines`` false: the bows may be the marks' own):
    the members' positions with that lens and without it both stand, as each angle's
    ``lens_or_bend`` term says (:mod:`align.lens`); zeros otherwise."""
    out = np.zeros(len(PARAMS))
    if (not record or record.get("source") != "marks"
            or record.get("confirmed_by_other_lines", True)):
        return out
    for j, p in enumerate(PARAMS):
        q = record.get("parameters", {}).get(p, {})
        if q.get("applied") and q.get("value") is not None:
            out[j] = float(q["value"])
    return out


def lens_shifts(middles: np.ndarray, record: Mapping | None, shape: tuple[int, int]
                ) -> np.ndarray:
    """(N, 2, P + 1) moves of the members' middles [px] (relative to the image centre,
    already corrected for the lens as far as it is known) per lens parameter at its
    standard u, and, last, the applied lens no other line confirms: with it minus without
    it, the truth uniform between them, / sqrt 3 (Type B, the angles' ``lens_or_bend``:
    a 23-line scale through an undeclared k1 -0.3 lens read 70.0 px with the lens the
    lines gave, 66.2 without it)."""
    u = lens_u_vector(record)
    lam = lens_or_bend_vector(record)
    if not np.any(u) and not np.any(lam):
        return np.zeros((len(middles), 2, len(PARAMS) + 1))
    _, jac = undistortion_jacobian(np.asarray(middles, float), np.zeros(len(PARAMS)),
                                   half_diagonal(shape))
    jac = np.nan_to_num(jac)
    return np.concatenate([jac * u[None, None, :], (jac @ lam)[:, :, None] / np.sqrt(3)],
                          axis=2)


def claimed_middle(m: MarkMeasurement, record: Mapping | None) -> np.ndarray:
    """A member's middle [px]: its groove ends' mean, undistorted only by the lens parameters
    the frame's record calls applied. A parameter fitted free (sign open,
    :func:`align.lens._marginalise`) is the angles' estimator, no claim about the lens, and
    :func:`lens_u_vector` carries it as not applied (|estimate| and u): the positions, and
    so the pitch, must be where that u is about. The mark's centres are taken back to the
    sensor and undistorted by the claimed lens, and its line fitted again there (its ends'
    mean on the free fit's line is off the sensor's by about the lens's sagitta): a
    lens-free scale read 62.886 px through a free k1 of 0.006 +- 0.003 (truth 62.971, its
    own u 0.0003 px), 62.971 now."""
    if not record or record.get("source") != "marks":
        return m.ends_px.mean(axis=0)
    par = record.get("parameters", {})
    lam = np.array([float(par.get(p, {}).get("value") or 0.0) for p in PARAMS])
    claimed = claimed_lens(lam, record)
    if np.array_equal(lam, claimed):
        return m.ends_px.mean(axis=0)
    r = half_diagonal(m.image_shape)
    raw = replace(m, points=distort_points(m.points, lam, r),
                  ends_px=distort_points(m.ends_px, lam, r))
    return undistorted_mark(raw, claimed).ends_px.mean(axis=0)


def offset_lens_u(points: np.ndarray, angle_rad: float, record: Mapping | None,
                  shape: tuple[int, int]) -> float:
    """The standard uncertainty [px] the frame's lens (its record, ``MarkResult.lens``)
    leaves on one mark's offset: each lens column of :func:`lens_shifts` (a parameter at its
    standard u; the applied lens no other line confirms) moves the mark's centres
    (``points``, relative to the image centre, corrected for the lens as far as it is known)
    across the line, and the straight line refitted to those moves moves the offset by its
    value at the foot of the perpendicular from the image centre (t = 0); the columns add in
    quadrature, as the pitch's. Zero when the lens leaves nothing (declared distortion-free,
    or unknown)."""
    pts = np.asarray(points, float)
    if pts.ndim != 2 or len(pts) < 2:
        return 0.0
    # The lens's moves are smooth along a mark: 65 of its centres, evenly spread, give the
    # term within 2 % of all of them (an 800-centre mark: 3.639 -> 3.690 px) at a tenth of
    # the cost.
    pts = pts[np.unique(np.linspace(0, len(pts) - 1, 65).round().astype(int))]
    moves = lens_shifts(pts, record, shape)
    if not np.any(moves):
        return 0.0
    # The undistorted centres are relative to the principal point; the offset is from the
    # image centre: a principal point off by c moves the lens's field by c (what is left
    # here), not the image (its translation, -c, added back: with it, the undetermined
    # principal point's 20 px range alone would put 23 px in every offset's u).
    u_lens = lens_u_vector(record)
    for j, axis in ((PARAMS.index("cx"), 0), (PARAMS.index("cy"), 1)):
        moves[:, axis, j] += u_lens[j]
    u, n = line_frame(angle_rad)
    across = moves[:, 0, :] * n[0] + moves[:, 1, :] * n[1]  # (N, columns) [px]
    # The straight line a + b t through each column's moves, its a (t = 0): normal equations.
    t = pts @ u
    X = np.array([[len(t), t.sum()], [t.sum(), t @ t]])
    a = np.linalg.solve(X, np.vstack([across.sum(0), t @ across]))[0]
    return float(np.linalg.norm(a))


DIAL_SPREAD = np.deg2rad(10.0)
"""A group whose lines' directions spread wider than this is a dial, not a family."""


def _wrap_all(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi / 2) % np.pi - np.pi / 2


def with_families(results: list[MarkResult], families: Sequence[Sequence[int]],
                  unreported: int, lens: str, alpha: float = 1e-3,
                  image: np.ndarray | None = None) -> list[MarkResult]:
    """The image's results with each family's :class:`align.family.LineFamily` on its
    measured members, and the count of lines found but not reported on every entry. With
    the ``image``, every mark's ends are checked for obstructions (dust, ink:
    :func:`align.family.member_ends`), a family's members' and single marks' alike: its
    length is the visible one, and a hidden end is said with the bound it leaves."""
    out = [replace(r, unreported=unreported) for r in results]
    for g in families:
        ok = [i for i in g if out[i].found]
        # A family whose refused members leave fewer measured lines than made it one (3,
        # or the 2 an explicit --min-length allows) is no family: its pitch is not defined
        # (building.jpg: 2 of 3 window edges, "pitch nan").
        if len(ok) < min(len(g), MIN_MEMBERS):
            continue
        lengths: list[tuple[float, float, int]] = []
        if image is not None:
            for i in ok:
                out[i], got = member_ends(image, out[i])
                lengths.append(got)
        ms = [out[i] for i in ok]
        mids = []
        for r in ms:
            if r.measurement is None or r.measurement.ends_px is None:
                mids.append(r.offset_px * line_frame(r.angle_rad)[1])
                continue
            # The groove's ends where its centres are (undistorted by the camera's lens):
            # the pitch is measured in the same coordinates as the offsets.
            mids.append(claimed_middle(r.measurement, r.lens))
        shape = next((r.measurement.image_shape for r in ms if r.measurement is not None),
                     None)
        shifts = (lens_shifts(np.array(mids), ms[0].lens, shape) if shape is not None
                  else None)
        # The lens's terms are shared by the members: out of their u for the chi2 of their
        # angles, into the family mean's u (align.family).
        shared = [{k: v for k, v in r.u_terms.items() if k.startswith(LENS_TERMS)} for r in ms]
        own = np.sqrt(np.maximum([r.angle_u_rad**2 - sum(v**2 for v in t.values())
                                  for r, t in zip(ms, shared, strict=True)], 1e-30))
        angles = np.array([r.angle_rad for r in ms])
        if np.ptp(_wrap_all(angles - angles[0])) > DIAL_SPREAD and len(ms) >= 3:
            # Lines that meet at a point (imaging.dials.group_dial): a dial.
            dial = line_dial([r.index for r in ms], angles, own,
                             np.array([r.offset_px for r in ms]),
                             np.array([r.offset_own_u_px for r in ms]), np.array(mids), lens, alpha,
                             [r.lens_coupling for r in ms])
            for i in ok:
                out[i] = replace(out[i], dial=dial)
            continue
        shading = np.array([shading_shift(r.angle_rad, r.measurement.profile.width_px,
                                          r.measurement.profile.blur_px,
                                          r.measurement.profile.background_dn,
                                          r.measurement.profile.slope_across_dn_per_px)
                            if r.measurement is not None else np.zeros(2) for r in ms])
        fam = line_family([r.index for r in ms], np.array([r.angle_rad for r in ms]), own,
                          np.array(mids), np.array([r.offset_own_u_px for r in ms]), lens,
                          len(g) - len(ok), alpha, shared, lengths, shifts,
                          [r.lens_coupling for r in ms], shading)
        for i in ok:
            out[i] = replace(out[i], family=fam)
    if image is not None:
        # Every other mark's ends checked alike (a single mark, a dial's graduation): its
        # length the visible one, a hidden end said with its bound.
        out = [member_ends(image, r)[0] if r.found and r.family is None else r for r in out]
    return out


def grating_notes(image: np.ndarray, name: str, results: Sequence[MarkResult]
                  ) -> tuple[str, ...]:
    """A note per grating in the tiles near the measured marks (:mod:`imaging.grating`),
    naming its pitch, direction and pixel region; a measured family's own ruling is not a
    grating to name."""
    segs, known = [], set()
    c = np.array([(image.shape[1] - 1) / 2, (image.shape[0] - 1) / 2])
    for r in results:
        m = r.measurement
        if m is None or not np.all(np.isfinite(m.extent_px)):
            continue
        u, n = line_frame(m.profile.angle_rad)
        segs.append(np.array([m.profile.offset_px * n + t * u + c for t in m.extent_px]))
        if r.family is not None and np.isfinite(r.family.pitch_px):
            known.add((abs(r.family.pitch_px), r.family.angle_rad))
    return tuple(f"{name}: {g.describe()}" for g in grating_regions(image, segs, sorted(known)))


def family_note(image: np.ndarray, roi: Roi | None = None) -> str | None:
    """What an image expected to hold one mark (a session's) holds instead, when it is a
    family of lines (a ruled scale, a dial): "it holds a family of N parallel lines at a°
    (pitch ~p px) in pixels x ..., y ...: measure it with `align marks`", from the search
    with families (:func:`imaging.detect_lines`); None when it holds none.

    A family has no place in a session's E (a view's angle is one mark's): said on the
    image's entry rather than dropped with "two competing marks"."""
    det = detect_lines(image, roi=roi)
    if not det.families:
        return None
    c = np.array([(image.shape[1] - 1) / 2, (image.shape[0] - 1) / 2])
    said = []
    for g in det.families:
        cs = [det.marks[i] for i in g]
        ends = np.array([[c + m.offset_px * line_frame(m.angle_rad)[1]
                          + t * line_frame(m.angle_rad)[0] for t in (m.t_start_px, m.t_end_px)]
                         for m in cs]).reshape(-1, 2)
        (x0, y0), (x1, y1) = ends.min(axis=0), ends.max(axis=0)
        angles = np.array([m.angle_rad for m in cs])
        where = f"in pixels x {x0:.0f}–{x1:.0f}, y {y0:.0f}–{y1:.0f}"
        if np.ptp(_wrap_all(angles - angles[0])) > DIAL_SPREAD:
            said.append(f"a dial of {len(cs)} lines meeting at a point {where}")
            continue
        a = float(angles[0] + np.median(_wrap_all(angles - angles[0])))
        q = np.sort([m.offset_px * float(line_frame(m.angle_rad)[1] @ line_frame(a)[1])
                     for m in cs])
        said.append(f"a family of {len(cs)} parallel lines at {np.rad2deg(a):.1f}° (pitch "
                    f"~{float(np.median(np.diff(q))):.1f} px) {where}")
    return ("it holds " + " and ".join(said) + ": measured by `align marks` (family, pitch, "
            "parallelism), not by a session, whose views are one mark each")
