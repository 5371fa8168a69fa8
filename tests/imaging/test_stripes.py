"""Row and column fixed-pattern noise (issue 18 item 4): found on the background away from the
marks, removed, and a clean background left alone at the test's level."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from align.lens import LensRanges
from align.marks import measure_image
from imaging import measure_frame, stripes
from imaging.stripes import ALPHA, find_stripes
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks
from tests.conftest import angle_error


def _image(seed: int, angle_deg: float = 90.05, **kw):
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(angle_deg), 10.0, 400.0, 4.0),), width=640,
                     height=480, full_well_e=full_well_for_snr(40, -0.6), seed=seed, **kw)
    return render_marks(spec, with_crlb=False)


@pytest.mark.parametrize("kw", [{"column_fpn": 0.6 * 0.01}, {"row_fpn": 0.6 * 0.015}],
                         ids=["columns 1 %", "rows 1.5 %"])
def test_stripes_of_one_percent_of_the_contrast_are_found_and_removed(kw):
    """Offsets of 1-1.5 % of the mark's contrast (the surface signal x 0.6 x that): found,
    removed (the mark leaves background above and below it), and named in the frame's
    notes with their size."""
    s = _image(3, **kw)
    fr = measure_frame(s.image)
    axis = "column" if "column_fpn" in kw else "row"
    found = {st.axis: st for st in fr.stripes}
    assert found[axis].found and found[axis].removed
    other = "row" if axis == "column" else "column"
    assert not found[other].found
    assert any(f"{axis} stripes" in n and "removed" in n for n in fr.notes)
    # The removed pattern is the rendered one (up to its high-passed slow part and noise).
    truth = np.random.default_rng([3, 0xF9]).standard_normal(640 + 480)
    truth = truth[:640] if axis == "column" else truth[640:]
    assert np.corrcoef(found[axis].offsets_dn, truth)[0, 1] > 0.9


def test_a_full_height_mark_keeps_its_stripes_and_says_so():
    """A vertical mark through every row leaves its columns no background: the stripes are
    found, not removed (carried by the texture replicas), and the note says why."""
    spec = ImageSpec(marks=(MarkSpec(np.pi / 2, 10.0, 600.0, 4.0),), width=640, height=480,
                     full_well_e=full_well_for_snr(40, -0.6), seed=2, column_fpn=0.012)
    fr = measure_frame(render_marks(spec, with_crlb=False).image)
    cols = fr.stripes[0]
    assert cols.found and not cols.removed and "hold a mark" in cols.reason
    assert any("carried in u" in n for n in fr.notes)


def test_clean_backgrounds_flag_at_the_tests_level():
    """200 stripe-free backgrounds (white noise of 1-100 DN, shading, a dark blob, 8- and
    16-bit): the p-values are uniform (KS), and at most 2 of the 200 tests fall below ALPHA
    (0.2 expected; P(>= 3) ~ 1e-3)."""
    rng = np.random.default_rng(7)
    ps = []
    y, x = np.mgrid[0:240, 0:320]
    for k in range(100):
        level, sd = rng.uniform(50, 3000), rng.uniform(1, 100)
        shade = 1 + rng.uniform(-0.2, 0.2) * x / 320 + rng.uniform(-0.2, 0.2) * y / 240
        img = level * shade + rng.normal(0, sd, x.shape)
        img[((x - 160) ** 2 + (y - 100) ** 2) < 100] -= 5 * sd
        top = 255.0 if k % 2 else 65535.0
        img = np.clip(np.round(img * (0.05 if k % 2 else 1)), 0, top)
        _, (c, r) = find_stripes(img, None, top)
        ps += [c.p_value, r.p_value]
    assert np.sum(np.array(ps) < ALPHA) <= 2
    assert stats.kstest(ps, "uniform").pvalue > 1e-3


def test_a_column_pattern_moves_a_near_vertical_mark_no_more_than_its_u():
    """The issue's case (column FPN 2 % of the contrast, a near-vertical mark, -9.6" at no
    flag before): one seed here (the slow sweep has the statistics); the stripes are named
    and the angle is within 3 u of the truth."""
    s = _image(5, column_fpn=0.6 * 0.02)
    (r,) = measure_image(s.image, ranges=LensRanges.none())
    assert any("column stripes" in n for n in r.notes)
    assert abs(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad)) <= 3 * r.angle_u_rad


def _clean_marked(k: int, vignetting: float, offset_px: float, length_px: float):
    """A stripe-free 480x360 frame with one near-vertical (k even) or near-horizontal mark,
    8/12/16-bit by k, under vignetting."""
    rng = np.random.default_rng([k, 0x18])
    a = (90.0 if k % 2 == 0 else 0.0) + rng.uniform(-0.5, 0.5)
    spec = ImageSpec(marks=(MarkSpec(np.deg2rad(a), offset_px, length_px, 4.0),), width=480,
                     height=360, full_well_e=full_well_for_snr(40, -0.6),
                     vignetting=vignetting, bits=(8, 12, 16)[k % 3], seed=k)
    return render_marks(spec, with_crlb=False).image


def test_a_clean_mark_under_vignetting_is_not_stripes():
    """user6: a clean 250 px vertical mark near the centre of a vignetted frame was "column
    stripes ... removed" (a row crossing the mark took its level from the darker columns
    beside it: a dip common to both halves on the mark's columns). 8 frames (vertical and
    horizontal, 8/12/16-bit, 30 % vignetting): 3 flagged before, none now (0.016 expected
    at ALPHA on two axes)."""
    flagged = []
    for k in range(8):
        fr = measure_frame(_clean_marked(k, 0.3, np.random.default_rng(k).uniform(-6, 6), 250.0))
        flagged += [(k, s.axis, s.p_value) for s in fr.stripes if s.found]
    assert not flagged


@pytest.mark.slow
def test_clean_marks_flag_stripes_at_most_one_percent():
    """300 stripe-free frames (vertical and horizontal marks 150-300 px anywhere near the
    centre, vignetting 0-30 %, 8/12/16-bit): the frames with a stripe flag are consistent
    with a rate of at most 1 % (binomial, one-sided at 1e-3); the test's own level is
    2 x ALPHA = 0.2 %."""
    n, flagged = 300, 0
    for k in range(n):
        rng = np.random.default_rng([k, 0x18, 1])
        img = _clean_marked(k, rng.uniform(0, 0.3), rng.uniform(-60, 60),
                            rng.uniform(150, 300))
        flagged += any(s.found for s in measure_frame(img).stripes)
    assert flagged <= stats.binom.isf(1e-3, n, 0.01), flagged


def _row_pattern_p(run: int, seeds: range, amp_dn: float) -> list[float]:
    """p of the row test on 5 MP backgrounds (noise 100 DN, a row pattern of ``amp_dn`` rms)
    with the frame's columns sampled in runs of ``run`` (a huge run: one in every step)."""
    h, w = 1944, 2592
    mask = np.zeros((w, h), bool)
    out = []
    saved = stripes.RUN
    try:
        stripes.RUN = run
        for seed in seeds:
            rng = np.random.default_rng(seed)
            rows = amp_dn * rng.standard_normal(h)[:, None]
            img = 20000 + 100 * rng.standard_normal((h, w)) + rows
            out.append(stripes.column_stripes(img.T, mask, 65535.0).p_value)
    finally:
        stripes.RUN = saved
    return out


