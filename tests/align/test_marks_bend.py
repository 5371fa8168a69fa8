"""Tell a lens from a bend from a wiggle (issue 18, point 3): seeded statistical checks.

Images come from ``synth`` (physics: a groove whose centre line is a circular arc or a
parabola through its ends, OpenCV's Brown-Conrady lens, shot and read noise), never from the
pipeline's model run backwards. The truth of a bent mark is its chord, end to end
(``MarkSpec.bow_px``).

* A bent mark on a camera declared distortion-free is named ("the mark is bent", its
  ``bent_mark_*`` u terms), never booked as radial distortion nor as a wiggle with fewer
  than 2 periods along it, and its angle is within 3 u of the chord.
* A bent mark among straight ones on a distortion-free camera whose lens is not declared:
  named, left out of the lens (no lens parameter applied from its bow), the straight marks
  not called bent.
* Straight marks through real lenses (k1 -0.3 ... +0.1 with k2, p1/p2 up to 1e-3): not
  called bent (the false-bend rate is printed and bounded), every angle within 3 u or marked
  lens-limited (not ok).
"""

from __future__ import annotations

import numpy as np
import pytest

from align import LensRanges, measure_image
from align.marks import BEND, RADIAL, WIGGLE
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks

W, H = 800, 600
F = 1.325 * 0.5 * np.hypot(W, H)       # f = 1.325 R, as the docs' test grid
SNR = 50.0

# (offset across the mark from the image centre, its middle along it from the foot of the
# perpendicular) [px], each with a random sign.
POSITIONS = {"centre": (0.0, 0.0), "along": (0.0, 140.0), "across": (200.0, 0.0),
             "corner": (190.0, 130.0)}


def _wrap(a: float) -> float:
    return float((a + np.pi / 2) % np.pi - np.pi / 2)


def _spec(marks, seed: int, camera: CameraGeometry | None = None) -> ImageSpec:
    return ImageSpec(marks=tuple(marks), width=W, height=H, seed=seed, supersample=3,
                     full_well_e=full_well_for_snr(SNR, -0.6),
                     camera=camera or CameraGeometry(focal_px=F))


def _bent(rng: np.random.Generator, where: str) -> MarkSpec:
    off, t = POSITIONS[where]
    return MarkSpec(rng.uniform(-np.pi / 2, np.pi / 2), off * rng.choice([-1, 1]),
                    rng.uniform(220.0, 380.0), 4.0, centre_t_px=t * rng.choice([-1, 1]),
                    bow_px=rng.uniform(0.5, 4.0) * rng.choice([-1, 1]),
                    bow_shape=str(rng.choice(["arc", "parabola"])))


def _match(r, marks):
    """The truth mark nearest to result r (angle [deg] + middle's distance [px] / 20: marks
    may be near parallel, or cross), and the angle error [rad]."""
    mid = r.measurement.ends_px.mean(axis=0)
    cost = [abs(np.rad2deg(_wrap(r.angle_rad - m.angle_rad)))
            + np.hypot(*(mid - np.array(m.centre_xy()))) / 20 for m in marks]
    m = marks[int(np.argmin(cost))]
    return m, _wrap(r.angle_rad - m.angle_rad)


def _called_bent(notes) -> bool:
    """A bend named: by the mark's loop, or by the camera's lens (a line no lens fits)."""
    return any("the mark is bent" in n or "a bent mark, left out" in n
               or "disagree with one lens" in n for n in notes)


def _check_bent_named(r, mark: MarkSpec) -> float:
    """The checks on one bent mark's result; returns its normalised error."""
    names = [e.name for e in r.loop.effects]
    assert BEND in names and RADIAL not in names, (mark, r.loop.summary_lines())
    assert any("the mark is bent" in n for n in r.notes), r.notes
    assert {"bent_mark_chord_vs_fit", "bent_mark_ends"} <= set(r.u_terms), r.u_terms
    span = float(np.ptp(r.measurement.regressors["t"]))
    for t in r.loop.terms:  # a wiggle on top is allowed only with >= 2 periods
        if t.name == WIGGLE:
            assert 2 * t.meta["period_px"] <= span, (t.meta, span)
    z = _wrap(r.angle_rad - mark.angle_rad) / r.angle_u_rad
    # A bent mark whose end is outside the frame has no chord in the image: not ok, said so
    # (and only then).
    inside = _inside_by(mark)
    assert r.bend_off_frame or inside > 0, (mark, r.notes)        # an end outside: flagged
    assert not r.bend_off_frame or inside < 15, (mark, r.notes)   # well inside: not flagged
    assert abs(z) <= 3 or r.bend_off_frame, (mark, np.rad2deg(r.angle_rad - mark.angle_rad)
                                             * 3600, np.rad2deg(r.angle_u_rad) * 3600)
    return float(z) if not r.bend_off_frame else float("nan")


def _inside_by(mark: MarkSpec) -> float:
    """How far the mark's ends (truth) are inside the frame [px] (< 0: one is outside)."""
    a = mark.angle_rad
    u, mid = np.array([np.cos(a), -np.sin(a)]), np.array(mark.centre_xy())
    return float(min(min((W - 1) / 2 - abs(p[0]), (H - 1) / 2 - abs(p[1]))
                     for p in (mid + s * mark.length_px / 2 * u for s in (-1, 1))))


