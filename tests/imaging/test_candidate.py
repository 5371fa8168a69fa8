"""imaging.candidate: a line direction wrapped to (-pi/2, pi/2] continuously through +-90 deg."""

from __future__ import annotations

import numpy as np
import pytest

from imaging import measure_marks
from imaging.candidate import (
    MarkCandidate,
    _covers,
    _dedupe,
    _may_cover,
    _near,
    _overlap,
    line_frame,
    may_be_near,
    wrap_angle,
)
from tests.conftest import angle_error, mark_image


def test_wrap_is_continuous_through_vertical():
    """Only -90 deg itself becomes +90; 1e-9 rad either side of vertical stays where it is
    (a tolerance here once snapped lines 3" past vertical onto exactly +90)."""
    assert wrap_angle(-np.pi / 2) == np.pi / 2
    assert wrap_angle(np.pi / 2) == np.pi / 2
    for d in (1e-9, 1e-7, 1.07e-5, 1e-3):  # 1.07e-5 rad = 2.2"
        assert wrap_angle(np.pi / 2 + d) == pytest.approx(-np.pi / 2 + d, abs=1e-15)
        assert wrap_angle(-np.pi / 2 - d) == pytest.approx(np.pi / 2 - d, abs=1e-15)
        assert wrap_angle(np.pi / 2 - d) == pytest.approx(np.pi / 2 - d, abs=1e-15)
        assert wrap_angle(-np.pi / 2 + d) == pytest.approx(-np.pi / 2 + d, abs=1e-15)


# Through vertical and through 0 by 2.2", and on the axes: each within 4.5 u of the truth
# (1 in 150000 for an honest u) and none pinned to exactly +-90 deg off the axis.
@pytest.mark.parametrize("angle", [90.0 - 6.1e-4, 90.0, 90.0 + 6.1e-4, -6.1e-4, 0.0, 6.1e-4])
def test_angles_through_vertical_and_zero_within_u(angle):
    s = mark_image(angle, seed=int(abs(angle) * 1e4) % 97 + 3, length_px=400)
    m = measure_marks(s.image.astype(float))[0]
    truth = s.truth.marks[0].image_angle_rad
    assert abs(angle_error(m.line.angle_rad, truth)) < 4.5 * m.line.angle_u_rad
    assert -np.pi / 2 < m.line.angle_rad <= np.pi / 2
    if angle != 90.0:
        assert abs(abs(m.line.angle_rad) - np.pi / 2) > 1e-9


def test_fused_prefilter_never_drops_a_covering_line():
    """_drop_fused's vectorised prefilter (_may_cover) is a necessary condition of the full
    test (_covers): over random bundles of nearly parallel lines of random extents, offsets
    and widths, every pair the full test says covers passes it, and it leaves most out."""
    rng = np.random.default_rng(18)
    covers = passed = tested = 0
    for _ in range(10):
        base = rng.uniform(-1.6, 1.6)
        cands = []
        for _ in range(25):
            t0 = rng.uniform(-300, 100)
            ang = base + rng.normal(0, 0.05) if rng.random() < 0.7 else rng.uniform(-1.6, 1.6)
            cands.append(MarkCandidate(angle_rad=float(ang), offset_px=rng.normal(0, 15),
                                       t_start_px=t0, t_end_px=t0 + rng.uniform(5, 400),
                                       dark=True, thickness_px=rng.uniform(1, 8), strength=1.0))
        angle = np.array([o.angle_rad for o in cands])
        offset = np.array([o.offset_px for o in cands])
        half = np.array([max(6.0, 2 * o.thickness_px) for o in cands])
        for c in cands:
            may = _may_cover(c, angle, offset, half)
            for o, m, h in zip(cands, may, half, strict=True):
                if o is c:
                    continue
                full = _covers(c, o, h, (c.t_start_px, c.t_end_px))
                assert m or not full
                covers += full
                passed += m
                tested += 1
    assert covers > 30  # the sweep holds covering pairs to miss
    assert passed < 0.2 * tested  # and the prefilter leaves most pairs out


