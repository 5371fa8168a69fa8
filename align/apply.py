"""The platform-frame calibration of a triad and its application to readings.

The triad model (seed paper, u = K R (a_c + b) with its effects) gives the per-axis calibrated
reading w = R a_c = |r_i| s_i . a_P; the fusion gives where the axes point on the platform,
the unit rows s_i of M. Hence the specific force in the platform frame

    a_P = M^-1 (w / |r|)            [g]

which is the seed paper's calibration placed in the platform frame (the limitation its
authors state, removed).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from align.calibration import TriadModel, r_matrix
from align.contract import check, document, read_json
from align.errors import InputError
from align.fusion import E_NAMES, axes_from, e_matrix
from align.session_json import LoadedSession
from align.tilt import calibrated_force, roll_pitch
from axisbase.covariance import cov_of
from axisbase.output import csv_text
from axisbase.provenance import Provenance


def not_ok_warning(made: str, what: str, problems: Sequence[str]) -> list[str]:
    """The one wording of "this calibration was not ok" for ``align apply`` and ``align
    tilt`` (empty when ``problems`` is)."""
    if not problems:
        return []
    return [f"calibration: {made} NOT OK (" + "; ".join(problems) + f"): {what} not a "
            "measurement to act on — the outputs are written, exit status 2"]


@dataclass(frozen=True)
class TriadCalibration:
    """A triad calibration (``align calibrate --json``) as ``align tilt`` uses it: the model
    and why the calibration was not ok (its own ``ok``/``problems``).

    Attributes
    ----------
    model : TriadModel
        The triad's calibration; unit — (its own fields carry units).
    not_ok : tuple of str
        The calibration's ``problems`` (empty: it was ok); ``align tilt`` warns with these and
        exits 2, as for a platform calibration from a not-ok session; unit —.
    """

    model: TriadModel
    not_ok: tuple[str, ...] = ()
    tilt_frame: ClassVar[str] = "triad"

    def not_ok_warning(self) -> list[str]:
        """The warning ``align tilt`` gives for a not-ok triad calibration (empty if ok)."""
        return not_ok_warning("the triad calibration was", "its roll and pitch are",
                              self.not_ok)

    def specific_force(self, u: np.ndarray, t: np.ndarray | float = 0.0,
                       temp: np.ndarray | float | None = None) -> np.ndarray:
        """Specific force in the triad's calibration frame (N, 3) [g] from outputs u (N, 3)."""
        return self.model.specific_force(u, t, temp)


def _triad_problems(d: dict) -> tuple[str, ...]:
    """Why a calibration document is not ok: its ``problems``; files written before that field
    existed give their "NOT OK" warnings, failing those all their warnings (or, with none,
    ``ok: false`` itself)."""
    if d.get("ok", True) is not False:
        return ()
    said = [str(w) for w in d.get("warnings", ())]
    problems = d.get("problems") or [w for w in said if "NOT OK" in w] or said
    return tuple(str(p) for p in problems) or ("the file says ok: false",)


