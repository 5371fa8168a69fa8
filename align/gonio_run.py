"""The result of the goniometer pipeline (:func:`align.gonio.measure_log`) and its JSON form:
face angles with u, the revolution summary, the loop, the direction and timing terms."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from align.gonio_directions import DirectionTerm, direction_effect
from axisbase.units import ARCSEC
from goniometry import FaceAngles, LogSummary
from goniometry.exclusions import code_of
from goniometry.timing import TimingAngles

if TYPE_CHECKING:
    from align.loop import LoopReport


@dataclass(frozen=True)
class GonioRun:
    """A counter log through the goniometer pipeline: the revolution summary, the face angles,
    the revolution-level loop (None when it did not run) and notes for the user. With a log
    of the other direction, ``angles`` is the mean of both, ``reverse`` that run and
    ``direction`` the term the mean cancelled.

    Attributes
    ----------
    summary : LogSummary
        The streaming pass's revolutions, exclusions and faults; unit — (its fields carry
        units).
    angles : FaceAngles
        The face angles [rad] with their u [rad] (Earth's rotation removed or bounded).
    loop : LoopReport or None
        The revolution-level loop (None when it did not run); unit —.
    notes : tuple of str
        What the user should know about the log; unit —.
    earth_rate_applied : float or None
        The vertical Earth rate removed [rad/s] (None: bounded in u, not removed).
    reverse : GonioRun or None
        The run of the other direction's log, when given; unit —.
    direction : DirectionTerm or None
        The term the mean of both directions cancelled; unit — (its fields carry units).
    timing : TimingAngles or None
        The face angles from the pulse times [rad], when the log has them; unit —.
    timing_used : bool
        Whether the pulse times replaced the counts (a steady table); unit —.
    warnings : tuple of str
        Options given that this log cannot honour; unit —.
    problems : tuple of str
        Why the angles cannot be trusted: a term u does not cover (a log without times on a
        table that may not be steady); the result is then not ok (exit 2); unit —.
    counters_sound : bool
        Whether the user declared the counters verified (no counts lost or gained at their
        switches: no counters' part in u); unit —.
    """

    summary: LogSummary
    angles: FaceAngles
    loop: LoopReport | None
    notes: tuple[str, ...]
    earth_rate_applied: float | None
    reverse: GonioRun | None = None
    direction: DirectionTerm | None = None
    timing: TimingAngles | None = None
    timing_used: bool = False
    warnings: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()
    counters_sound: bool = False

    def to_dict(self, faces: Sequence[str], nominal: np.ndarray | None = None) -> dict:
        """The run as JSON (the contract of ``align gonio``, also a session's stage);
        angles in degrees, uncertainties in arc-seconds at this edge. ``faces``: their
        names in passing order; ``nominal``: nominal angles [rad] for the deviations."""
        fa, summary, loop = self.angles, self.summary, self.loop
        arcsec = 1.0 / ARCSEC
        effects = [e.to_dict() for e in loop.effects] if loop is not None else []
        if self.direction is not None:
            effects.append(direction_effect(self.direction, faces))
        js = {"faces": list(faces), "angles_deg": np.rad2deg(fa.angles_rad).tolist(),
              "angles_u_arcsec": (fa.u_rad * arcsec).tolist(),
              "revolutions_used": fa.revolutions, "effects": effects,
              "unexplained_structure": bool(loop and loop.unexplained_structure),
              "covariance_arcsec2": (fa.cov * arcsec**2).tolist(),
              "type_a_arcsec": (fa.u_type_a_rad * arcsec).tolist(),
              "type_a_method": fa.type_a_method, "jitter_counts": fa.jitter_counts,
              "type_b_arcsec": (fa.u_type_b_rad * arcsec).tolist(),
              "exclusions": {k: {"code": code_of(k), "count": v,
                                 "lines": summary.exclusions.lines[k]}
                             for k, v in summary.exclusions.counts.items()},
              "allan": {"tau_revolutions": fa.allan_tau_rev.tolist(),
                        "adev_arcsec": (fa.allan_dev_rad * arcsec).tolist()},
              "angles_source": "pulse times (steady table)" if self.timing_used else "counts",
              "counters_sound": self.counters_sound,
              "type_b_terms_arcsec": {k: (v * arcsec).tolist()
                                      for k, v in fa.type_b_terms.items()},
              "faults": {"sigma_counts": summary.sigma_counts,
                         "tolerance_counts": summary.tolerance_counts,
                         "revolutions_excluded": summary.excluded_revolutions,
                         "armed_face": summary.armed_face,
                         "rows_before_first_revolution": summary.incomplete_head,
                         "rows_after_last_revolution": summary.incomplete_tail},
              "notes": list(self.notes)}
        if self.timing is not None:
            ta = self.timing
            js["timing"] = {"angles_deg": np.rad2deg(ta.angles_rad).tolist(),
                            "angles_u_arcsec": (ta.u_rad * arcsec).tolist(),
                            "counts_minus_timing_arcsec": (ta.diff_rad * arcsec).tolist(),
                            "counts_minus_timing_u_arcsec": (ta.diff_u_rad * arcsec).tolist(),
                            "chi2": ta.chi2, "dof": ta.dof, "p_value": ta.p_value,
                            "used": self.timing_used}
        if nominal is not None:
            js["deviation_arcsec"] = ((fa.angles_rad - nominal) * arcsec).tolist()
        return js
