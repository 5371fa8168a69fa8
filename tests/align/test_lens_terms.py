"""The marks checked against a calibrated lens with the calibration's joint covariance
(:func:`align.lens_terms.lens_cov`): k1 and k2 of one calibration strongly anticorrelated,
a change of the lens along their well-determined combination is missed by their u's taken
as independent (the rule before camera format 4), and the angles then carry a bias far
beyond their u, silently."""

from __future__ import annotations

import numpy as np

from align.lens_design import LineGeometry
from align.lens_terms import check_camera, lens_cov, lone_departures
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