@dataclass(frozen=True)
class PlatformCalibration:
    """Triad model plus the misalignment E and its covariance (what ``align apply`` needs).

    Attributes
    ----------
    model : TriadModel
        The triad's calibration; unit — (its own fields carry units).
    e6 : numpy.ndarray
        The six angles of E in ``E_NAMES`` order [rad].
    cov : numpy.ndarray
        Their 6×6 covariance [rad²].
    not_ok : tuple of str
        Why the session it came from was not ok (empty: it was); ``align apply`` and ``align
        tilt`` warn with these and exit 2 (docs/commands/apply.md); unit —.
    """

    model: TriadModel
    e6: np.ndarray
    cov: np.ndarray
    not_ok: tuple[str, ...] = ()

    tilt_frame: ClassVar[str] = "platform"

    def not_ok_warning(self) -> list[str]:
        """The warning ``align apply``/``tilt`` give for a calibration from a not-ok session
        (empty when it was ok)."""
        return not_ok_warning("made from a session that was", "its misalignment is", self.not_ok)

    @property
    def axes(self) -> np.ndarray:
        """Unit rows s_i of M: where accelerometer i points in the platform frame."""
        return axes_from(self.e6)

    def cov_of(self, *names: str) -> np.ndarray:
        """The covariance [rad²] of the named angles of E (``E_NAMES``) in the order given."""
        return cov_of(self.cov, E_NAMES, names)

    def to_dict(self, units: str | None = None) -> dict:
        """The calibration's body (``units``: the output unit of the readings it was made
        from, checked by ``align apply``)."""
        model = self.model.to_dict()
        if units is not None:
            model["output_unit"] = units
        return {"frame": "platform: X, Y horizontal, Z up; row i = accelerometer i",
                "model": model,
                "misalignment_rad": e_matrix(self.e6).tolist(),
                "misalignment_u_rad": e_matrix(np.sqrt(np.diag(self.cov))).tolist(),
                "angle_names": list(E_NAMES), "angles_rad": self.e6.tolist(),
                "angles_covariance_rad2": self.cov.tolist(),
                "axes": self.axes.tolist(),
                "source_ok": not self.not_ok, "source_problems": list(self.not_ok)}

    def document(self, units: str | None, settings: dict, inputs,
                 prov: Provenance | None = None) -> dict:
        """The file ``align run --calibration`` writes (format, version, provenance)."""
        return document("platform-calibration", self.to_dict(units), settings, inputs, prov)

    @classmethod
    def from_dict(cls, d: dict, where: str) -> PlatformCalibration:
        """Read a platform calibration — the file itself or a session result holding one —
        of any format version this tool reads (version 1: the files written before
        versions existed); ``InputError`` says which versions it cannot."""
        d = _block(d, where)
        try:
            model = TriadModel.from_dict(d["model"], where)
            e6 = np.array(d["angles_rad"], float).reshape(6)
            cov = np.array(d["angles_covariance_rad2"], float).reshape(6, 6)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: not a platform calibration ({exc!s}); expected the "
                             "JSON that 'align run --json' or '--calibration' writes") from None
        return cls(model, e6, cov, tuple(str(p) for p in d.get("source_problems", ())))

    @classmethod
    def load(cls, path: str | Path) -> PlatformCalibration:
        return cls.load_with_units(path)[0]

    @classmethod
    def load_with_units(cls, path: str | Path) -> tuple[PlatformCalibration, str | None]:
        """The calibration and the output unit of the readings it was made from (None for
        files that do not say)."""
        block = _block(read_json(path, "a platform calibration"), str(path))
        return cls.from_dict(block, str(path)), _output_unit(block)

    def specific_force(self, u: np.ndarray, t: np.ndarray | float = 0.0,
                       temp: np.ndarray | float | None = None) -> np.ndarray:
        """Specific force in the platform frame (N, 3) [g] from outputs u (N, 3)."""
        m = self.model
        R = r_matrix(m.beta)
        w = m.specific_force(u, t, temp) @ R.T
        w = w / np.linalg.norm(R, axis=1)
        return np.linalg.solve(self.axes, w.T).T


def _is_session(d: dict) -> bool:
    """A session result (any version: version 1 has no ``format``), not a calibration file."""
    return ("platform_calibration" in d or d.get("format") == "axis-align/session"
            or "misalignment_rad" in d and "model" not in d)


def _block(d: dict, where: str) -> dict:
    """The platform calibration's block: the file itself (its format checked) or a session
    result's, read by the one reader of session results (:class:`LoadedSession`)."""
    if not _is_session(d):
        check(d, "platform-calibration", where)
        return d
    block = LoadedSession.from_dict(d, where).platform_calibration
    if block is None:
        raise InputError(f"{where}: a session result without a platform calibration "
                         "(the session had no [calibration] or its fusion failed)")
    return dict(block)


