"""align.family_stage: a ruled scale where a session expects one mark is named as a family;
the frame lens's share in a family's pitch u and a dial's increment u."""

from __future__ import annotations

import numpy as np

from align.family import line_family
from align.family_stage import lens_or_bend_vector, lens_shifts, lens_u_vector
from align.line_dial import line_dial
from align.marks import measure_camera
from synth.marks import write_image
from synth.ruled import RuledSpec, render_ruled


def test_session_image_of_a_scale_names_the_family(tmp_path):
    """A camera's image holding a ruled scale (one mark expected, as in a session): the
    entry says the family — its lines, direction, pitch, pixel region — not only that two
    marks compete. (Seed 5 has a graduation cut in pieces by specks, which families do not
    rebuild: docs/ruled-scales.md.)"""
    s = render_ruled(RuledSpec(width=640, height=480, pitch_px=70.0, line_angle_rad=1.3,
                               lengths_px=(110.0, 140.0, 170.0), bits=12, snr=30, seed=4))
    path = write_image(tmp_path / "scale.png", s.image)
    (res,) = measure_camera([(path, None)], expect_one=True, label="A")
    assert len(res) == 1 and not res[0].found
    err = res[0].error
    n = len(s.truth.lines)
    said = f"a family of {n} parallel lines at {np.rad2deg(s.truth.line_angle_rad):.1f}°"
    assert said in err, err
    pitch = float(err.split("(pitch ~")[1].split(" px")[0])
    assert abs(pitch - 70.0) < 3.0 and "in pixels x " in err and "\n" not in err


def test_lens_u_vector_from_records():
    """A calibrated camera's own u; for a lens from the lines: applied -> u from the lines,
    determined and not applied -> |estimate| and u together (within the range),
    undetermined -> range / sqrt 3; declared flat -> zeros."""
    assert not np.any(lens_u_vector({"source": "declared distortion-free"}))
    assert list(lens_u_vector({"source": "camera model",
                               "u_lens_vector": [1e-3, 0, 0, 0, 0, 0.5, 0.5]}))[0] == 1e-3
    par = {p: {"determined": False, "applied": False, "estimate": None, "u_from_lines": None}
           for p in ("k1", "k2", "p1", "p2", "aspect", "cx", "cy")}
    par["k1"] = {"determined": True, "applied": True, "estimate": -0.05, "u_from_lines": 0.004}
    par["k2"] = {"determined": True, "applied": False, "estimate": 0.03, "u_from_lines": 0.04}
    u = lens_u_vector({"source": "marks", "parameters": par,
                       "ranges": {"k1": 0.3, "k2": 0.1, "p": 1e-3, "aspect": 0.005,
                                  "pp_px": 20.0}})
    assert np.allclose(u, [0.004, np.hypot(0.03, 0.04), 1e-3 / np.sqrt(3), 1e-3 / np.sqrt(3),
                           0.005 / np.sqrt(3), 20 / np.sqrt(3), 20 / np.sqrt(3)])


def test_pitch_lens_share_is_the_slope_of_the_lens_moves():
    """Members at 0, 10, ..., 40 px; a lens whose u moves member k by 0.01 k px across the
    lines (a scale change of 0.1 %): the pitch's lens share is 0.01 px; a uniform shift
    (the principal point) adds nothing."""
    n = 5
    mids = np.column_stack([np.zeros(n), 10.0 * np.arange(n)])  # lines along x: normal y
    shift = np.zeros((n, 2, 2))
    shift[:, 1, 0] = 0.01 * np.arange(n)
    shift[:, 1, 1] = 0.7
    fam = line_family(range(n), np.zeros(n), np.full(n, 1e-5), mids, np.full(n, 0.01),
                      lens_shift=shift)
    assert np.isclose(fam.pitch_u_lens_px, 0.01)
    assert fam.pitch_u_px >= fam.pitch_u_lens_px


def test_unconfirmed_lens_carried_in_the_pitch_as_with_and_without():
    """A lens from the lines that no other line confirms (the bows may be the marks' own):
    the pitch carries (with it - without it) / sqrt 3, as the angles' lens_or_bend does.
    Members 70 px apart across a 1600 x 1200 frame, k1 -0.17 applied: the last direction
    moves them by the lens's own correction / sqrt 3, its slope a few tenths of the pitch's
    change; confirmed, or a camera model, or nothing applied: no such direction."""
    rec = {"source": "marks", "confirmed_by_other_lines": False,
           "parameters": {"k1": {"applied": True, "value": -0.17, "u_from_lines": 1e-3},
                          "k2": {"applied": False, "determined": False}},
           "ranges": {"k1": 0.3, "k2": 0.05, "p": 1e-3, "aspect": 0.005, "pp_px": 20.0}}
    assert np.allclose(lens_or_bend_vector(rec), [-0.17, 0, 0, 0, 0, 0, 0])
    for other in ({**rec, "confirmed_by_other_lines": True}, {**rec, "source": "camera model"},
                  None):
        assert not np.any(lens_or_bend_vector(other))
    n = 23
    x = 70.0 * (np.arange(n) - 11)
    mids = np.column_stack([x, np.zeros(n)])  # lines along y: normal x
    sh = lens_shifts(mids, rec, (1200, 1600))
    assert sh.shape == (n, 2, 8)
    fam = line_family(range(n), np.full(n, np.pi / 2), np.full(n, 1e-5), mids,
                      np.full(n, 0.01), lens_shift=sh)
    # k1 at the half-diagonal (1000 px) moves x by k1 x^3 / 1000^2: the slope of those
    # moves over the members, / sqrt 3.
    moves = 0.17 * x**3 / 1000.0**2 / np.sqrt(3)
    slope = np.polyfit(np.arange(n), moves, 1)[0]
    assert 0.5 * slope < fam.pitch_u_lens_px < 1.5 * slope and slope > 1.0


