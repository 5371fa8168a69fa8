"""``session.toml``: what a session holds, read and checked before anything runs.

Every problem is reported with the key that causes it (``InputError``), e.g.
``session.toml: [[images]] #3 housing = 'w': not one of x, y, z``. Paths are relative to the
session folder. The format is documented with a complete example in README.md.
"""

from __future__ import annotations

import datetime as _dt
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from align.calibration.nonlinearity import session_bounds
from align.calibration.stability import KEY as STABILITY_KEY
from align.calibration.stability import stability_ppm
from align.calibration.static import SESSION_KEYS, StaticSettings, session_names
from align.decision import ToleranceSpec
from align.errors import InputError
from align.face_plan import check_face_plan
from align.fusion.observations import REF, ROLL, TILT
from align.lens import LensRanges
from align.lens_design import RANGE_KEYS, replaced_by_model
from axisbase.header import OUTPUT_UNITS, parse_column_map
from axisbase.provenance import sha256_file
from axisbase.units import ARCSEC, DECLARED_TIME_UNITS, DEG
from imaging import ImageInputError, check_roi

HOUSINGS = ("x", "y", "z")
AXIS = {"X": 0, "Y": 1, "Z": 2}
TOP_KEYS = {"latitude_deg", "calibration", "goniometer", "cameras", "views", "images",
            "platform", "name", "latitude_range_deg", "metadata", "tolerance"}


def signed_axis(text: object, where: str) -> np.ndarray:
    """'+X', '-Z', 'Y' -> unit vector in the platform frame."""
    t = str(text).strip().upper()
    sign = -1.0 if t.startswith("-") else 1.0
    ax = t.lstrip("+-")
    if ax not in AXIS:
        raise InputError(f"{where} = {text!r}: expected a signed platform axis such as +X, -Y, +Z")
    v = np.zeros(3)
    v[AXIS[ax]] = sign
    return v


@dataclass(frozen=True)
class ImageEntry:
    file: Path
    housing: str
    view: str
    nominal: str  # "horizontal" | "vertical"
    key: str
    roi: tuple[int, int, int, int] | None = None  # (x, y, w, h) [px]: search only there


@dataclass(frozen=True)
class View:
    name: str
    camera: str
    right: np.ndarray
    up: np.ndarray


@dataclass(frozen=True)
class Camera:
    name: str
    model: Path | None = None
    roll_rad: float = 0.0
    lens: LensRanges | None = None
    blur_after_pixels: bool = False
    roll_u_rad: float | None = None  # roll_u_arcsec: its plausible range's σ [rad]


@dataclass(frozen=True)
class Goniometer:
    log: Path
    faces: tuple[str, ...]
    nominal_rad: np.ndarray
    direction: int
    reference_offset_rad: float = 0.0
    reverse_log: Path | None = None
    steady_table: bool = False
    columns: dict[str, str] = field(default_factory=dict)
    time_unit: str | None = None  # the t column's unit when its header says none
    reference_offset_u_rad: float | None = None  # reference_offset_u_arcsec: σ [rad]
    latency_max_s: float | None = None  # latency_max_us: the autocollimator's bound [s]
    counters_sound: bool = False  # counters_sound: the counters verified (no counts lost)


@dataclass(frozen=True)
class TableKeys:
    """How a table file is read (keys ``columns``, ``units``, ``rate_hz``, ``time_unit``; the
    CLI's ``--columns``, ``--units``, ``--rate``, ``--time-unit``)."""

    columns: dict[str, str] = field(default_factory=dict)
    units: str | None = None
    rate_hz: float | None = None
    time_unit: str | None = None  # the time column's unit when its header says none