def test_row_test_on_runs_of_columns_finds_a_pattern_and_not_noise():
    """At 5 MP the row test samples the frame's columns in runs of 8 (stripes._runs): the same
    number of pixels per row as one in every 9, so the same test. A row pattern at 5 % of the
    pixel noise is found (p far below alpha) and a clean background is not, both with runs."""
    found, clean = _row_pattern_p(8, range(1), 5.0)[0], _row_pattern_p(8, range(1, 2), 0.0)[0]
    assert found < 1e-6 and clean > ALPHA


@pytest.mark.slow
def test_row_test_on_runs_of_columns_has_the_power_of_spread_columns():
    """Runs of 8 adjacent columns against one in every 9, 20 clean and 20 striped 5 MP frames
    each (pattern 2.2 % of the noise, near the test's limit): no false alarm at alpha either
    way, and the two find the pattern equally often (counts within 2 binomial sigma of each
    other) with median log10 p within 0.5."""
    runs = np.array(_row_pattern_p(8, range(20), 2.2))
    spread = np.array(_row_pattern_p(10**6, range(20), 2.2))
    clean = np.array(_row_pattern_p(8, range(20, 40), 0.0))
    assert (clean < ALPHA).sum() <= 1  # (P(2 or more of 20 at alpha 1e-3) ~ 2e-4)
    a, b = int((runs < ALPHA).sum()), int((spread < ALPHA).sum())
    assert 0 < a < 20 and abs(a - b) <= 2 * np.sqrt(20 * 0.25 * 2)
    assert abs(np.median(np.log10(runs)) - np.median(np.log10(spread))) < 0.5


def test_interquartile_means_row_by_row():
    """The test's robust profiles (each column's or row's interquartile mean over its finite
    entries, from one sort and OpenCV's counts and transposes) equal the same mean taken
    line by line (to rounding), NaN with fewer than MIN_ROWS finite entries: float32 rows
    with NaN holes (the marks' bands), both axes, strided views."""
    rng = np.random.default_rng(18)
    for k in range(40):
        a = rng.normal(1000.0, 30.0, size=(int(rng.integers(1, 90)), int(rng.integers(1, 90))))
        a[rng.random(a.shape) < rng.uniform(0.0, 0.9)] = np.nan
        a = a.astype(np.float32)[:, ::1 + k % 2]
        for axis in (0, 1):
            lines = a.T if axis == 0 else a
            want = np.full(lines.shape[0], np.nan)
            if lines.shape[1] >= stripes.MIN_ROWS:
                for i, line in enumerate(lines):
                    f = np.sort(line[np.isfinite(line)]).astype(float)
                    if f.size >= stripes.MIN_ROWS:
                        want[i] = f[f.size // 4:f.size - f.size // 4].mean()
            np.testing.assert_allclose(stripes._column_median(a, axis), want, rtol=1e-12)
