"""A calibration from files: the unit of the input files (the static file, or
``--units``/``units``, sets it; a check file's header must agree with it, not set it), then
the poses read, the triad calibrated and the check poses judged."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from align.calibration import STATIC, StaticSettings, calibrate, read_poses
from align.calibration.check import CheckResult, check_poses
from align.calibration.stability import chosen_ppm
from align.calibration.units import unit_scale_check
from align.calibration.units import unit_source as default_source
from align.warnings import calibration_warnings
from axisbase.console import captured_warnings
from axisbase.header import header_units, resolve_units
from axisbase.units import DEG

_U = ("ux", "uy", "uz")
ARRAY_SUFFIXES = (".mat", ".npz")
"""Files of named arrays: no header to carry a unit (the flag, else V, says it)."""


def calibration_units(static: str | Path, check: str | Path | None, given: str | None,
                      columns: Mapping[str, str] | None = None, flag: str = "--units") -> str:
    """The output unit of a calibration's readings.

    Parameters
    ----------
    static, check : paths of the static-pose file and of the check poses (or None).
    given : the unit the user stated (``flag``), or None.
    columns : the user's header names for the format's columns.

    Returns
    -------
    The unit (a key of :data:`axisbase.header.OUTPUT_UNITS`): ``given``, else the static
    file's header unit, else V. Raises :class:`~axisbase.errors.InputError` when a header
    disagrees (naming the file and what said otherwise)."""
    def has_header(p: str | Path | None) -> bool:
        return p is not None and Path(p).suffix.lower() not in ARRAY_SUFFIXES

    units = resolve_units(given, [static] if has_header(static) else [], STATIC, columns, _U,
                          flag=flag)
    if has_header(check):
        said = f"{flag} {units}"
        if not given:
            known = has_header(static) and header_units(static, STATIC, columns, _U)
            said = f"{static} ({units}{'' if known else ', no unit in its header'})"
        resolve_units(units, [check], STATIC, columns, _U, flag=said)
    return units


@dataclass(frozen=True)
class CalibrationRun:
    """A calibration made from files.

    Attributes
    ----------
    cal : the :class:`~align.calibration.Calibration` (model in ``units`` per g).
    poses : the calibration's pose means (``Poses``, in ``units``).
    intervals : the static intervals found in a continuous recording [s] (None for a file
        of pose means).
    check : the check poses (None without a check file) and ``checked`` their verdict.
    units : the output unit of the readings (a key of ``OUTPUT_UNITS``).
    warnings : what the reader must be told (the loop, the unit, the check poses).
    """

    cal: object
    poses: object
    intervals: list | None
    check: object | None
    checked: CheckResult | None
    units: str
    warnings: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """The calibration is a measurement and the check poses (if any) agree with it."""
        return self.cal.ok and (self.checked is None or self.checked.ok)


def calibrate_files(static: str | Path, check: str | Path | None, units: str,
                    signs: tuple[float, float, float] | None, settings: StaticSettings,
                    columns: Mapping[str, str] | None = None, rate_hz: float | None = None,
                    alpha: float = 1e-3, fixture_error_rad: float = 0.5 * DEG,
                    unit_source: str | None = None,
                    adc_range: tuple[float, float] | None = None,
                    time_unit: str | None = None,
                    scale_stability_ppm: float | None = None,
                    nonlinearity_bound: tuple[float | None, float | None] | None = None
                    ) -> CalibrationRun:
    """Read the static poses (and check poses), calibrate the triad and judge the check.

    Parameters
    ----------
    static, check : the static-pose file (poses, or a recording cut into static intervals
        by ``settings``) and the check poses (or None).
    units : their unit (:func:`calibration_units`); ``unit_source`` says who declared it
        (default: the static file's header).
    signs : the scale factors' signs (an ellipsoid cannot tell them), or None: from
        labelled faces when the poses carry them, else +,+,+.
    columns, rate_hz, time_unit : see :func:`axisbase.table.read_table`.
    alpha : significance of the residual loop's tests and of the check.
    fixture_error_rad : placement error of the faces (known-pose method) [rad].
    adc_range : the ADC's rails (LO, HI) in ``units``, when declared: a pose at a rail is
        left out (warned) or refused (:func:`align.calibration.static.read_poses`).
    scale_stability_ppm : the scale factors' declared stability over the run [ppm], or None
        (the default of :func:`align.calibration.stability.chosen_ppm`).
    nonlinearity_bound : the declared bounds on K2 [1/g] and K3 [1/g²], or None
        (:mod:`align.calibration.nonlinearity`).
    """
    left_out: list[str] = []
    with captured_warnings() as logged:  # (how the files were read: into the JSON too)
        poses, intervals = read_poses(static, settings, columns=columns, rate_hz=rate_hz,
                                      adc_range=adc_range, warnings=left_out,
                                      time_unit=time_unit)
        chk = (read_poses(check, settings, calibration=False, columns=columns,
                          rate_hz=rate_hz, adc_range=adc_range, warnings=left_out,
                          time_unit=time_unit)[0]
               if check else None)
    ppm, default = chosen_ppm(scale_stability_ppm, poses.temp is not None)
    cal = calibrate(poses, signs, alpha=alpha, fixture_error_rad=fixture_error_rad,
                    scale_stability_ppm=ppm, stability_default=default,
                    nonlinearity_bound=nonlinearity_bound)
    if unit_source is None:
        known = (Path(static).suffix.lower() not in ARRAY_SUFFIXES
                 and header_units(static, STATIC, columns, _U) is not None)
        unit_source = default_source(str(static), units, known)
    warnings = unit_scale_check(cal.model, units, unit_source)
    checked = check_poses(cal, poses, chk, alpha, f"{check}") if chk is not None else None
    warnings = (list(dict.fromkeys(logged)) + left_out + calibration_warnings(cal, poses)
                + warnings
                + (list(checked.warnings) if checked is not None else []))
    return CalibrationRun(cal, poses, intervals, chk, checked, units, tuple(warnings))
