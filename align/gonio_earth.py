"""A declared Earth rate (``--latitude``, ``--direction``) checked against the one the log shows.

With pulse times on a table whose speed varies, the counts per revolution follow the period
with the slope of the vertical rate the ring laser sees (:mod:`align.gonio_loop`). A latitude
typed with the wrong sign, or a clockwise log read as counter-clockwise, removes the Earth
rate with the wrong sign: the angles are then off by many u with nothing said. When the log's
rate disagrees with the declared one beyond its u (a two-sided test at the loop's alpha) the
result warns, naming the flags and keys, and the angles are taken at the mid-point of the two
rates with half their difference (plus the fit's u) carried in u as a named Type B term: it
covers either being right.
"""

from __future__ import annotations

import numpy as np

from align.gonio_loop import latitude_from_earth_rate, seen_earth_rate
from goniometry import FaceAngles, LogSummary, face_angles, kept_table
from goniometry.angles import vertical_earth_rate

DECLARED_DISAGREES = "earth_rate (declared vs. the log's)"


def declared_earth_angles(summary: LogSummary, latitude_rad: float, direction: int,
                          alpha: float, max_revolutions: int
                          ) -> tuple[FaceAngles, float, str | None]:
    """Face angles with the declared Earth rate removed, unless the log disagrees with it.

    Parameters
    ----------
    summary : LogSummary
        The pass over a log with pulse times.
    latitude_rad : float
        Declared latitude [rad].
    direction : int
        Declared direction, +1 counter-clockwise, -1 clockwise.
    alpha : float
        False-alarm rate of the test (two-sided).
    max_revolutions : int
        Revolutions the fit sees (the head of the log).

    Returns
    -------
    FaceAngles, float, str or None
        The angles, the rate removed [rad/s], and the warning when the log disagrees.
    """
    declared = vertical_earth_rate(latitude_rad, direction)
    counts, dt, t_end = kept_table(summary)
    m = max_revolutions
    seen = seen_earth_rate(counts[:m], dt[:m], t_end[:m]) if len(counts) >= 40 else None
    if seen is None:
        return face_angles(summary, declared), declared, None
    from scipy.special import ndtri  # (the normal quantile; loaded only when needed)

    est, u = seen
    z = (est - declared) / u
    if abs(z) <= float(ndtri(1 - alpha / 2)):
        return face_angles(summary, declared), declared, None
    mid, half = (est + declared) / 2, abs(est - declared) / 2
    lat, ulat = latitude_from_earth_rate(est, u, direction)
    lat_flip, _ = latitude_from_earth_rate(est, u, -direction)
    why = (f"the Earth rate this log shows ({est:.3g} ± {u:.2g} rad/s: latitude "
           f"{np.rad2deg(lat):.0f} ± {np.rad2deg(ulat):.0f}° turning "
           f"{'ccw' if direction > 0 else 'cw'}, or {np.rad2deg(lat_flip):.0f}° turning "
           f"{'cw' if direction > 0 else 'ccw'}) disagrees with the declared --latitude "
           f"{np.rad2deg(latitude_rad):g} --direction {'ccw' if direction > 0 else 'cw'} "
           f"({declared:.3g} rad/s; session.toml latitude_deg, [goniometer] direction) by "
           f"{abs(z):.1f} u: a latitude of the wrong sign or the wrong direction? Angles at "
           "the mid-point of both rates, the difference carried in u")
    fa = face_angles(summary, mid, type_b={DECLARED_DISAGREES: float(np.hypot(half, u))})
    return fa, mid, why
