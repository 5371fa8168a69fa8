"""A log of the other direction: the mean of both, and the term it cancels.

The other direction brings the faces in reverse order; what flips sign with the direction
(autocollimator latency times a speed change locked to the table, an Earth rate not removed)
is half the difference of the two runs' angles, and the plain mean cancels it. A "reverse"
log whose difference is far beyond what a reversal leaves is refused (``check_reversed``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from align.errors import InputError
from axisbase.units import ARCSEC
from goniometry import FaceAngles


@dataclass(frozen=True)
class DirectionTerm:
    """Half the difference between the counter-clockwise and clockwise estimates of each angle
    [rad] (ccw order) with its covariance: what flips with the direction — autocollimator
    latency times a speed change locked to the table, an Earth rate not removed — and which
    the mean of the two directions cancels. chi2 over n - 1 dof (closure) and its p-value."""

    half_difference_rad: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    p_value: float

    @property
    def u_rad(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))


def combine_directions(fwd: FaceAngles, rev: FaceAngles) -> tuple[FaceAngles, DirectionTerm]:
    """Mean of a run and a run in the other direction, angles in the first run's order.

    The other direction brings the faces in reverse order (0, n-1, ..., 1): its angle m is the
    first run's angle n-1-m. Equal weights on purpose: only the plain mean cancels what flips
    sign with the direction.
    """
    n = len(fwd.angles_rad)
    if len(rev.angles_rad) != n:
        raise InputError(f"the two directions have {n} and {len(rev.angles_rad)} faces")
    P = np.eye(n)[::-1]
    a_rev = P @ rev.angles_rad
    c_rev = P @ rev.cov @ P.T
    mean = (fwd.angles_rad + a_rev) / 2
    cov = (fwd.cov + c_rev) / 4
    half = (fwd.angles_rad - a_rev) / 2
    chi2 = float(half @ np.linalg.pinv(cov, rcond=1e-10) @ half)
    from scipy.special import chdtrc  # (the chi2 survival function)

    term = DirectionTerm(half, cov, chi2, n - 1, float(chdtrc(n - 1, chi2)))
    comb = replace(
        fwd, angles_rad=mean, u_rad=np.sqrt(np.diag(cov)), cov=cov,
        u_type_a_rad=np.sqrt(fwd.u_type_a_rad**2 + (P @ rev.u_type_a_rad) ** 2) / 2,
        u_type_b_rad=np.sqrt(fwd.u_type_b_rad**2 + (P @ rev.u_type_b_rad) ** 2) / 2,
        revolutions=fwd.revolutions + rev.revolutions,
        quantisation_locked=fwd.quantisation_locked & (P @ rev.quantisation_locked > 0))
    return comb, term


DIRECTION_LIMIT_ARCSEC = 10.0
"""The largest direction-dependent part of a face angle a real reversal leaves [″]. What
flips with the direction — the autocollimator's latency times the change of the table's
speed between faces (5 µs x a 2 % ripple at 1 rev/s: 0.13″), a tilted detector slit over
pyramidal errors (10″ x tan 1°: 0.17″) — stays under a second of arc; a 'reverse' log whose
reversed angles differ from the forward run's by more is not the other direction of the same
faces (the same direction read reversed differs by the faces' deviations from equal spacing:
arc-minutes)."""


def check_reversed(fwd: FaceAngles, rev: FaceAngles, term: DirectionTerm, path,
                   reverse_log, alpha: float, unexplained: np.ndarray | None = None) -> None:
    """Refuse a reverse log that is not the forward run's faces turning the other way, saying
    whether it matches the forward run unreversed. Judged on ``unexplained``: the half
    difference [rad] less what the autocollimator's latency times each run's measured speed
    profile (and an Earth rate not removed) leaves (:mod:`align.gonio_latency`; the whole
    half difference when not given) — beyond ``DIRECTION_LIMIT_ARCSEC``, what else a
    reversal leaves, and significant."""
    left = term.half_difference_rad if unexplained is None else unexplained
    worst = float(np.max(np.abs(left))) / ARCSEC
    if worst <= DIRECTION_LIMIT_ARCSEC or term.p_value >= alpha:
        return
    same = float(np.max(np.abs(fwd.angles_rad - rev.angles_rad))) / ARCSEC
    why = (f"its angles read unreversed match {Path(path).name}'s within {same:.2g}″: the "
           "table turned the same way in both runs" if same <= DIRECTION_LIMIT_ARCSEC else
           "nor do they match it unreversed (another table, or other faces)")
    raise InputError(
        f"--reverse-log {reverse_log}: reversed, its face angles differ from {path}'s by up to "
        f"{2 * float(np.max(np.abs(term.half_difference_rad))) / ARCSEC:.3g}″ (direction-"
        f"dependent part {worst:.3g}″ beyond what the latency times the speeds explains, more "
        f"than the {DIRECTION_LIMIT_ARCSEC:g}″ a slit tilt leaves) — it is not a run in "
        f"the other direction; {why}. Measure each log alone, or give a log of the table "
        "turning the other way")


def direction_effect(term: DirectionTerm, faces: Sequence[str]) -> dict:
    """The direction-dependent term as an entry of the JSON ``effects`` list: per angle the
    half difference ccw - cw [rad]; the most significant one is the estimate; after the mean
    of both directions it is cancelled (rms_after 0)."""
    n = len(faces)
    k = int(np.argmax(np.abs(term.half_difference_rad) / term.u_rad))
    return {"name": "direction_dependent", "estimate": float(term.half_difference_rad[k]),
            "u": float(term.u_rad[k]), "unit": "rad",
            "rms_before": float(np.sqrt(np.mean(term.half_difference_rad**2))),
            "rms_after": 0.0, "p_value": term.p_value, "chi2": term.chi2, "dof": term.dof,
            "components": [{"axis": f"{faces[i]}->{faces[(i + 1) % n]}",
                            "estimate": float(term.half_difference_rad[i]),
                            "u": float(term.u_rad[i])} for i in range(n)]}