@dataclass(frozen=True)
class CalibrationInput:
    static: Path
    scale_sign: tuple[float, float, float] | None  # None: from labelled faces, else +
    check: Path | None = None
    table: TableKeys = field(default_factory=TableKeys)
    adc_range: tuple[float, float] | None = None  # the ADC's rails [output units]
    scale_stability_ppm: float | None = None  # declared; None: the default (stability.py)
    nonlinearity_bound: tuple[float | None, float | None] | None = None  # K2 [1/g], K3 [1/g²]
    detection: StaticSettings = field(
        default_factory=lambda: StaticSettings(names=session_names("[calibration]")))
    """Static detection of a continuous recording (keys ``window_s``, ``threshold``,
    ``min_static_s``, ``margin_s``, ``split_sigma``, ``split_deg``: ``align calibrate``'s
    ``--window`` ...), checked by the rules the command line uses."""


@dataclass(frozen=True)
class PlatformInput:
    static: Path
    poses: dict[str, tuple[np.ndarray, float]]  # label -> (up vector, table angle [rad])
    table_tilt_rad: np.ndarray = field(default_factory=lambda: np.zeros(2))
    table: TableKeys = field(default_factory=TableKeys)


@dataclass(frozen=True)
class Session:
    folder: Path
    name: str
    latitude_rad: float | None  # session.toml latitude_deg, converted [rad]
    calibration: CalibrationInput | None
    goniometer: Goniometer | None
    cameras: dict[str, Camera]
    views: dict[str, View]
    images: tuple[ImageEntry, ...]
    platform: PlatformInput | None
    latitude_range_rad: tuple[float, float] | None = None  # latitude_range_deg [rad]
    metadata: dict[str, str | int | float | bool] = field(default_factory=dict)
    """``[metadata]``: free keys about the unit and the set-up (unit, serial, operator,
    camera, table, date, ...), carried into the result for 'align lot'."""
    tolerance: ToleranceSpec | None = None
    """``[tolerance]``: the specification of E and the decision rule (:mod:`align.decision`);
    None when the session gives none."""

    def declared_setup(self) -> dict[str, np.ndarray]:
        """What session.toml declares of the set-up the fusion's loop can find more of, by
        the fusion's effect name [rad]: each camera's roll (``camera_roll[A]``), the
        reference face's offset, the table's tilt (x, y). The loop finds an increment on it."""
        out = {f"{ROLL}[{n}]": np.array([c.roll_rad]) for n, c in self.cameras.items()}
        if self.goniometer is not None:
            out[REF] = np.array([self.goniometer.reference_offset_rad])
        if self.platform is not None:
            out[TILT] = np.asarray(self.platform.table_tilt_rad, float)
        return out

    def plausible_u(self) -> dict[str, float]:
        """The declared standard uncertainty [rad] of a nuisance's plausible range, by the
        fusion's effect name (``roll_u_arcsec``, ``reference_offset_u_arcsec``): carried in
        E's u where the data cannot determine the nuisance (:mod:`align.fusion.undetermined`;
        not declared: its default range)."""
        out = {f"{ROLL}[{n}]": c.roll_u_rad for n, c in self.cameras.items()
               if c.roll_u_rad is not None}
        if self.goniometer is not None and self.goniometer.reference_offset_u_rad is not None:
            out[REF] = self.goniometer.reference_offset_u_rad
        return out

    @property
    def inputs(self) -> list[Path]:
        """Every file the session names (outputs must never be one of them)."""
        out = [self.folder / "session.toml", *(i.file for i in self.images)]
        if self.calibration:
            out += [self.calibration.static] + ([self.calibration.check]
                                                if self.calibration.check else [])
        if self.goniometer:
            out.append(self.goniometer.log)
            if self.goniometer.reverse_log:
                out.append(self.goniometer.reverse_log)
        if self.platform:
            out.append(self.platform.static)
        out += [c.model for c in self.cameras.values() if c.model is not None]
        return out