def _output_unit(block: dict) -> str | None:
    model = block.get("model")
    return model.get("output_unit", block.get("output_unit")) if isinstance(model, dict) \
        else block.get("output_unit")


def load_triad_model(path: str | Path) -> tuple[TriadModel, str | None]:
    """The triad model of a calibration file (``align calibrate --json``, any readable format
    version, or a bare model block) and the output unit it was made from (None if unknown)."""
    cal, units = load_triad_calibration(path)
    return cal.model, units


def load_triad_calibration(path: str | Path) -> tuple[TriadCalibration, str | None]:
    """:func:`load_triad_model` with the calibration's not-ok reasons
    (:class:`TriadCalibration`)."""
    d = read_json(path, "a calibration")
    fmt = d.get("format")
    if _is_session(d):  # a session result: its triad model
        d = _block(d, str(path))
    elif fmt == "axis-align/platform-calibration":
        check(d, "platform-calibration", str(path))
    elif "model" in d:
        check(d, "calibration", str(path))
    block = d.get("model", d)
    if not isinstance(block, dict):
        raise InputError(f"{path}: 'model' is not a table")
    return (TriadCalibration(TriadModel.from_dict(block, str(path)), _triad_problems(d)),
            block.get("output_unit", d.get("output_unit")))


def load_tilt_calibration(path: str | Path) -> tuple[TriadCalibration | PlatformCalibration,
                                                      str | None]:
    """What ``align tilt --calibration`` reads: a platform calibration or a session result
    holding one -> that ``PlatformCalibration`` (roll and pitch of the platform, its
    misalignment applied, exactly as ``align apply --tilt``); a triad calibration (``align
    calibrate --json``) -> a ``TriadCalibration`` (the triad's own frame: no misalignment
    known; not ok when the calibration was not).
    With the output unit of the readings it was made from (None if the file does not say)."""
    d = read_json(path, "a calibration")
    if (_is_session(d) or d.get("format") == "axis-align/platform-calibration"
            or "misalignment_rad" in d):
        block = _block(d, str(path))  # read once: the body is a version-1 calibration
        return PlatformCalibration.from_dict(block, str(path)), _output_unit(block)
    return load_triad_calibration(path)


@dataclass(frozen=True)
class AppliedReadings:
    """Readings through a platform calibration: times [s] (None when the readings had none),
    specific force in the platform frame (N, 3) [g], roll/pitch [rad] when asked, and what
    the reader must know (a drift model taken at its reference time)."""

    t: np.ndarray | None
    a: np.ndarray
    roll: np.ndarray | None = None
    pitch: np.ndarray | None = None
    warnings: tuple[str, ...] = ()

    @property
    def samples(self) -> int:
        return len(self.a)

    @property
    def mean_g(self) -> np.ndarray:
        return self.a.mean(0)

    def csv_text(self) -> str:
        """``t,ax_g,ay_g,az_g[,roll_deg,pitch_deg]``; t blank when the readings had none."""

        cols, names = [self.t, *self.a.T], ["t", "ax_g", "ay_g", "az_g"]
        if self.roll is not None:
            cols += [np.rad2deg(self.roll), np.rad2deg(self.pitch)]
            names += ["roll_deg", "pitch_deg"]
        return csv_text(names, cols, exact=("t",))


def apply_to_readings(pc: PlatformCalibration, tab, tilt: bool = False,
                      method: str = "exact") -> AppliedReadings:
    """Readings ``tab`` (ux, uy, uz[, t][, temp]) -> specific force in the platform frame.
    Readings without times keep none; a drift of the model is then taken at its reference
    time, and a warning says so (likewise a temperature)."""

    t, a, warnings = calibrated_force(pc, tab)
    warnings = tuple(warnings)
    if not tilt:
        return AppliedReadings(t, a, warnings=warnings)
    roll, pitch = roll_pitch(a, method=method)
    return AppliedReadings(t, a, roll, pitch, warnings)
