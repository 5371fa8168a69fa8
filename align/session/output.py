"""A session's result as JSON (the contract of ``align run``), the platform calibration, and
writing a session's outputs (JSON, report, calibration: each atomically, none lost)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from align.apply import PlatformCalibration
from align.calibration import calibration_json
from align.calibration.output import with_units
from align.contract import document
from align.fusion import E_INDEX
from align.gonio import run_json
from align.session.run import SessionResult
from align.warnings import session_warnings
from axisbase.output import write_json
from axisbase.provenance import Provenance


def platform_calibration(res: SessionResult) -> PlatformCalibration | None:
    if res.fusion is None or res.calibration is None:
        return None
    e6 = np.array([res.fusion.E[i, j] for i, j in E_INDEX])
    return PlatformCalibration(res.calibration.model, e6, res.fusion.cov)


def result_json(res: SessionResult) -> dict:
    d: dict = {"session": res.session.name, "folder": str(res.session.folder),
               "ok": res.ok, "fused": res.fused, "warnings": session_warnings(res),
               "errors": [{"stage": e.stage, "message": e.message} for e in res.errors],
               "metadata": dict(res.session.metadata)}
    if res.fusion is not None:
        d.update(res.fusion.to_dict())
    pc = platform_calibration(res)
    if pc is not None:
        d["platform_calibration"] = pc.to_dict(res.units)
    stages: dict = {}
    if res.calibration is not None:
        stages["calibration"] = with_units(
            calibration_json(res.calibration, res.calibration_poses), res.units)
    if res.gonio is not None:
        g = res.session.goniometer
        stages["goniometer"] = run_json(res.gonio, g.faces, g.nominal_rad)
    if res.marks:
        stages["marks"] = [dict(r.to_dict(), housing=im.housing, view=im.view,
                                nominal=im.nominal) for im, r in res.marks]
    d["stages"] = stages
    return d


def session_document(res: SessionResult, settings: Mapping) -> dict:
    """:func:`result_json` in its envelope (format, version, provenance)."""
    return document("session", result_json(res), settings, res.session.inputs)


def session_outputs(res: SessionResult, outs: Mapping[str, Path | None], force: bool,
                    settings: Mapping) -> tuple[dict[str, Path], dict]:
    """Write the outputs asked for (``json``, ``report``, ``cal``: checked paths or None);
    returns what was written and the result JSON. Each file is written to a temporary name
    and renamed into place, exclusively unless ``force``."""
    from align.session.report import write_report

    js = session_document(res, settings)
    written: dict[str, Path] = {}
    if outs.get("json") is not None:
        written["json"] = write_json(outs["json"], js, force)
    if outs.get("report") is not None:
        written["report"] = write_report(res, outs["report"], force, js)
    pc = platform_calibration(res)
    if outs.get("cal") is not None and pc is not None:
        written["cal"] = write_json(outs["cal"], pc.document(
            res.units, dict(settings), res.session.inputs, Provenance.from_dict(js)), force)
    return written, js


def truth_errors(fusion, truth: Mapping) -> tuple[np.ndarray, float]:
    """Error of E against a synthetic session's truth [rad] and the RMS of the normalised
    errors (error / u) over the six angles."""
    err = fusion.E - np.array(truth["misalignment_rad"])
    u = np.where(fusion.E_u > 0, fusion.E_u, np.inf)
    z = [err[i, j] / u[i, j] for i, j in E_INDEX]
    return err, float(np.sqrt(np.mean(np.square(z))))