class _Files:
    """Every path session.toml names: it must exist and — symlinks followed — lie inside the
    session folder unless ``allow_outside``; no file may be named twice."""

    def __init__(self, folder: Path, allow_outside: bool):
        self.folder = folder
        self.root = folder.resolve()
        self.allow_outside = allow_outside
        self.seen: dict[Path, str] = {}

    def __call__(self, value: object, where: str, unique: bool = True) -> Path:
        if not isinstance(value, str) or not value.strip():
            raise InputError(f"{where}: expected a file name")
        p = self.folder / value
        real = p.resolve()
        if not self.allow_outside and not real.is_relative_to(self.root):
            raise InputError(f"{where} = {value!r}: outside the session folder (a session "
                             "names its own files only; 'align run --allow-outside' lifts it)")
        if not p.is_file():
            raise InputError(f"{where} = {value!r}: no such file" if not p.exists() else
                             f"{where} = {value!r}: not a file")
        if not unique:
            return p
        if real in self.seen:
            raise InputError(f"{where} = {value!r}: the same file as {self.seen[real]}")
        self.seen[real] = where.split(": ", 1)[-1]
        return p


def _same_contents(a: Path, b: Path) -> bool:
    """Byte-identical files (size first, then streamed hashes: logs can be gigabytes)."""

    return a.stat().st_size == b.stat().st_size and sha256_file(a) == sha256_file(b)


def _adc_range(value: object, where: str) -> tuple[float, float] | None:
    """``adc_range = [LO, HI]``: the ADC's rails in the readings' unit (None when absent)."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 2:
        raise InputError(f"{where} = {value!r}: expected [LO, HI] in the readings' unit")
    lo, hi = (_number(v, where) for v in value)
    if not lo < hi:
        raise InputError(f"{where} = {value!r}: need LO < HI")
    return lo, hi


def _number(value: object, where: str, lo: float | None = None, hi: float | None = None,
            open_lo: bool = False) -> float:
    """A finite number in [lo, hi] (lo excluded with ``open_lo``)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} = {value!r}: expected a number")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{where} = {value!r}: not a finite number")
    if (lo is not None and (v <= lo if open_lo else v < lo)) or (hi is not None and v > hi):
        raise InputError(f"{where} = {value!r}: outside {'(' if open_lo else '['}"
                         f"{'-inf' if lo is None else f'{lo:g}'}, "
                         f"{'inf' if hi is None else f'{hi:g}'}]")
    return v


def _u_arcsec(table: dict, key: str, where: str, hi: float) -> float | None:
    """A declared standard uncertainty ``key`` [″] (> 0, at most ``hi``) in [rad], or None."""
    if key not in table:
        return None
    return _number(table[key], f"{where} {key}", 0.0, hi, open_lo=True) * ARCSEC


DETECTION_KEYS = {v for k, v in SESSION_KEYS.items() if k not in ("rate_hz", "columns")}
"""The static-detection keys of ``[calibration]`` (:data:`align.calibration.SESSION_KEYS`)."""


def _detection(c: dict, src: str) -> StaticSettings:
    """``[calibration]``'s static-detection keys through the rules ``align calibrate``'s
    flags go through (:meth:`StaticSettings.given`), named as keys."""
    names = session_names("[calibration]")
    values = {k: c[v] for k, v in SESSION_KEYS.items() if v in DETECTION_KEYS and v in c}
    try:
        return StaticSettings.given(names, **values)
    except InputError as exc:
        raise InputError(f"{src}{exc}") from None


def _table_keys(t: dict, where: str, rate: bool = True, units: bool = True,
                time_unit: bool | None = None) -> TableKeys:
    """The table keys of ``t``, checked (``time_unit``: whether the key applies; default
    ``rate``, as the command line's :func:`align.commands.parents.tables`)."""
    cols = t.get("columns")
    if cols is not None and not isinstance(cols, str | dict):
        raise InputError(f"{where} columns: expected \"ux=ax,uy=ay,uz=az\" or a table")
    if isinstance(cols, dict):
        cols = ",".join(f"{k}={v}" for k, v in cols.items())
    mapping = parse_column_map(cols, f"{where} columns")
    u = t.get("units")
    if units and u is not None and u not in OUTPUT_UNITS:
        raise InputError(f"{where} units = {u!r}: one of {', '.join(OUTPUT_UNITS)}")
    r = (_number(t["rate_hz"], f"{where} rate_hz", 0, 1e7, open_lo=True)
         if rate and "rate_hz" in t else None)
    tu = t.get("time_unit") if (rate if time_unit is None else time_unit) else None
    if tu is not None and tu not in DECLARED_TIME_UNITS:
        raise InputError(f"{where} time_unit = {tu!r}: one of "
                         f"{', '.join(DECLARED_TIME_UNITS)}")
    return TableKeys(mapping, u, r, tu)


