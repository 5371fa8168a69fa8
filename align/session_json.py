"""The one reader of a session result JSON (``align run --json``, format ``axis-align/session``).

A session result is not loaded back whole (its stages need the session's files); what other
parts of the tool need of one is :class:`LoadedSession`: a lot reads its angles, a resumed
batch its provenance and outputs, ``align apply``/``tilt`` its platform calibration, ``align
plan`` its budget. Every one of them reads it through :meth:`LoadedSession.from_dict`, which
checks the format and its version (every version in :data:`align.contract.READABLE`: version
1 without an envelope, 2 with the provenance nested, 3 with it at the top level) and the keys'
shapes, and says in one line naming the file and the key what is wrong.

Kept light (no fusion, no numpy beyond the checks): a lot reads thousands of these.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from align import problem_codes as pc
from align.contract import check, read_json
from align.errors import InputError
from axisbase.covariance import cov_of
from axisbase.provenance import Provenance
from axisbase.units import ARCSEC

ANGLE_NAMES = ("E_xY", "E_xZ", "E_yX", "E_yZ", "E_zX", "E_zY")
"""The six angles in the order of ``angle_names`` of a session result (``align.fusion``'s
``E_NAMES``, repeated here so reading a result does not import the fusion)."""
ANGLE_INDEX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
"""Row and column in E of each of :data:`ANGLE_NAMES`."""

_AGREE_ARCSEC = 1e-6
"""How far [″] the arc-second copy of a matrix may differ from the radian one (both are
written from one float64; 1e-6″ is far above their rounding)."""


@dataclass(frozen=True)
class StageFailure:
    """One entry of a result's ``errors``.

    Attributes
    ----------
    stage : str
        The stage that failed (``calibration``, ``goniometer``, ``marks``, ...); unit —.
    message : str
        Why, as the result says it; unit —.
    internal : bool
        A defect of the tool ("internal error — please report"), not bad input; unit —.
    """

    stage: str
    message: str
    internal: bool = False


@dataclass(frozen=True)
class LoadedSession:
    """What a session result JSON says, checked.

    Attributes
    ----------
    where : str
        The file (or the label) it was read from, for messages; unit —.
    format_version : int
        The result's format version — dimensionless.
    session : str
        The session's name; unit —.
    folder : str or None
        The session folder it was made from (None: the result does not say); unit —.
    ok : bool
        Every stage succeeded and the fusion ran; unit —.
    fused : bool
        A misalignment matrix exists (perhaps from fewer sources than named); unit —.
    e_rad : tuple of float or None
        The six angles E_ij in :data:`ANGLE_NAMES` order [rad] (None when not fused).
    u_rad : tuple of float or None
        Their standard uncertainties [rad] (None when not fused).
    covariance : tuple of tuple of float or None
        The 6×6 covariance of ``e_rad`` [rad²] (None when not fused or not written).
    chi2 : float or None
        The fusion's χ² — dimensionless (None when not fused).
    dof : int or None
        Its degrees of freedom — dimensionless.
    p_value : float or None
        P(χ² ≥ chi2) — dimensionless.
    consistent : bool
        No structure left in the fusion's residual (``not unexplained_structure``); unit —.
    warnings : tuple of str
        The result's warnings; unit —.
    errors : tuple of StageFailure
        Each failed stage; unit —.
    metadata : Mapping
        The session's ``[metadata]`` (texts, numbers, booleans) as the user wrote them;
        unit —.
    provenance : Provenance
        Tool version, creation time, settings and inputs (read from either layout); unit —.
    disposition : Mapping or None
        The verdict block (:meth:`align.decision.Disposition.from_dict` reads it); None in
        results written before verdicts; unit —.
    problems : tuple of str
        Why a result that ran is not ok beyond a failed stage, as the result says it; unit —.
    problem_codes : tuple of str
        The code of each of ``problems`` (:mod:`align.problem_codes`; a result before
        version 5: :data:`~align.problem_codes.UNKNOWN` each); unit —.
    undetermined : tuple of Mapping
        The nuisances the fusion carried undetermined
        (:meth:`align.fusion.undetermined.Undetermined.from_dict` reads each; empty before
        they were written); unit —.
    budget : Mapping or None
        The uncertainty budget block (:meth:`align.fusion.budget.Budget.from_dict`); unit —.
    platform_calibration : Mapping or None
        The platform calibration block (:meth:`align.apply.PlatformCalibration.from_dict`
        reads it); None when the session gave none; unit —.
    """

    where: str
    format_version: int
    session: str
    folder: str | None
    ok: bool
    fused: bool
    e_rad: tuple[float, ...] | None = None
    u_rad: tuple[float, ...] | None = None
    covariance: tuple[tuple[float, ...], ...] | None = None
    chi2: float | None = None
    dof: int | None = None
    p_value: float | None = None
    consistent: bool = True
    warnings: tuple[str, ...] = ()
    errors: tuple[StageFailure, ...] = ()
    metadata: Mapping[str, Any] = field(default_factory=dict)
    provenance: Provenance = field(default_factory=lambda: Provenance(command=()))
    disposition: Mapping[str, Any] | None = None
    problems: tuple[str, ...] = ()
    problem_codes: tuple[str, ...] = ()
    undetermined: tuple[Mapping[str, Any], ...] = ()
    budget: Mapping[str, Any] | None = None
    platform_calibration: Mapping[str, Any] | None = None

    @property
    def verdict(self) -> str | None:
        """PASS / FAIL / INCONCLUSIVE / NOT MEASURED / NO TOLERANCE, or None (no verdict)."""
        v = (self.disposition or {}).get("verdict")
        return v if isinstance(v, str) else None

    @property
    def internal_error(self) -> bool:
        """A stage hit a defect of the tool."""
        return any(e.internal for e in self.errors)

    def cov_of(self, *names: str) -> np.ndarray:
        """The covariance [rad²] of the angles named (of :data:`ANGLE_NAMES`), in the order
        given; ``InputError`` when the result has none."""
        if self.covariance is None:
            raise InputError(f"{self.where}: no covariance_rad2 (not fused, or written before "
                             "covariances)")
        return cov_of(np.asarray(self.covariance), ANGLE_NAMES, names)

    @classmethod
    def load(cls, path: str | Path) -> LoadedSession:
        """Read the file ``path`` (``InputError`` naming it when it is not a readable
        session result)."""
        return cls.from_dict(read_json(path, "a session result"), str(path))

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], where: str) -> LoadedSession:
        """From a session result's JSON (``InputError`` naming ``where`` and the key when it
        is not a readable session result)."""
        if not isinstance(d, Mapping):
            raise InputError(f"{where}: not a JSON object (a session result is one)")
        version = check(d, "session", where)
        for key in ("session", "ok", "fused"):
            if key not in d:
                raise InputError(f"{where}: no {key!r}: not a session result")
        ok, fused = d["ok"], d["fused"]
        if not isinstance(ok, bool) or not isinstance(fused, bool):
            raise InputError(f"{where}: 'ok' and 'fused' must be true or false")
        angles: dict[str, Any] = {}
        if fused:
            names = d.get("angle_names", list(ANGLE_NAMES))
            if list(names) != list(ANGLE_NAMES):
                raise InputError(f"{where}: angle_names {names!r}: expected "
                                 f"{list(ANGLE_NAMES)}")
            e = _angles(d.get("misalignment_rad"), f"{where}: misalignment_rad", diagonal=True)
            u = _angles(d.get("misalignment_u_rad"), f"{where}: misalignment_u_rad")
            _copies_agree(d, e, u, where)
            angles = {"e_rad": e, "u_rad": u, "chi2": _finite_or_none(d.get("chi2")),
                      "dof": d["dof"] if isinstance(d.get("dof"), int)
                      and not isinstance(d.get("dof"), bool) else None,
                      "p_value": _finite_or_none(d.get("p_value")),
                      "covariance": _covariance(d.get("covariance_rad2"), where),
                      "consistent": not d.get("unexplained_structure", False)}
        meta = d.get("metadata") or {}
        if not isinstance(meta, Mapping):
            raise InputError(f"{where}: metadata: expected an object")
        for k, v in meta.items():
            if not isinstance(v, str | int | float | bool):  # what session.toml allows
                raise InputError(f"{where}: metadata {k}: expected a text, number or "
                                 "true/false")
        errs = d.get("errors") or []
        warns = d.get("warnings") or []
        if not isinstance(errs, list) or not isinstance(warns, list):
            raise InputError(f"{where}: 'errors' and 'warnings' must be lists")
        failed = tuple(StageFailure(str(x.get("stage", "?")), str(x.get("message", "")),
                                    x.get("internal") is True)
                       if isinstance(x, Mapping) else StageFailure("?", str(x)) for x in errs)
        if ok and failed:
            raise InputError(f"{where}: 'ok' is true but stage {failed[0].stage} failed "
                             f"({failed[0].message}): a corrupt or edited result")
        blocks = {}
        for key in ("disposition", "budget", "platform_calibration"):
            v = d.get(key)
            if v is not None and not isinstance(v, Mapping):
                raise InputError(f"{where}: {key}: expected an object")
            blocks[key] = v
        problems = d.get("problems") or []
        carried = d.get("undetermined") or []
        if not isinstance(problems, list) or not isinstance(carried, list) or not all(
                isinstance(c, Mapping) for c in carried):
            raise InputError(f"{where}: 'problems' and 'undetermined' must be lists")
        folder = d.get("folder")
        return cls(where, version, str(d["session"]), folder if isinstance(folder, str)
                   else None, ok, fused, **angles, warnings=tuple(str(w) for w in warns),
                   errors=failed, metadata=dict(meta), provenance=_provenance(d, where),
                   problems=tuple(str(p) for p in problems),
                   problem_codes=pc.codes_of(problems, d.get("problem_codes")),
                   undetermined=tuple(carried), **blocks)


def _provenance(d: Mapping[str, Any], where: str) -> Provenance:
    try:
        return Provenance.from_dict(d)
    except (KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"{where}: its provenance (inputs, settings) is malformed "
                         f"({exc!s})") from None


def _covariance(cov: object, where: str) -> tuple[tuple[float, ...], ...] | None:
    if cov is None:
        return None
    a = None
    if isinstance(cov, list):
        try:
            a = np.asarray(cov, float)
        except (TypeError, ValueError):
            a = None
    if a is None or a.shape != (6, 6) or not np.all(np.isfinite(a)):
        raise InputError(f"{where}: covariance_rad2: expected a 6×6 matrix of numbers")
    return tuple(map(tuple, a.tolist()))


def _copies_agree(d: Mapping[str, Any], e: tuple[float, ...], u: tuple[float, ...],
                  where: str) -> None:
    """Each u > 0, and the arc-second copies of the matrices equal the radian ones."""
    for (i, j), v in zip(ANGLE_INDEX, u, strict=True):
        if not v > 0:
            raise InputError(f"{where}: misalignment_u_rad[{i}][{j}] = {v!r}: an uncertainty "
                             "must be > 0 (no measured angle is exact)")
    for key, rad in (("misalignment_arcsec", e), ("misalignment_u_arcsec", u)):
        if key not in d:
            continue
        arc = _angles(d[key], f"{where}: {key}")
        for (i, j), a, r in zip(ANGLE_INDEX, arc, rad, strict=True):
            if abs(a - r / ARCSEC) > _AGREE_ARCSEC + 1e-9 * abs(a):
                raise InputError(f"{where}: {key}[{i}][{j}] = {a:.6g}″ but "
                                 f"{key.replace('arcsec', 'rad')} gives {r / ARCSEC:.6g}″: "
                                 "the two copies disagree (an edited result?)")


def _finite_or_none(v: object) -> float | None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        return None
    return float(v)


def _angles(m: object, where: str, diagonal: bool = False) -> tuple[float, ...]:
    """The six off-diagonal elements of a 3×3 list, each a finite number; ``diagonal``: the
    diagonal must be zero too (E has none: a non-zero one is a corrupt or edited file)."""
    if not (isinstance(m, list) and len(m) == 3
            and all(isinstance(r, list) and len(r) == 3 for r in m)):
        raise InputError(f"{where}: expected a 3×3 matrix")
    if diagonal:
        for i in range(3):
            if m[i][i] != 0:
                raise InputError(f"{where}[{i}][{i}] = {m[i][i]!r}: the diagonal of E is zero "
                                 "(a corrupt or edited result?)")
    out = []
    for i, j in ANGLE_INDEX:
        v = m[i][j]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise InputError(f"{where}[{i}][{j}] = {v!r}: not a finite number")
        out.append(float(v))
    return tuple(out)
