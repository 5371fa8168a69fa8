"""The document ``align calibrate --json`` writes: the calibration's JSON in its envelope
(format, version, provenance), with the data's output unit, the static intervals found and
the check poses."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from align.calibration.check import CheckResult
from align.calibration.pipeline import Calibration
from align.calibration.static import StaticInterval
from align.calibration.triad import Poses, delta_g
from align.contract import document
from axisbase.header import OUTPUT_UNITS

SCALE_KEYS = {"V": "scale_factors_v_per_g", "counts": "scale_factors_counts_per_g",
              "m/s2": "scale_factors_m_s2_per_g", "g": "scale_factors_g_per_g"}
"""The JSON key of the scale factors for each output unit."""


def with_units(js: dict, units: str) -> dict:
    """Add the data's output unit to a calibration's JSON (and to its ``model`` block, which
    ``align tilt``/``apply`` check readings against). The historical key names
    ``scale_factors_v_per_g``/``k_v_per_g`` are kept; their unit is ``scale_factor_unit``."""
    js = dict(js, output_unit=units, scale_factor_unit=OUTPUT_UNITS[units])
    # The scale factors also under a key named after their unit (volts keep the old key).
    key = SCALE_KEYS[units]
    if key not in js and "scale_factors_v_per_g" in js:
        js[key] = js["scale_factors_v_per_g"]
        js[key.replace("_per_g", "_u_per_g")] = js.get("scale_factors_u_v_per_g")
    if "model" in js:
        js["model"] = dict(js["model"], output_unit=units)
    return js


def calibration_document(cal: Calibration, poses: Poses, units: str,
                         intervals: Sequence[StaticInterval] | None, check: Poses | None,
                         warnings: Sequence[str], settings: dict,
                         inputs: Iterable[str | Path], checked: CheckResult | None = None
                         ) -> dict:
    """The document; ``checked``: the check poses judged (:mod:`align.calibration.check`):
    their dg, u, z, and ``ok: false`` when they disagree with 1 g."""
    js = with_units(cal.to_dict(poses), units)
    if intervals is not None:
        js["static_intervals"] = [{"start_s": iv.start_s, "end_s": iv.end_s,
                                   "samples": iv.samples, "mean": iv.mean.tolist(),
                                   "std": iv.std.tolist(),
                                   "left_out_s": [list(g) for g in iv.left_out]}
                                  for iv in intervals]
    if checked is not None:
        js["check"] = checked.to_list()
    elif check is not None:
        js["check"] = [{"pose": lab, "dg_g": float(d)} for lab, d in
                       zip(check.labels, delta_g(cal.model, check), strict=True)]
    problems = [*cal.problems, *(() if checked is None else checked.warnings)]
    body = {"ok": not problems, "problems": problems, "warnings": list(warnings), **js}
    return document("calibration", body, settings, inputs)