# Physical ranges of the angles a session may declare: a known roll, offset or tilt is a
# small correction; a value beyond these is a typing error (1e308), not a setting.
MAX_ROLL_ARCSEC = 36000.0       # 10°
MAX_OFFSET_ARCSEC = 36000.0     # 10°
MAX_TILT_ARCSEC = 3600.0        # 1°


KEYS = {
    "calibration": {"static", "scale_sign", "check", "columns", "units", "rate_hz", "time_unit",
                    "adc_range", "scale_stability_ppm", "k2_bound_ug_per_g2",
                    "k3_bound_ug_per_g3", *DETECTION_KEYS},
    "goniometer": {"log", "faces", "nominal_deg", "direction", "reference_offset_arcsec",
                   "reference_offset_u_arcsec", "reverse_log", "steady_table", "columns",
                   "time_unit", "latency_max_us", "counters_sound"},
    "cameras": {"model", "roll_arcsec", "roll_u_arcsec", "blur_after_pixels",
                *(f"lens_{k}" for k in RANGE_KEYS)},
    "views": {"camera", "right", "up"},
    "images": {"file", "housing", "view", "nominal", "roi"},
    "platform": {"static", "table_tilt_arcsec", "poses", "columns", "units", "rate_hz",
                 "time_unit"},
}


def _known(table: object, kind: str, where: str) -> dict:
    """The table, checked: a table at all, and no misspelt key (it would be silently ignored)."""
    if not isinstance(table, dict):
        raise InputError(f"{where}: expected a table")
    unknown = set(table) - KEYS[kind]
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; known: "
                         f"{', '.join(sorted(KEYS[kind]))}")
    return table


def _table(d: dict, key: str, where: str) -> dict:
    v = d.get(key, {})
    if not isinstance(v, dict):
        raise InputError(f"{where}[{key}]: expected a table")
    return v


def _metadata(d: dict, src: str) -> dict[str, str | int | float | bool]:
    """``[metadata]``: free keys whose values are texts, numbers, true/false or TOML dates
    (kept as ISO 8601 text, so the result JSON can carry them)."""
    m = d.get("metadata", {})
    if not isinstance(m, dict):
        raise InputError(f"{src}: metadata: expected a [metadata] table of key = value")
    out: dict[str, str | int | float | bool] = {}
    for k, v in m.items():
        if isinstance(v, _dt.date | _dt.time):  # datetime is a date
            v = v.isoformat()
        elif isinstance(v, float) and not math.isfinite(v):
            raise InputError(f"{src}: [metadata] {k} = {v!r}: not a finite number")
        elif not isinstance(v, str | int | float | bool):
            raise InputError(f"{src}: [metadata] {k}: expected a text, number, true/false or "
                             "date, not a table or a list")
        out[str(k)] = v
    return out


