"""Issue 18 failure mode 5, held-out figure: single marks under an undeclared radial lens, the
angle error over the Cramér–Rao bound of a line + k1 fitted from the mark's own pixels.

The bound is synth's (``crlb(..., free_k1=True, free_ends=True)``: Fisher information over
the noise-free render, with the lens's k1 as one more nuisance, and the mark's length and
position along its line too: a tool is never told where a mark ends, and with the ends known
the bound reads k1 from how far the lens moves them, 1.4-1.75x lower). To be held to it, the
pipeline is told the same model: k1 free over its plausible range, the rest of the lens (k2,
p, aspect, principal point) declared absent. An efficient unbiased estimator gives
mean((err/CRLB)²) ~ χ²_n / n; the band is its 0.1 %–99.9 % quantiles. The control is the
same marks without a lens, declared absent (the bound the line's own, k1 fixed): the line
fit is efficient.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy import stats

from align.lens import LensRanges
from align.marks import measure_image
from synth import CameraGeometry, ImageSpec, MarkSpec, crlb, full_well_for_snr, render_marks
from tests.conftest import angle_error

K1_ONLY = LensRanges(k1=0.3, k2=0.0, p=0.0, aspect=0.0, pp_px=0.0)
FOCAL_PX, K1 = 1024.0, -0.3  # the session cameras' focal length (1.6 w); OpenCV k1
N_MARKS = 40


def _mark(seed: int, k1: float, ranges: LensRanges = K1_ONLY) -> tuple[float, float, float]:
    """(angle error, CRLB with k1 (when ``ranges`` has it) and the ends free, the pipeline's
    u) [rad] of one 300 px mark at a random angle and place (offset +-150 px, along +-80 px)
    in a 640x480 frame."""
    rng = np.random.default_rng(seed)
    mark = MarkSpec(rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(-150, 150), 300.0, 4.0,
                    centre_t_px=rng.uniform(-80, 80))
    spec = ImageSpec(marks=(mark,), width=640, height=480, seed=seed, supersample=4,
                     camera=CameraGeometry(focal_px=FOCAL_PX, k1=k1),
                     full_well_e=full_well_for_snr(40, -0.6))
    s = render_marks(spec, with_crlb=False)
    (r,) = measure_image(s.image.astype(float), ranges=ranges, expect_one=True)
    return (angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad),
            crlb(spec, free_k1=ranges.k1 > 0, free_ends=True)[0], r.angle_u_rad)


@cache
def _sweep(k1: float, ranges: LensRanges = K1_ONLY) -> np.ndarray:
    return np.array([_mark(seed, k1, ranges) for seed in range(N_MARKS)])


def _band(n: int) -> tuple[float, float]:
    return (np.sqrt(stats.chi2.ppf(1e-3, n) / n), np.sqrt(stats.chi2.ppf(1 - 1e-3, n) / n))


def _report(k1: float, ranges: LensRanges = K1_ONLY) -> float:
    x = _sweep(k1, ranges)
    rms = float(np.sqrt(np.mean((x[:, 0] / x[:, 1]) ** 2)))
    print(f"k1 {k1}, k1 range {ranges.k1}: RMS err/CRLB {rms:.2f} (band {_band(len(x))[0]:.2f}-"
          f"{_band(len(x))[1]:.2f}); err/u RMS {np.sqrt(np.mean((x[:, 0] / x[:, 2])**2)):.2f}, "
          f"max {np.max(np.abs(x[:, 0] / x[:, 2])):.2f} over {len(x)}")
    return rms


@pytest.mark.slow
def test_lens_free_control_meets_its_bound():
    """The control: no lens, declared absent, the same marks: the line fit is efficient (the
    instrument works)."""
    lo, hi = _band(N_MARKS)
    none = LensRanges.none()
    assert lo <= _report(0.0, none) <= hi
    x = _sweep(0.0, none)
    assert np.max(np.abs(x[:, 0] / x[:, 2])) <= 3


@pytest.mark.slow
@pytest.mark.parametrize("k1", [K1, 0.0])
def test_undeclared_lens_held_out_marks_within_their_u(k1):
    """With k1 free over its range the tool is never confidently wrong, under the lens and
    without one: every |err|/u <= 3."""
    _report(k1)
    x = _sweep(k1)
    assert np.max(np.abs(x[:, 0] / x[:, 2])) <= 3


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 18 failure mode 5: RMS err/CRLB(k1 and ends free)"
                   " 1.59 under the lens over 40 (1.53 without one): the k1-free line fit from"
                   " the centres (u honest: err/u RMS 1.04 at k1 = 0) is 1.5x the pixels' bound;"
                   " the centres span ~248 of the 300 px, whose bound is 1.51-1.55x. Centres"
                   " out to a blurred end short of each groove end (stopped at other marks and"
                   " the frame: branch ends2, 38c6407 + fb1ec85, reverted) reach 1.21 and 1.16"
                   " (err/u RMS 0.19 / 1.06, max 0.66 / 2.63) but 5 slow tests then fail: the"
                   " dial's graduations' u drops ~30 % while their error does not (seed 0: z"
                   " -3.87), a strong lens folds at a principal-point probe over the longer"
                   " centres (lens_shared: u inf), two bent-mark seeds lose 'differs', and"
                   " marks_loop's k1 +0.2 RMS z falls to 0.37 (< 0.4). Since (branch ends3-wip,"
                   " 551644a): the dial was a 1-series texture coupling (fixed on main:"
                   " imaging.centres.MIN_CV_REPLICAS), lens_shared's inf the fold (fixed:"
                   " align.lens_pp.pp_corners) then end centres past the half-depth end (capped"
                   " there); camera_lens seed 2's 'neither' was lens_or_bends comparing a k1"
                   " read with k2 free against one with k2 held at 0 (fixed on main). Left"
                   " (branch ends4-wip): marks_loop's k1 +0.2 floor, RMS z 0.365 < 0.4: the"
                   " angles' RMS error falls 30.4 -> 26.0'' while u stays 59.5 -> 58.9'',"
                   " mostly Type B terms this scene does not realise (lens_pp_cross 42.1 ->"
                   " 42.9'' RMS, its principal point at the centre): not a term the longer"
                   " centres widen. Centres out to the grooves' ends (ends6: merged cd3df0f,"
                   " reverted 0e52ce9; branches ends7-full, ends7-wip) reach 1.13 and 1.05"
                   " but 3 slow tests failed. (1) marks_crossing 5 deg 'end' seed 2003, z"
                   " 3.92: not the added centres (added at the far end, t -231 -> -245 px;"
                   " the error is 71.8'' with them, 71.3'' without) but the crossing mask's"
                   " window, short of the other groove's flank: a groove 12-14 px beside a 9 px"
                   " band tilts the line; the longer centres' u (28.2 -> 18.3'') exposed it (z"
                   " 2.53 on this tree). The window + 2 blur widths: error 2'', z -0.10, but"
                   " test_crossmask's stepped corner is then refused (seeds 1, 2; ends7-wip)."
                   " (2) test_jpeg q90 crop, seed 3's first mark, z -3.40: its error is"
                   " -20.9'' with the added centres, -22.7'' without (z -2.96); u 7.7 -> 6.1''"
                   " because the Type B jpeg_blocks (the noise-free model's turn beyond its"
                   " scatter, imaging.jpeg.blocks_systematic) fell 3.4 -> 0.0'' over the"
                   " longer stretch: the encoder's turn of a noisy edge the model under-states"
                   " (the q75 crop's open issue), not the end centres. (3) test_lens"
                   " exact-camera check, 20 seeds: KS p 2.9e-5, median p 0.83 (0.032, 0.75"
                   " without the added centres); with the model's u x 0.01 KS p 0.021, median"
                   " 0.78 (0.14, 0.70 without), the pp stability not entering p: the model's"
                   " declared u, realised 0 by the render, bows more beside the noise over"
                   " the longer centres (a conservative p, no false alarm; angles' RMS z"
                   " 0.27). Branch cross8 (tag cross8-ext; 27 Nov, on 8305a96): (1) fixed on"
                   " main too: the crossing groove's flank beside the stretch left out"
                   " (imaging.crossmask.flank_skip) and its run-on measured (run_on): 71.8'' ->"
                   " 19.4'' at u 38.5'', crossing sweep 106 angles within 2.71 u with the"
                   " extension (2.57 u here); (2) q90 crop still a strict xfail, z -3.40 (jcrop);"
                   " (3) conservative by construction: median p 0.85, RMS z 0.12; with the"
                   " lens drawn from the declared u KS p 0.24, max |z| 2.35, RMS z 1.07 over"
                   " 40 (one-sided KS then passes: cross8-ext's test_lens). The extension then"
                   " reached 1.23 / 1.16, but test_marks_bend seed 14 'centre' (3.6 px"
                   " parabola over 287 px) failed, z 3.12: the extent look on the straight line"
                   " read one end 10.5 px short, the chord turned 279'' (covered on main only"
                   " by chord-vs-fit 185'', 2'' over the longer centres); the extent looked for"
                   " along the groove's path fixes it (-54'', z -0.60) but a q50 near-axis JPEG"
                   " mark then reaches z 3.13 (test_jpeg q50 file and crop), not looked into")
@pytest.mark.parametrize("k1", [K1, 0.0])
def test_undeclared_lens_held_out_marks_reach_the_k1_free_bound(k1):
    lo, hi = _band(N_MARKS)
    assert lo <= _report(k1) <= hi
