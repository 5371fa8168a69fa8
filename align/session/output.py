"""A session's result as JSON (the contract of ``align run``), the platform calibration, and
writing a session's outputs (JSON, report, calibration: each atomically, none lost)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from align.contract import document
from align.fusion import E_INDEX
from align.session.report import report_html
from align.session.run import SessionResult
from axisbase.output import OutputSet, dumps, write_atomic
from axisbase.provenance import Provenance


def session_document(res: SessionResult, settings: Mapping) -> dict:
    """:meth:`SessionResult.to_dict` in its envelope (format, version, provenance)."""
    return document("session", res.to_dict(), settings, res.session.inputs)


def session_outputs(res: SessionResult, outs: Mapping[str, Path | None], force: bool,
                    settings: Mapping) -> tuple[dict[str, Path], dict]:
    """Write the outputs asked for (``json``, ``report``, ``cal``: checked paths or None);
    returns what was written and the result JSON.

    The files appear all together or not at all (:class:`axisbase.output.OutputSet`: each is
    written to a temporary name, then all are renamed into place, exclusively unless
    ``force``); the JSON is put in place last, so an existing JSON means a complete set. A JSON
    to standard output (``-``) is written after the files."""

    js = session_document(res, settings)
    pc = res.platform_calibration()
    files: dict[str, tuple[Path, str]] = {}
    if outs.get("cal") is not None and pc is not None:
        files["cal"] = (outs["cal"], dumps(pc.document(
            res.units, dict(settings), res.session.inputs, Provenance.from_dict(js))))
    if outs.get("report") is not None:
        files["report"] = (outs["report"], report_html(res, js))
    to_stdout = outs.get("json") is not None and str(outs["json"]) == "-"
    if outs.get("json") is not None and not to_stdout:
        files["json"] = (outs["json"], dumps(js))
    with OutputSet(force) as out:
        for path, text in files.values():
            out.stage(path, text)
        out.commit()
    written = {k: files[k][0] for k in ("json", "report", "cal") if k in files}
    if to_stdout:
        written["json"] = write_atomic(outs["json"], dumps(js))
    return written, js


def truth_errors(fusion, truth: Mapping) -> tuple[np.ndarray, float]:
    """Error of E against a synthetic session's truth [rad] and the RMS of the normalised
    errors (error / u) over the six angles."""
    err = fusion.E - np.array(truth["misalignment_rad"])
    u = np.where(fusion.E_u > 0, fusion.E_u, np.inf)
    z = [err[i, j] / u[i, j] for i, j in E_INDEX]
    return err, float(np.sqrt(np.mean(np.square(z))))
