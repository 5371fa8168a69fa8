"""The marks checked against a calibrated lens with the calibration's joint covariance
(:func:`align.lens_terms.lens_cov`): k1 and k2 of one calibration strongly anticorrelated,
a change of the lens along their well-determined combination is missed by their u's taken
as independent (the rule before camera format 4), and the angles then carry a bias far
beyond their u, silently."""

from __future__ import annotations

import numpy as np

from align.lens_design import LineGeometry
from align.lens_terms import check_camera, lens_cov, lens_or_bends, lone_departures
from imaging.lens import distort_points

R = 400.0
"""Half-diagonal [px] of a 640x480 frame."""
U_K = 0.02
RHO = -0.98
COV = np.zeros((7, 7))
COV[:2, :2] = U_K**2 * np.array([[1.0, RHO], [RHO, 1.0]])
"""A calibration's lens-vector covariance: k1, k2 (at the half-diagonal) each ± 0.02,
correlated −0.98 (the real chessboard views: −0.94 to −0.97): k1 + k2 known to ± 0.004."""


def _lines(dlam: np.ndarray, seed: int, sigma: float = 0.05) -> list[LineGeometry]:
    """Four straight 220 px marks 200-250 px from the centre, through a lens that departs
    from the calibration by ``dlam`` (centres with white noise ``sigma`` [px])."""
    rng = np.random.default_rng(seed)
    out = []
    for x, y, a in ((-180, -130, 10), (170, 120, 70), (200, -100, -30), (-150, 140, -60)):
        a = np.radians(a)
        q = np.array([x, y]) + np.outer(np.linspace(-110, 110, 220), [np.cos(a), -np.sin(a)])
        raw = distort_points(q, dlam, R) + rng.normal(0, sigma, q.shape)
        out.append(LineGeometry(raw, np.full(len(q), sigma), None))
    return out


def test_a_departure_the_joint_covariance_sees_and_the_independent_rule_misses():
    """The lens changed by 0.02 along k1 + k2 (5 of its joint u, 0.7 of the u's as if
    independent), 3 seeds: with the joint covariance the marks call the lens changed
    (p < 1e-3: the camera's warning, u widened); with the u's as if independent they
    agree with the calibration (p ≥ 1e-3) while the worst mark's angle is off by more than
    3 of its u from the calibration — the old rule's silent wrong answer. The departure is
    every mark's (no one mark's alone). Control: no change, both rules agree."""
    dlam = np.zeros(7)
    dlam[:2] = 0.02 / np.sqrt(2)
    zero, diag_u = np.zeros(7), np.sqrt(np.diag(COV))
    np.testing.assert_array_equal(lens_cov(diag_u), np.diag(np.diag(COV)))
    for seed in range(3):
        lines = _lines(dlam, seed)
        p_joint, _, designs = check_camera(lines, zero, COV, R)
        p_indep = check_camera(lines, zero, diag_u, R)[0]
        assert p_joint < 1e-3 <= p_indep, (p_joint, p_indep)
        z = [abs(d.s @ dlam) / np.sqrt(d.s @ COV @ d.s) for d in designs]
        assert max(z) > 3, z
        assert lone_departures(designs, COV) == ()
        p0 = [check_camera(_lines(zero, seed), zero, c, R)[0] for c in (COV, diag_u)]
        assert min(p0) >= 1e-3, p0


def _mark(x: float, y: float, a_deg: float, length: float, dlam: np.ndarray, seed,
          sigma: float = 0.05) -> LineGeometry:
    """A straight mark of ``length`` [px] through (x, y) px from the centre at ``a_deg``,
    imaged through a lens that departs from the calibration by ``dlam``."""
    rng = np.random.default_rng(seed)
    a = np.radians(a_deg)
    t = np.linspace(-length / 2, length / 2, int(length))
    q = np.array([x, y]) + np.outer(t, [np.cos(a), -np.sin(a)])
    return LineGeometry(distort_points(q, dlam, R) + rng.normal(0, sigma, q.shape),
                        np.full(len(q), sigma), None)


def test_marks_are_bent_only_where_the_straight_marks_rule_the_lens_change_out():
    """Two corner marks depart from an exact calibration by bows of opposite k1 (±0.01 at
    the half-diagonal: no one linear change fits both — as a wrong model's principal point
    and k's left two of user 12's marks) beside a straight third mark. A short one at the
    centre would show the change their bows call for < 1 sigma: it cannot rule a changed
    lens out, so the marks are not read as bent beside a kept calibration ('undecided': u
    carries the lens; before: 'bends' in 4/4 seeds). A long one in the corner would show it
    5-6 sigma and is straight: 'bends' (4/4)."""
    cov = np.diag(np.full(7, 1e-8))
    zero = np.zeros(7)
    k = np.zeros(7)
    k[0] = 0.01
    for seed in range(4):
        bowed = [_mark(-180, -130, 10, 220, k, [seed, 0]), _mark(170, 120, 70, 220, -k, [seed, 1])]
        for third, verdict in (((5, -8, 120, 80), "undecided"),
                               ((200, -100, -30, 220), "bends")):
            p, _, designs = check_camera([*bowed, _mark(*third, zero, [seed, 2])], zero, cov, R)
            told = lens_or_bends(designs, cov)
            assert p < 1e-3 and told is not None, (seed, p)
            assert told.verdict == verdict and told.departing == (0, 1), (seed, third, told)
