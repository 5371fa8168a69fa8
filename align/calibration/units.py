"""Does the declared output unit fit the measured scale factors?

Readings declared in an acceleration unit (``g``, ``m/s2``) must change by about one g of
that unit per g: 1 g/g, resp. g0 = 9.80665 (m/s²)/g. Volts and counts carry no such
expectation. A triad's scale-factor tolerance is a few per cent (datasheets: 1–3 %) and local
gravity is within 0.3 % of g0, so:

* a scale factor further than a factor sqrt(g0) ≈ 3.13 from the expected one is closer (on a
  log scale) to another unit than to the declared one — readings in g declared m/s², or in
  m/s² declared g, or in mg/counts — and is refused, naming the unit's source and the measured
  magnitude (a calibration in a wrong unit would be written silently otherwise);
* one further than :data:`UNIT_SCALE_WARN` (10 %, over three times the worst tolerance) is
  warned of: a conversion with the wrong range or a wrong factor.

Readings in volts (the default unit) carry a plausible range, :data:`V_PER_G_RANGE`: a static
calibration turns the triad through ±1 g, so its readings span ±k; no data-acquisition input
reads beyond tens of volts, so k above 100 V/g cannot be volts (readings in counts left at the
default unit give thousands), and below 0.1 mV/g a µg would be 0.1 nV, under any ADC's noise.
Outside it is warned of (the numbers are right in the readings' own unit; only the label is
not), naming the key or flag that declares the unit.
"""

from __future__ import annotations

import numpy as np

from align.calibration.triad import TriadModel
from axisbase.errors import InputError
from axisbase.units import G0

EXPECTED_PER_G = {"g": 1.0, "m/s2": G0}
"""Scale factor [unit/g] of readings already in an acceleration unit."""
UNIT_SCALE_REFUSE = float(np.sqrt(G0))
"""Ratio beyond which a magnitude is nearer another unit than the expected one (on a log scale
between the closest mix-up, g against m/s²: a factor g0; a triad's axes and local gravity
differ by a few per cent). The one such limit: the declared unit against the scale factors
here, a pose against the others (:func:`align.calibration.geometry.odd_pose`), check poses
against 1 g (:mod:`align.calibration.check`)."""
UNIT_SCALE_WARN = 0.10
"""Relative departure from the expected scale factor that is warned of."""
_NAMES = {"g": "g", "m/s2": "m/s²"}
V_PER_G_RANGE = (1e-4, 100.0)
"""[V/g] plausible scale factors of readings in volts (see the module's notes)."""


def unit_source(static: str, units: str, in_header: bool) -> str:
    """Who declared the readings' unit when no flag or key did: ``static``'s header
    (``in_header``), else nobody (the default V)."""
    return (f"{static}: header unit [{units}]" if in_header
            else f"{static}: no unit in its header, the default {units}")


def _give(name: str, value: str) -> str:
    """``--units g`` on the command line, ``[calibration] units = "g"`` in session.toml."""
    return f"{name} {value}" if name.startswith("--") else f'{name} = "{value}"'


def unit_scale_check(model: TriadModel, units: str, source: str,
                     units_as: str = "--units") -> list[str]:
    """Warnings about the declared unit ``units`` (from ``source``, e.g. ``--units m/s2``)
    given the calibrated sensitivities; :class:`InputError` when they contradict it.
    ``units_as``: how the user names a unit (``--units``, or session.toml's ``[calibration]
    units``), which the hint names."""
    if units == "V":
        return _volts_check(np.abs(model.sensitivity()), source, units_as)
    expected = EXPECTED_PER_G.get(units)
    if expected is None:
        return []
    s = np.abs(model.sensitivity())
    ratio = s / expected
    nm = _NAMES[units]
    mags = ", ".join(f"{v:.4g}" for v in s)
    if np.any((ratio > UNIT_SCALE_REFUSE) | (ratio < 1 / UNIT_SCALE_REFUSE)):
        mean = float(np.exp(np.mean(np.log(s))))
        nearest = min(EXPECTED_PER_G, key=lambda u: abs(np.log(mean / EXPECTED_PER_G[u])))
        hint = (f"; they look like {_NAMES[nearest]} (give {_give(units_as, nearest)})"
                if abs(np.log(mean / EXPECTED_PER_G[nearest])) < np.log(UNIT_SCALE_REFUSE)
                else f"; if they are volts or counts, say so ({_give(units_as, 'V')} or "
                "counts)")
        raise InputError(f"{source}: readings in {nm} change by {expected:.5g} {nm} per g, "
                         f"these change by {mags} per g (scale factors): not {nm}{hint}")
    far = np.flatnonzero(np.abs(ratio - 1) > UNIT_SCALE_WARN)
    if far.size:
        i = int(far[np.argmax(np.abs(ratio[far] - 1))])
        return [f"calibration: scale factor k_{'xyz'[i]} = {s[i]:.5g} {nm}/g is "
                f"{ratio[i] - 1:+.0%} from {expected:.5g} {nm}/g, what readings in {nm} "
                f"({source}) have within a triad's tolerance of a few %: converted with the "
                "wrong range or factor?"]
    return []


def _volts_check(s: np.ndarray, source: str, units_as: str) -> list[str]:
    """A warning when scale factors ``s`` [V/g] leave :data:`V_PER_G_RANGE` (``source``: where
    the unit V came from; ``units_as``: the key or flag that declares it)."""
    lo, hi = V_PER_G_RANGE
    if np.all((s >= lo) & (s <= hi)):
        return []
    mags = ", ".join(f"{v:.4g}" for v in s)
    return [f"calibration: scale factors {mags} V/g ({source}) are outside {lo:g}–{hi:g} V/g, "
            "what any accelerometer read in volts has (its readings span ±k over the poses): "
            f"are the readings counts or another unit? Declare it ({_give(units_as, 'counts')}"
            ", or g, m/s2); the numbers are right in the readings' own unit"]
