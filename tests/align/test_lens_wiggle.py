"""A wiggle fitted out of a mark before the lens reads its bow (:mod:`align.lens_wiggle`, issue
18 ask 3: a wiggle needs >= 2 periods along the mark). Straight 300 px marks off the image
centre with white centre noise; a sinusoid across the mark (a shaking camera's rolling
shutter) of a known period and amplitude."""

from __future__ import annotations

import numpy as np

from align.lens_design import LineGeometry
from align.lens_terms import check_camera
from align.lens_wiggle import without_wiggle

R = 400.0
"""Half-diagonal [px] of a 640x480 frame."""
SIGMA = 0.05
"""Centre noise across the mark [px]."""


def _mark(seed: int, amp: float = 0.0, period: float = 110.0, sag: float = 0.0,
          n: int = 75) -> LineGeometry:
    """A 300 px mark at 35 deg through (120, -90) px from the centre: a wiggle of ``amp``
    [px] and ``period`` [px] along it, and a bow of sagitta ``sag`` [px] (a lens's shape)."""
    rng = np.random.default_rng([seed, 41])
    a = np.deg2rad(35.0)
    u, nrm = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
    t = np.linspace(-150, 150, n)
    phase = rng.uniform(0, 2 * np.pi)
    e = (amp * np.sin(2 * np.pi * t / period + phase) + sag * (t / 150) ** 2
         + rng.normal(0, SIGMA, n))
    return LineGeometry(np.array([120.0, -90.0]) + np.outer(t, u) + np.outer(e, nrm),
                        np.full(n, SIGMA))


def test_a_wiggle_of_enough_periods_is_found_and_taken_off():
    """0.2 px at 110 px (2.7 periods along the mark) beside a lens's 1 px bow, 10 seeds:
    found every time, its period within 3 % and amplitude within 0.02 px (4 x the fit's
    sd ~ SIGMA sqrt(2/75)); what is left is the bow and the noise (a cubic along the mark
    leaves chi2 of the noise: within its 5 sd, sqrt(2 dof))."""
    for seed in range(10):
        line = _mark(seed, amp=0.2, sag=1.0)
        out, wig = without_wiggle(line)
        assert wig is not None, seed
        assert abs(wig.period_px / 110.0 - 1) < 0.03, wig
        assert abs(wig.amplitude_px - 0.2) < 0.02, wig
        a = np.deg2rad(35.0)
        q = out.points
        t, e = q @ [np.cos(a), np.sin(a)], q @ [-np.sin(a), np.cos(a)]
        X = np.column_stack([t**k / 150**k for k in range(4)])
        r = e - X @ np.linalg.lstsq(X, e, rcond=None)[0]
        dof = len(t) - 4 - 2
        assert abs(np.sum((r / SIGMA) ** 2) - dof) < 5 * np.sqrt(2 * dof), seed


def test_fewer_than_two_periods_or_noise_alone_is_no_wiggle():
    """A 0.2 px sinusoid of 1.5 periods along the mark (200 px) is a bow, a bend or a lens,
    never a wiggle (10 seeds); noise alone at the test's level 1e-3: at most 2 false wiggles
    in 100 marks (P(>= 3) = 2e-4 at the nominal rate)."""
    for seed in range(10):
        assert without_wiggle(_mark(seed, amp=0.2, period=200.0))[1] is None, seed
    false = sum(without_wiggle(_mark(seed, sag=1.0))[1] is not None for seed in range(100))
    assert false <= 2, false


def test_the_lens_check_reads_the_mark_without_its_wiggle():
    """A straight mark through an exact calibration with a 0.3 px wiggle of 2.7 periods: the
    check reads the wiggle as the lens departing from its model (p < 1e-3, user 8's shaking
    camera: cy +13 px on top of an exact model), and after the wiggle is taken off the mark
    agrees with the calibration (p >= 1e-3), 5 seeds."""
    zero = np.zeros(7)
    cov = np.diag(np.full(7, 1e-8))
    for seed in range(5):
        line = _mark(seed, amp=0.3)
        assert check_camera([line], zero, cov, R)[0] < 1e-3, seed
        assert check_camera([without_wiggle(line)[0]], zero, cov, R)[0] >= 1e-3, seed