def load_session(folder: str | Path, allow_outside: bool = False) -> Session:
    """Read and check ``folder/session.toml``.

    Every file it names must lie inside the session folder (symlinks followed) unless
    ``allow_outside``; no file may be named twice.

    Parameters
    ----------
    folder : str or Path
        The session folder (or its session.toml).
    allow_outside : bool
        Allow files outside the folder.

    Returns
    -------
    Session
        The checked settings, stages and files.

    Raises
    ------
    InputError
        Naming the key at fault (``session.toml: [[images]] #3 housing = 'w': ...``).
    """
    folder = Path(folder)
    path = folder / "session.toml" if folder.is_dir() else folder
    if folder.is_file():
        folder = folder.parent
    src = f"{path}"
    if not path.is_file():
        raise InputError(f"{src}: no such file (a session is a folder with a session.toml)")
    try:
        # utf-8-sig: a byte-order mark (Windows editors) is not part of the TOML.
        d = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{src}: not valid TOML ({exc})") from None
    except UnicodeDecodeError:
        raise InputError(f"{src}: not UTF-8 text (TOML is UTF-8)") from None
    _file = _Files(folder, allow_outside)
    unknown = set(d) - TOP_KEYS
    if unknown:
        raise InputError(f"{src}: unknown key(s) {', '.join(sorted(unknown))}; known: "
                         f"{', '.join(sorted(TOP_KEYS))}")
    lat = d.get("latitude_deg")
    if lat is not None:
        lat = _number(lat, f"{src}: latitude_deg", -90, 90)
    lat_range = d.get("latitude_range_deg")
    if lat_range is not None:
        w = f"{src}: latitude_range_deg"
        if not isinstance(lat_range, list) or len(lat_range) != 2:
            raise InputError(f"{w} = {lat_range!r}: expected [LO, HI] in degrees")
        lat_range = tuple(_number(v, w, -90, 90) for v in lat_range)
        if lat_range[0] > lat_range[1] or lat is not None:
            raise InputError(f"{w} = {list(lat_range)}: need LO <= HI, and no latitude_deg")

    cal = None
    if "calibration" in d:
        c = _table(d, "calibration", src + ": ")
        _known(c, "calibration", f"{src}: [calibration]")
        sign = str(c.get("scale_sign", "+"))
        parts = [p.strip() for p in sign.split(",")] if "," in sign else [sign.strip()] * 3
        if len(parts) != 3 or any(p not in ("+", "-") for p in parts):
            raise InputError(f"{src}: [calibration] scale_sign = {sign!r}: use +, - or "
                             "three of them, e.g. \"-,-,-\"")
        cal = CalibrationInput(
            _file(c.get("static"), f"{src}: [calibration] static"),
            tuple(-1.0 if p == "-" else 1.0 for p in parts)  # type: ignore[arg-type]
            if "scale_sign" in c else None,
            _file(c["check"], f"{src}: [calibration] check") if "check" in c else None,
            _table_keys(c, f"{src}: [calibration]"),
            _adc_range(c.get("adc_range"), f"{src}: [calibration] adc_range"),
            (stability_ppm(c["scale_stability_ppm"], f"{src}: {STABILITY_KEY}")
             if "scale_stability_ppm" in c else None),
            session_bounds(c, f"{src}: "),
            _detection(c, f"{src}: "))

    gon = None
    if "goniometer" in d:
        g = _table(d, "goniometer", src + ": ")
        w = f"{src}: [goniometer]"
        _known(g, "goniometer", w)
        faces = g.get("faces")
        if not isinstance(faces, list) or len(faces) < 2 or not all(
                isinstance(f, str) for f in faces):
            raise InputError(f"{w} faces: expected a list of face names in passing order, the "
                             "first being the reference face, e.g. [\"ref\", \"y\", \"x\", \"z\"]")
        if any(not f.strip() for f in faces):
            raise InputError(f"{w} faces = {faces}: an empty face name")
        if len(set(faces)) != len(faces):
            raise InputError(f"{w} faces = {faces}: a face is named twice")
        nom = g.get("nominal_deg", [360.0 / len(faces)] * len(faces))
        if not isinstance(nom, list) or len(nom) != len(faces):
            raise InputError(f"{w} nominal_deg: expected {len(faces)} angles, one per face")
        nom_r = np.deg2rad([_number(v, f"{w} nominal_deg", 0, 360, open_lo=True)
                            for v in nom])
        if abs(np.rad2deg(nom_r.sum()) - 360) > 1e-6:
            raise InputError(f"{w} nominal_deg = {nom}: the angles of a full turn must sum to "
                             "360")
        check_face_plan(faces, nom_r, f"{w} faces", f"{w} nominal_deg = {nom}")
        direction = g.get("direction", "ccw")
        if direction not in ("ccw", "cw"):
            raise InputError(f"{w} direction = {direction!r}: ccw or cw")
        dsign = 1 if direction == "ccw" else -1
        for k in ("steady_table", "counters_sound"):
            if not isinstance(g.get(k, False), bool):
                raise InputError(f"{w} {k} = {g[k]!r}: true or false")
        log_path = _file(g.get("log"), f"{w} log")
        rev_path = _file(g["reverse_log"], f"{w} reverse_log") if "reverse_log" in g else None
        if rev_path is not None and _same_contents(rev_path, log_path):
            raise InputError(f"{w} reverse_log = {g['reverse_log']!r}: the same contents as "
                             "log; the other direction is a different recording")
        keys = _table_keys(g, w, rate=False, units=False, time_unit=True)
        gon = Goniometer(log_path, tuple(faces), nom_r, dsign,
                         _number(g.get("reference_offset_arcsec", 0.0),
                                 f"{w} reference_offset_arcsec", -MAX_OFFSET_ARCSEC,
                                 MAX_OFFSET_ARCSEC) * ARCSEC,
                         rev_path, g.get("steady_table", False), keys.columns, keys.time_unit,
                         _u_arcsec(g, "reference_offset_u_arcsec", w, MAX_OFFSET_ARCSEC),
                         None if "latency_max_us" not in g else
                         _number(g["latency_max_us"], f"{w} latency_max_us", 0.0) * 1e-6,
                         g.get("counters_sound", False))

    cameras = {}
    for name, c in _table(d, "cameras", src + ": ").items():
        w = f"{src}: [cameras.{name}]"
        _known(c, "cameras", w)
        # Two cameras may share a model file (one calibration of a camera type).
        model = _file(c["model"], f"{w} model", unique=False) if "model" in c else None
        # The plausible lens when no model is given (Type B ranges, issue 18).
        lens = {k: _number(c[f"lens_{k}"], f"{w} lens_{k}", 0.0,
                           None) for k in RANGE_KEYS if f"lens_{k}" in c}
        beside = replaced_by_model(lens) if model is not None else []
        if beside:  # silently ignored otherwise: the model is the lens
            raise InputError(f"{w} model = {c['model']!r} and "
                             f"{', '.join(f'lens_{k}' for k in beside)} both given: a camera "
                             "model is the lens (its u is carried), lens_ ranges are for a "
                             "camera without one (lens_max_u_arcsec applies to both); remove "
                             "one of them")
        if lens.get("max_u_arcsec") == 0:
            raise InputError(f"{w} lens_max_u_arcsec = 0: must be > 0")
        after = c.get("blur_after_pixels", False)
        if not isinstance(after, bool):
            raise InputError(f"{w} blur_after_pixels = {after!r}: true or false")
        cameras[name] = Camera(name, model,
                               _number(c.get("roll_arcsec", 0.0), f"{w} roll_arcsec",
                                       -MAX_ROLL_ARCSEC, MAX_ROLL_ARCSEC) * ARCSEC,
                               LensRanges.of(lens) if lens else None, after,
                               _u_arcsec(c, "roll_u_arcsec", w, MAX_ROLL_ARCSEC))

    views = {}
    for name, v in _table(d, "views", src + ": ").items():
        w = f"{src}: [views.{name}]"
        _known(v, "views", w)
        right = signed_axis(v.get("right"), f"{w} right")
        up = signed_axis(v.get("up"), f"{w} up")
        if abs(right @ up) > 0:
            raise InputError(f"{w}: right = {v.get('right')!r} and up = {v.get('up')!r} are "
                             "the same axis; they must be perpendicular")
        cam = v.get("camera", name)
        # A view naming no declared camera is refused, never given a camera of its own: a
        # typo (camera = "C" for "A") would split a view from its reversal, and the roll of
        # the real camera would silently not reach it.
        if not isinstance(cam, str) or cam not in cameras:
            said = f"camera = {cam!r}" if "camera" in v else f"no camera key (default {cam!r})"
            raise InputError(f"{w} {said}: no [cameras.{cam}] table (known: "
                             f"{', '.join(cameras) or 'none'})")
        views[name] = View(name, cam, right, up)

    imgs = []
    raw = d.get("images", [])
    if not isinstance(raw, list):
        raise InputError(f"{src}: images: expected [[images]] entries")
    for k, im in enumerate(raw, start=1):
        w = f"{src}: [[images]] #{k}"
        _known(im, "images", w)
        housing = im.get("housing")
        if housing not in HOUSINGS:
            raise InputError(f"{w} housing = {housing!r}: not one of x, y, z")
        view = im.get("view")
        if view not in views:
            raise InputError(f"{w} view = {view!r}: no [views.{view}] table (known: "
                             f"{', '.join(views) or 'none'})")
        nominal = im.get("nominal")
        if nominal not in ("horizontal", "vertical"):
            raise InputError(f"{w} nominal = {nominal!r}: horizontal or vertical")
        e = np.eye(3)[HOUSINGS.index(housing)]
        along = views[view].right if nominal == "horizontal" else views[view].up
        if abs(e @ along) != 1:
            axis = "XYZ"[HOUSINGS.index(housing)]
            raise InputError(
                f"{w}: housing {housing} is nominally along platform {axis}, but view {view} "
                f"has {nominal} = {'XYZ'[int(np.argmax(np.abs(along)))]} — contradictory "
                "nominal orientation")
        roi = None
        if "roi" in im:
            try:
                roi = check_roi(im["roi"], f"{w} roi")
            except ImageInputError as exc:
                raise InputError(str(exc)) from None
        imgs.append(ImageEntry(_file(im.get("file"), f"{w} file"), housing, view,
                               nominal, w, roi))

    plat = None
    if "platform" in d:
        p = _table(d, "platform", src + ": ")
        w = f"{src}: [platform]"
        _known(p, "platform", w)
        poses = {}
        for label, spec in _table(p, "poses", w).items():
            if not isinstance(spec, dict) or "up" not in spec:
                raise InputError(f"{w}.poses {label}: expected {{ up = \"+Z\", table_deg = 0 }}")
            unknown = set(spec) - {"up", "table_deg"}
            if unknown:  # a misspelt table_deg would silently leave the pose at 0°
                raise InputError(f"{w}.poses {label}: unknown key(s) "
                                 f"{', '.join(sorted(unknown))}; known: table_deg, up")
            poses[str(label)] = (signed_axis(spec["up"], f"{w}.poses {label} up"),
                                 np.deg2rad(_number(spec.get("table_deg", 0.0),
                                                    f"{w}.poses {label} table_deg", -360, 360)))
        if not poses:
            raise InputError(f"{w}: no [platform.poses]: each pose label in the file needs its "
                             "attitude (up = \"+Z\", table_deg = ...)")
        tilt = p.get("table_tilt_arcsec", [0.0, 0.0])
        if not isinstance(tilt, list) or len(tilt) != 2:
            raise InputError(f"{w} table_tilt_arcsec: expected [tx, ty]")
        plat = PlatformInput(_file(p.get("static"), f"{w} static"), poses,
                             np.array([_number(t, f"{w} table_tilt_arcsec", -MAX_TILT_ARCSEC,
                                               MAX_TILT_ARCSEC) for t in tilt]) * ARCSEC,
                             _table_keys(p, w))
        if cal is None:
            raise InputError(f"{w}: platform static readings need the triad's calibration "
                             "([calibration] static = ...) for scale factors and biases")
        cu, pu = cal.table.units, plat.table.units
        if cu is not None and pu is not None and cu != pu:
            raise InputError(f"{w} units = {pu!r}: the calibration's readings are in {cu!r}; "
                             "one triad, one unit")

    name = d.get("name", folder.resolve().name)
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"{src}: name = {name!r}: expected a non-empty text")
    if not (imgs or gon or plat or cal):
        raise InputError(f"{src}: names no sources (images, goniometer, calibration, platform)")
    tol = (ToleranceSpec.from_table(_table(d, "tolerance", src + ": "), f"{src}: [tolerance]")
           if "tolerance" in d else None)
    # The file's degrees stop here: the library takes radians.
    return Session(folder, name, None if lat is None else lat * DEG, cal, gon, cameras,
                   views, tuple(imgs), plat,
                   None if lat_range is None else (lat_range[0] * DEG, lat_range[1] * DEG),
                   _metadata(d, src), tol)