def test_dial_increment_carries_the_lens_coupling():
    """Eight lines round a point 45° apart; one lens direction moves every angle by the same
    amount (a roll-like term): the increment's share is 0; one that moves line k by k x
    (1 arc-second) is the increment's slope, 1 arc-second."""
    arc = np.deg2rad(1 / 3600)
    th = np.deg2rad(45.0) * np.arange(8) + 0.2
    r = 100.0
    mid = np.column_stack([r * np.cos(th), -r * np.sin(th)])
    offs = np.zeros(8)
    same = [{"lens_fit.0": 2 * arc} for _ in range(8)]
    d0 = line_dial(range(8), th, np.full(8, 1e-4), offs, np.full(8, 0.01), mid,
                   lens_coupling=same)
    assert d0.increment_u_lens_rad < 1e-12
    ramp = [{"lens_k1_range": k * arc} for k in range(8)]
    d1 = line_dial(range(8), th, np.full(8, 1e-4), offs, np.full(8, 0.01), mid,
                   lens_coupling=ramp)
    assert np.isclose(d1.increment_u_lens_rad, arc)
    assert np.isclose(d1.increment_u_rad, np.hypot(d0.increment_u_rad, arc))


def test_single_mark_hidden_end_said_with_its_bound():
    """A single line (no family) with an opaque particle over one end: its length the
    visible part (not longer than the truth), a note that the end is hidden with a bound
    that holds the true length — as a family's member gets (align.family.member_ends)."""
    from align.marks import measure_image

    for seed in range(2):
        s = render_ruled(RuledSpec(width=640, height=480, n_lines=1, seed=seed, dust=5,
                                   lengths_px=(200.0, 200.0, 200.0), dust_on_ends=1,
                                   numerals=False, dust_on_lines=0))
        (r,) = measure_image(s.image)
        assert r.found and r.family is None and s.truth.lines[0].hidden in ("start", "end")
        said = [n for n in r.notes if "under an obstruction" in n]
        assert len(said) == 1, r.notes
        up_to = float(said[0].split("up to ")[1].split(" px")[0])
        assert r.length_px <= 200.0 + 1.0 and up_to >= 200.0 - 1.0, (r.length_px, said)


def test_member_middle_not_moved_by_a_free_lens():
    """A k1 fitted free (its sign open: the angles' estimator, reported not applied, and
    carried so in the pitch's u by lens_u_vector) moves no member's middle: the middle is
    the mark's own line's without it. Before, the middles were undistorted by the free k1
    and the pitch took its noise beyond its own u (a lens-free 1600 x 1200 scale: 62.886 px,
    truth 62.971, own u 0.0003 px; the slow sweep
    tests/imaging/test_families.py::test_ruled_scale_grid_every_line_found)."""
    from align.camera_lens import undistorted_mark
    from align.family_stage import claimed_middle
    from imaging import measure_marks
    from synth import ImageSpec, MarkSpec, render_marks

    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(80.0), 180.0, 200.0, 4.0),), width=640,
                     height=480, seed=2)
    m = next(m for m in measure_marks(render_marks(spec, with_crlb=False).image)
             if not isinstance(m, Exception))
    lam = np.zeros(7)
    lam[0] = 0.05
    mu = undistorted_mark(m, lam)
    own = undistorted_mark(m, np.zeros(7)).ends_px.mean(axis=0)

    def record(applied: bool) -> dict:
        return {"source": "marks", "parameters": {"k1": {
            "value": 0.05, "applied": applied, "determined": True,
            "estimator": "applied" if applied else "free"}}}

    moved = float(np.linalg.norm(mu.ends_px.mean(axis=0) - own))
    assert moved > 0.3  # what the free k1 moved the middle by (the defect's size)
    assert np.linalg.norm(claimed_middle(mu, record(False)) - own) < 1e-3 * moved
    # An applied k1 is the lens: the middle stays undistorted by it.
    assert np.array_equal(claimed_middle(mu, record(True)), mu.ends_px.mean(axis=0))
