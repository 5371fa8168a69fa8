"""imaging.crossmask: where another mark's groove lies in a mark's profile window. A corner
(the other groove ends where the two meet) leaves out only the other's found part and both
are measured; a crossing (the other groove runs on through) is handled as before — its whole
fused stretch left out, or the two refused. Rendered by synth (physics), seeded."""

from __future__ import annotations

import numpy as np
import pytest

from imaging import detect_lines, measure_frame
from imaging.candidate import line_frame
from imaging.crossmask import groove_runs_on
from imaging.groove import centres_half
from imaging.measure import MarkMeasurement
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error

DELTA_DEG = 6.0
LENGTH_PX = 200.0


def stepped_scene(through: bool, seed: int, step_px: float = 4.0, gap_px: float = 8.0
                  ) -> ImageSpec:
    """Two 200 px grooves 6 deg apart: A ends at P; B starts 8 px on, stepped 4 px across
    (a ledge's two edges at a kink: A's line meets B's some 40 px along B). ``through``: A
    runs on 150 px past P, across B's line (a crossing near B's start)."""
    r = np.random.default_rng(seed)
    a1 = np.deg2rad(r.uniform(-60, 60))
    sgn = r.choice([-1, 1])
    a2 = a1 + np.deg2rad(DELTA_DEG) * sgn
    u1, n1 = np.array([np.cos(a1), -np.sin(a1)]), np.array([np.sin(a1), np.cos(a1)])
    u2, n2 = np.array([np.cos(a2), -np.sin(a2)]), np.array([np.sin(a2), np.cos(a2)])
    p = r.uniform(-20, 20, 2) - 60 * u1
    q = p + gap_px * u2 - sgn * step_px * n2
    ext = 150.0 if through else 0.0
    a = MarkSpec(a1, float(p @ n1), LENGTH_PX + ext, 4.0,
                 centre_t_px=float(p @ u1 + (ext - LENGTH_PX) / 2))
    b = MarkSpec(a2, float(q @ n2), LENGTH_PX, 4.0, centre_t_px=float(q @ u2 + LENGTH_PX / 2))
    return ImageSpec(marks=(a, b), width=640, height=480,
                     full_well_e=full_well_for_snr(50, -0.6), seed=seed)


def _which(angle: float, spec: ImageSpec) -> int:
    return int(np.argmin([abs(angle_error(angle, m.angle_rad)) for m in spec.marks]))


def _probes(img: np.ndarray, spec: ImageSpec, items: list) -> list[bool | None]:
    """groove_runs_on of each mark's window (its measured profile) for the other's groove
    (its detected candidate)."""
    cands = detect_lines(img).marks
    out = []
    for m in items:
        if not isinstance(m, MarkMeasurement):
            continue
        pf, k = m.profile, _which(m.line.angle_rad, spec)
        for o in (c for c in cands if _which(c.angle_rad, spec) != k):
            out.append(groove_runs_on(img, pf, o, centres_half(pf) + o.thickness_px / 2 + 1))
    return out


def _in_band(o: MarkSpec, m: MarkMeasurement) -> float:
    """Length along m's line [px] over which o's true groove (its core: half its width) lies
    in m's centres' band."""
    pf = m.profile
    u, n = line_frame(pf.angle_rad)
    uo, no = line_frame(o.angle_rad)
    s = np.arange(-o.length_px / 2, o.length_px / 2, 0.5) + o.centre_t_px
    pts = o.offset_px * no + s[:, None] * uo
    t = pts[np.abs(pts @ n - pf.offset_px) <= centres_half(pf) + o.width_px / 2] @ u
    t = t[(t >= pf.t_start_px) & (t <= pf.t_end_px)]
    return float(np.ptp(t)) if t.size else 0.0


@pytest.mark.parametrize("seed", [1, 2])
def test_a_stepped_corner_is_measured_and_a_crossing_still_left_out(seed):
    """The corner: past the found end facing the meeting point the probe finds bare
    surface, so only the other's found part counts in each window and both marks are
    measured, each within 3 u (before the probe: one refused on these seeds, "mark ... lies
    in its profile window": the other's groove taken to run on through its found end). The
    crossing twin (A runs on): the probe finds no groove ending (B's start lies on A, whose
    groove is seen there), and B's stretch along A is left out: at least where B's true
    groove lies in A's band (~70 px; B is taken to run on past its found start as far as
    it is seen to or is hidden under A: :func:`imaging.crossmask.run_on`; before, through
    the whole window, ~220 px, though B starts 40 px past where the lines meet)."""
    corner = stepped_scene(False, seed)
    img = render_marks(corner, with_crlb=False).image.astype(float)
    items = measure_frame(img).items
    assert False in _probes(img, corner, items) and True not in _probes(img, corner, items)
    assert len(items) == 2 and all(isinstance(m, MarkMeasurement) for m in items), items
    assert sorted(_which(m.line.angle_rad, corner) for m in items) == [0, 1]
    for m in items:
        t = corner.marks[_which(m.line.angle_rad, corner)]
        assert abs(angle_error(m.line.angle_rad, t.angle_rad)) < 3 * m.line.angle_u_rad
        assert m.length_px > 0.9 * LENGTH_PX

    crossing = stepped_scene(True, 2)
    img = render_marks(crossing, with_crlb=False).image.astype(float)
    items = measure_frame(img).items
    assert False not in _probes(img, crossing, items)
    through = [m for m in items if isinstance(m, MarkMeasurement)
               and _which(m.line.angle_rad, crossing) == 0]
    assert len(through) == 1, items
    assert sum(n for _, n in through[0].crossings) >= _in_band(crossing.marks[1], through[0])
    for m in (m for m in items if isinstance(m, MarkMeasurement)):
        t = crossing.marks[_which(m.line.angle_rad, crossing)]
        assert abs(angle_error(m.line.angle_rad, t.angle_rad)) < 3 * m.line.angle_u_rad