def test_dedupe_keeps_what_the_pairwise_test_keeps():
    """_dedupe's test against all kept candidates at once (with a 1e-6 slack, then the
    scalar test on those left) keeps exactly what testing each kept one in turn keeps: over
    random bundles of nearly coincident lines of both polarities, some across the wrap at
    +-pi/2, the same list, with duplicates to drop and lines to keep."""
    rng = np.random.default_rng(7)
    dropped = kept = 0
    for _ in range(40):
        base = rng.uniform(-np.pi / 2, np.pi / 2, 4)
        cands = []
        for _ in range(int(rng.integers(2, 60))):
            t0 = rng.uniform(-300, 300)
            cands.append(MarkCandidate(
                angle_rad=wrap_angle(float(base[rng.integers(4)] + rng.normal(0, 0.03))),
                offset_px=float(rng.normal(0, 8)), t_start_px=t0,
                t_end_px=t0 + rng.uniform(5, 400), dark=bool(rng.integers(2)),
                thickness_px=rng.uniform(0, 12), strength=rng.uniform(0, 1000)))
        cands.sort(key=lambda c: -c.strength)
        ref: list[MarkCandidate] = []
        for c in cands:
            if not any(c.dark == o.dark and _near(c, o, np.deg2rad(3), max(6.0, o.thickness_px))
                       and _overlap(c, o) for o in ref):
                ref.append(c)
        assert _dedupe(cands) == ref
        dropped += len(cands) - len(ref)
        kept += len(ref)
    assert dropped > 100 and kept > 100


def test_may_be_near_keeps_every_near_pair_and_drops_the_far():
    """The all-pairs prefilter of _near is a necessary condition (every pair _near accepts
    it keeps, also at the tolerances' edges and across +-90 deg) that drops most others."""
    rng = np.random.default_rng(7)
    tol, px = np.deg2rad(1.5), 3.0
    cands = []
    for _ in range(150):
        # Directions clustered around 0 and around vertical (either sign), offsets on a
        # coarse ruling with scatter of the tolerance's size: many pairs near each edge.
        a = rng.choice([0.0, np.pi / 2, -np.pi / 2]) + rng.normal(0, tol)
        ts = rng.uniform(-200, 200)
        cands.append(MarkCandidate(angle_rad=float(a), offset_px=float(
            rng.integers(0, 3) * 40 + rng.normal(0, px)), t_start_px=float(ts),
            t_end_px=float(ts + rng.uniform(5, 60)), dark=True, thickness_px=3.0,
            strength=1.0))
    for a in (0.3, np.pi / 2 - 1e-4):  # and pairs just inside both tolerances
        o = MarkCandidate(angle_rad=a, offset_px=10.0, t_start_px=0.0, t_end_px=50.0,
                          dark=True, thickness_px=3.0, strength=1.0)
        b = a + tol * (1 - 1e-9)
        u, n = line_frame(b)
        no = line_frame(a)[1]
        # c's middle at t = 25 along its own line, px (1 - 1e-9) from o's line
        off = (10.0 + px * (1 - 1e-9) - 25.0 * float(u @ no)) / float(n @ no)
        cands.append(MarkCandidate(angle_rad=b, offset_px=off, t_start_px=0.0,
                                   t_end_px=50.0, dark=True, thickness_px=3.0, strength=1.0))
        cands.append(o)
        assert _near(cands[-2], o, tol, px)
    may = may_be_near(cands, tol, px)
    near = np.array([[_near(c, o, tol, px) for o in cands] for c in cands])
    assert near.sum() > 500  # (the test sees many near pairs)
    assert not (near & ~may).any()
    assert may.sum() <= near.sum() + 10  # only rounding's slack beyond _near
    assert may_be_near([], tol, px).shape == (0, 0)