def assert_bent_sweep(seeds, positions) -> np.ndarray:
    zs = []
    for seed in seeds:
        for where in positions:
            rng = np.random.default_rng([seed, len(where)])
            mark = _bent(rng, where)
            img = render_marks(_spec([mark], seed), with_crlb=False).image
            found = [r for r in measure_image(img, ranges=LensRanges.none()) if r.found]
            assert len(found) == 1, [r.error for r in found]
            zs.append(_check_bent_named(found[0], mark))
    return np.array(zs)


def test_bent_marks_named_and_covered():
    """One bent mark per position (arc or parabola, sagitta 0.5-4 px), lens declared free."""
    assert_bent_sweep([3], POSITIONS)


@pytest.mark.slow
def test_bent_marks_named_and_covered_over_seeds():
    zs = assert_bent_sweep(range(30), POSITIONS)
    off = int(np.sum(np.isnan(zs)))
    zs = zs[np.isfinite(zs)]
    print(f"bent marks: {len(zs) + off} ({off} running off the frame, not ok), RMS z "
          f"{np.sqrt(np.mean(zs**2)):.2f}, max |z| {np.abs(zs).max():.2f}")
    # u covers a Type B (where the ends are, uniform): conservative, never understated.
    assert np.sqrt(np.mean(zs**2)) <= 1.2


CELLS = [(-200.0, -150.0), (200.0, -150.0), (-200.0, 150.0), (200.0, 150.0)]
"""Middles of the frame's quarters [px from the centre]: a mark of up to 250 px about one
never crosses another (crossing marks disturb each other's centres: not the point here)."""


def _in_cell(rng: np.random.Generator, cell: tuple[float, float], bow_px: float = 0.0,
             length: tuple[float, float] = (150.0, 250.0)) -> MarkSpec:
    a = rng.uniform(-np.pi / 2, np.pi / 2)
    x, y = cell[0] + rng.uniform(-30, 30), cell[1] + rng.uniform(-20, 20)
    # (x, y) = offset n + t u with n = (sin a, cos a), u = (cos a, -sin a).
    return MarkSpec(a, x * np.sin(a) + y * np.cos(a), rng.uniform(*length), 4.0,
                    centre_t_px=x * np.cos(a) - y * np.sin(a), bow_px=bow_px,
                    bow_shape=str(rng.choice(["arc", "parabola"])))


def _mixed(seed: int):
    """Three straight marks and a bent one (sagitta 1-4 px) on a distortion-free camera,
    lens undeclared."""
    rng = np.random.default_rng([seed, 7])
    cells = rng.permutation(len(CELLS))
    marks = [_in_cell(rng, CELLS[c], rng.uniform(1.0, 4.0) * rng.choice([-1, 1]) if k == 0
                      else 0.0) for k, c in enumerate(cells)]
    return marks, render_marks(_spec(marks, seed), with_crlb=False).image


def _check_mixed(seed: int) -> None:
    marks, img = _mixed(seed)
    found = [r for r in measure_image(img) if r.found]
    assert len(found) == 4 and len({id(_match(r, marks)[0]) for r in found}) == 4
    lens = found[0].lens
    assert not any(p["applied"] for p in lens["parameters"].values()), lens
    for r in found:
        m, err = _match(r, marks)
        if m is marks[0]:
            assert any("the mark is bent" in n for n in r.notes), r.notes
        else:
            assert not any("the mark is bent" in n for n in r.notes), r.notes
        assert abs(err) <= 3 * r.angle_u_rad or r.lens_limited, (seed, m, err, r.angle_u_rad)


def test_bent_mark_among_straight_ones_is_not_a_lens():
    _check_mixed(0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 13))
def test_bent_mark_among_straight_ones_is_not_a_lens_over_seeds(seed):
    _check_mixed(seed)


K1 = (-0.3, -0.15, 0.0, 0.1)   # OpenCV's k1 at f = 1.325 R


def _straight_through_lens(seed: int):
    rng = np.random.default_rng([seed, 11])
    k1 = float(K1[seed % len(K1)])
    cam = CameraGeometry(focal_px=F, k1=k1, k2=rng.uniform(-0.5, 0.5) * abs(k1),
                         p1=rng.uniform(-1e-3, 1e-3), p2=rng.uniform(-1e-3, 1e-3))
    cells = rng.permutation(len(CELLS))[:int(rng.integers(1, 5))]
    marks = [_in_cell(rng, CELLS[c]) for c in cells]
    return marks, render_marks(_spec(marks, seed, cam), with_crlb=False).image


def _straight_sweep(seeds) -> tuple[int, int, int]:
    """(marks, marks called bent, images with a bend called)."""
    n = bent = frames = 0
    for seed in seeds:
        marks, img = _straight_through_lens(seed)
        found = [r for r in measure_image(img) if r.found]
        frames += any(_called_bent(r.notes) for r in found)
        for r in found:
            _, err = _match(r, marks)
            n += 1
            bent += any("the mark is bent" in x for x in r.notes)
            assert abs(err) <= 3 * r.angle_u_rad or r.lens_limited, (seed, err, r.angle_u_rad)
    return n, bent, frames


