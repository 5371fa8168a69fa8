"""How widely the poses spread over directions: the cone that holds them.

A tumble for the ellipsoid should turn the unit over all directions (the paper's cube: six
faces and eight corners). Poses within a cone about one direction see no axis both up and
down; the fit then separates the scale factors from the biases only through the ellipsoid's
curvature, and the narrower the cone, the less it can (third- and fourth-order terms of the
cap carry three of the nine parameters). These functions measure that cone, before the fit
from the raw outputs (any offset, scale near-equal per axis) and after it from the fitted
directions.
"""

from __future__ import annotations

import numpy as np

from align.calibration.units import UNIT_SCALE_REFUSE
from axisbase.units import DEG

HEMISPHERE_RAD = 90 * DEG
"""Poses within a cone of this half-angle [rad] or less see no axis both up and down."""
SURROUND_RAD = 60 * DEG
"""Below this estimated half-angle [rad] the poses do not surround their median: a cap of
half-angle theta has its centroid at (1 + cos theta)/2 of the radius from the centre, so
below ~60 deg a pose near the cap's apex sits closer to the median than a third of the
typical distance, and 'far from the median' no longer means 'another unit'."""


def cone_estimate(u: np.ndarray) -> float:
    """Half-angle [rad] of the cap of the ellipsoid the outputs ``u`` (N, 3) lie on, from
    their own shape: a cap of half-angle theta is tan(theta/2) as deep (along the poses'
    least-spread direction) as it is wide (half its extent across). Exact for a sphere's cap
    with apex and rim populated; saturates near 90-120 deg for poses all round (then it
    says only "not a narrow cone")."""
    c = np.asarray(u, float) - np.mean(u, 0)
    if len(c) < 3:
        return float("nan")
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    p = c @ vt.T
    width = max(np.ptp(p[:, 0]), np.ptp(p[:, 1])) / 2
    if width <= 0:
        return 0.0
    return float(2 * np.arctan(np.ptp(p[:, 2]) / width))


def cone_half_angle(a: np.ndarray) -> float:
    """Half-angle [rad] of the cone about the poses' mean direction that holds every pose
    direction ``a`` (N, 3) (specific forces through a calibration; pi when they have no
    mean direction)."""
    d = np.asarray(a, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    m = d.mean(0)
    if np.linalg.norm(m) < 1e-9:
        return float(np.pi)
    m = m / np.linalg.norm(m)
    return float(np.arccos(np.clip(d @ m, -1.0, 1.0)).max())


def odd_pose(u: np.ndarray) -> tuple[int, float] | None:
    """A pose in another unit than the others: (index, its distance from the centre in
    radii; beyond :data:`UNIT_SCALE_REFUSE` either way), or None. Each pose is measured
    against the sphere fitted to the others
    (algebraic, |u|^2 = 2 c.u + d: the offset and a common scale, which is all a unit
    mix-up changes), so one bad pose cannot hide by dragging the fit. Meaningful only for
    poses that surround the centre (see :data:`SURROUND_RAD`)."""
    u = np.asarray(u, float)
    n = len(u)
    if n < 6:
        return None
    # Centre and scale the data first (the fit is then well conditioned in any unit).
    m = u.mean(0)
    s = float(np.sqrt(np.mean(np.sum((u - m) ** 2, 1)))) or 1.0
    x = (u - m) / s
    A = np.column_stack([2 * x, np.ones(n)])
    b = np.sum(x * x, 1)
    worst: tuple[int, float] | None = None
    for i in range(n):
        keep = np.arange(n) != i
        sol, *_ = np.linalg.lstsq(A[keep], b[keep], rcond=None)
        r2 = sol[3] + sol[:3] @ sol[:3]
        if r2 <= 0:
            continue
        rho = float(np.linalg.norm(x[i] - sol[:3]) / np.sqrt(r2))
        off = max(rho, 1 / rho) if rho > 0 else np.inf
        if off > UNIT_SCALE_REFUSE and (worst is None or off > max(worst[1], 1 / worst[1])):
            worst = (i, rho)
    return worst
