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
@pytest.mark.parametrize("k1", [K1, 0.0])
def test_undeclared_lens_held_out_marks_reach_the_k1_free_bound(k1):
    """With k1 free the angle is read against the lens's bow mostly from the ends' centres:
    they must reach the groove's ends (imaging.ends.centres_stretch). Sampled on the
    search's stretch (~248 of the 300 px, whose bound is 1.51-1.55x) the RMS was 1.59 under
    the lens and 1.53 without one; out to a blurred end short of each end 1.23 and 1.16
    (err/u RMS 0.19 and 1.05, max 0.66 and 2.63)."""
    lo, hi = _band(N_MARKS)
    assert lo <= _report(k1) <= hi