@pytest.mark.slow  # 4 seeds of the 120 its twin below sweeps
def test_straight_marks_through_lenses_not_called_bent():
    n, bent, frames = _straight_sweep(range(4))
    assert bent == 0 and frames == 0


@pytest.mark.slow
def test_straight_marks_through_lenses_false_bend_rate():
    seeds = range(120)
    n, bent, frames = _straight_sweep(seeds)
    print(f"straight marks through lenses: {n} marks in {len(seeds)} images; called bent: "
          f"{bent} marks, {frames} images")
    # The bend tests run at alpha = 1e-3 per mark/frame; a few in a hundred would mean the
    # lens's shapes are not being told from a bend.
    assert frames <= 2 and bent <= 2


def test_a_bow_that_moves_no_reading_of_the_angle_is_not_a_bent_mark():
    """A 0.025 px bow on a 300 px mark at SNR 100 (the clean session's 'bent' mark): the
    loop sees it (beyond 3.3 of its own sigma) but its certain effect on the angle (the
    ends' term, 8 s / L^2 x ~1.1 px, ~0.2 u) widens u by < 5 %: carried as ``bow_*``, the
    straight fit kept, not named bent; angle within 3 u (2 seeds). A 0.5 px bow on the same
    mark is named (positive control)."""
    def one(bow, seed):
        a = np.deg2rad(3.0)
        spec = ImageSpec(marks=(MarkSpec(a, 5.0, 300.0, 4.0, contrast=-0.6, bow_px=bow),),
                         width=480, height=360, full_well_e=full_well_for_snr(100, -0.6),
                         seed=seed)
        (m,) = [r for r in measure_image(render_marks(spec, with_crlb=False).image,
                                         ranges=LensRanges.none()) if r.found]
        return m, _wrap(m.angle_rad - a) / m.angle_u_rad

    for seed in range(2):
        m, z = one(0.025, seed)
        b = next(e for e in m.loop.effects if e.name == BEND)
        assert abs(b.estimate) > 3.3 * b.u, (seed, b.estimate, b.u)
        assert not any("bent" in n or "bow" in n for n in m.notes), m.notes
        assert "bow_ends" in m.u_terms and not m.bend_off_frame and abs(z) < 3, (seed, z)
    m, z = one(0.5, 0)
    assert any("the mark is bent" in n for n in m.notes) and abs(z) < 3, (m.notes, z)


def _s_mark(seed: int) -> tuple[MarkSpec, np.ndarray]:
    """An S-shaped groove (one sine period along it, 0.3-0.6 px; its ends and middle on the
    chord), 260-340 px, lens declared free: the parabola of the bow averages it away, and
    the straight fit turns off the chord by several hundred arc-seconds; the chord is the
    truth."""
    rng = np.random.default_rng([seed, 19])
    a = rng.uniform(-np.pi / 2, np.pi / 2)
    mark = MarkSpec(a, rng.uniform(-40, 40), rng.uniform(260.0, 340.0), 4.0,
                    bow_px=rng.uniform(0.3, 0.6) * rng.choice([-1, 1]), bow_shape="s")
    return mark, render_marks(_spec([mark], seed), with_crlb=False).image


def _check_s(seed: int) -> float:
    mark, img = _s_mark(seed)
    (r,) = [r for r in measure_image(img, ranges=LensRanges.none()) if r.found]
    z = _wrap(r.angle_rad - mark.angle_rad) / r.angle_u_rad
    assert abs(z) <= 3, (seed, np.rad2deg(_wrap(r.angle_rad - mark.angle_rad)) * 3600,
                         np.rad2deg(r.angle_u_rad) * 3600, r.u_terms)
    # Read as its chord, or covered: u holds the chord against the fit (a bent mark's or,
    # when the loop names no effect, the unexplained structure's).
    assert {"bent_mark_chord_vs_fit", "structure_chord_vs_fit"} & set(r.u_terms), r.u_terms
    return float(z)


def test_s_shaped_mark_read_as_its_chord():
    """An S-shaped mark (synth ``bow_shape="s"``): before, its 'chord' was the fitted
    parabola's, equal to the straight fit (an independent user: ~600'' off at u ~160'', z
    -3.8, ok); now the chord between the groove's own ends, u covering chord vs fit."""
    for seed in range(2):
        _check_s(seed)


@pytest.mark.slow
def test_s_shaped_marks_over_seeds():
    zs = np.array([_check_s(seed) for seed in range(2, 14)])
    # The truth (the chord) is at one extreme of the Type B interval [fit, chord] when the
    # fit is read: |z| up to sqrt 3 by design, so only the per-mark bound (|z| <= 3, in
    # _check_s) is asserted; the RMS is printed.
    print(f"S-shaped marks: {len(zs)}, RMS z {np.sqrt(np.mean(zs**2)):.2f}, max |z| "
          f"{np.abs(zs).max():.2f}")
