"""Two straight grooves meeting at a kink, found as one mark (align.mark_kink): measured as
two marks, each within its u of its own groove (or, where a kink is left in one mark, not
ok); straight and bent (circular-arc) marks are not split (the false-kink rate over seeds)."""

import numpy as np
import pytest

from align import LensRanges, loop_mark, measure_image
from align.documents import marks_document
from align.mark_kink import kink_test
from align.mark_stage import MarkStage
from imaging import measure_frame
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from synth.scenes import kinked_pair as kink_spec

ALPHA = 1e-3


def clean_spec(seed: int, bow: bool) -> ImageSpec:
    """One straight mark, or one bent as a circular arc (sagitta 0.5-4 px), random pose."""
    rng = np.random.default_rng(1000 + seed)
    sag = rng.uniform(0.5, 4.0) * rng.choice([-1, 1]) if bow else 0.0
    mark = MarkSpec(rng.uniform(-0.5, 0.5), rng.uniform(-100, 100), rng.uniform(150, 450),
                    rng.uniform(3, 6), bow_px=sag, bow_shape="arc")
    return ImageSpec(marks=(mark,), width=640, height=480, blur_px=rng.uniform(0.8, 2),
                     full_well_e=full_well_for_snr(rng.uniform(20, 80), -0.6), seed=seed)


def _kink_p(spec: ImageSpec) -> float:
    m = measure_frame(render_marks(spec, with_crlb=False).image, None).items[0]
    k = kink_test(m, MarkStage(m).sigma)
    return 1.0 if k is None else k.p  # None: too few centres to test (never split)


@pytest.mark.parametrize(("seed", "kink_deg"), [(0, 5.0), (1, 8.0)])
def test_kinked_mark_measured_as_two(seed, kink_deg):
    # Before: one bent line, 12-26 u off after inflation, only "unexplained structure".
    spec, truth = kink_spec(seed, kink_deg)
    res = measure_image(render_marks(spec, with_crlb=False).image, ranges=LensRanges.none())
    assert len(res) == 2 and all(r.found and not r.kinked for r in res)
    for r in res:
        err = min(abs(r.angle_rad - a) for a in truth)
        assert err < 3 * r.angle_u_rad
        assert any("measured as two lines, marks 0 and 1" in n for n in r.notes)
    # one mark per groove, not both on the same one
    got = sorted(int(np.argmin([abs(r.angle_rad - a) for a in truth])) for r in res)
    assert got == [0, 1]
    assert marks_document(res, {}, [])["ok"] is True


def test_kink_left_in_one_mark_is_not_ok():
    # Through the loop without the split: the kink is named and the mark is not ok.
    spec, _ = kink_spec(2, 5.0)
    m = measure_frame(render_marks(spec, with_crlb=False).image, None).items[0]
    r = loop_mark(m, "image", 0)
    assert r.kinked
    assert any("NOT OK: a kink at t =" in n for n in r.notes)
    doc = marks_document([r], {}, [])
    assert doc["ok"] is False and doc["marks"][0]["kinked_mark"] is True


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_straight_and_arc_marks_not_kinked(seed):
    assert _kink_p(clean_spec(seed, bow=False)) >= ALPHA
    assert _kink_p(clean_spec(seed, bow=True)) >= ALPHA


def test_bent_arc_mark_not_kinked_end_to_end():
    (r,) = measure_image(render_marks(clean_spec(3, bow=True), with_crlb=False).image,
                         ranges=LensRanges.none())
    assert r.found and not r.kinked


@pytest.mark.slow
@pytest.mark.parametrize("bow", [False, True])
def test_false_kink_rate(bow):
    # The test on every mark (not only those the loop leaves structure on): at alpha 1e-3
    # the expected count over 100 is 0.1; the owner's bound is 1 %.
    n = 100
    fired = sum(_kink_p(clean_spec(s, bow)) < ALPHA for s in range(n))
    assert fired <= 0.01 * n


@pytest.mark.slow
def test_kinks_found_over_seeds():
    n = 20
    found = sum(_kink_p(kink_spec(s, k)[0]) < ALPHA for s in range(n) for k in (5.0, 8.0))
    assert found == 2 * n


def _parts(seed: int, kink_deg: float):
    spec, truth = kink_spec(seed, kink_deg)
    res = [r for r in measure_image(render_marks(spec, with_crlb=False).image,
                                    ranges=LensRanges.none()) if r.found]
    return res, truth


def _z(r, truth) -> float:
    return min((((r.angle_rad - a + np.pi / 2) % np.pi - np.pi / 2) / r.angle_u_rad
                for a in truth), key=abs)


def test_kinked_parts_carry_their_own_grooves_sigma():
    """Each part measured again as its own groove: its centres' scatter about its line
    matches their stated sigma (line chi2 inside its 0.1-99.9 % band; before, with the whole
    V's noise model, chi2/dof was 0.20-0.44 and u 40-80" on these 200 px strokes)."""
    from scipy import stats

    res, truth = _parts(0, 5.0)
    assert len(res) == 2
    for r in res:
        lf = r.measurement.line
        lo, hi = stats.chi2.ppf([1e-3, 1 - 1e-3], lf.dof)
        assert lo <= lf.chi2 <= hi, (lf.chi2, lf.dof)
        assert abs(_z(r, truth)) <= 3


@pytest.mark.slow
def test_kinked_parts_z_over_seeds():
    """benchmarks/kinked_marks.py's scenes (10 seeds x 5 and 8 deg): the parts' RMS z
    0.8-1.2 and max |z| <= 3.5 (before: RMS z 0.54, u 1.5-2.2x too wide; seen 0.90, 1.96)."""
    z = np.array([_z(r, t) for s in range(10) for k in (5.0, 8.0)
                  for res, t in [_parts(s, k)] for r in res])
    rms = float(np.sqrt(np.mean(z**2)))
    print(f"kinked parts: {z.size}, RMS z {rms:.2f}, max |z| {np.abs(z).max():.2f}")
    assert z.size == 40 and 0.8 <= rms <= 1.2 and np.abs(z).max() <= 3.5
