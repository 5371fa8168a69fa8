"""A session's result as JSON (the contract of ``align run``) and the platform calibration."""

from __future__ import annotations

import numpy as np

from align.apply import PlatformCalibration
from align.calibration import calibration_json
from align.fusion import E_INDEX, E_NAMES
from align.gonio import run_json
from align.session.run import SessionResult

ARCSEC = np.pi / 180 / 3600


def platform_calibration(res: SessionResult) -> PlatformCalibration | None:
    if res.fusion is None or res.calibration is None:
        return None
    e6 = np.array([res.fusion.E[i, j] for i, j in E_INDEX])
    return PlatformCalibration(res.calibration.model, e6, res.fusion.cov)


def result_json(res: SessionResult) -> dict:
    d: dict = {"session": res.session.name, "folder": str(res.session.folder),
               "ok": res.ok,
               "errors": [{"stage": e.stage, "message": e.message} for e in res.errors]}
    f = res.fusion
    if f is not None:
        d.update({
            "misalignment_rad": f.E.tolist(), "misalignment_u_rad": f.E_u.tolist(),
            "misalignment_arcsec": (f.E / ARCSEC).tolist(),
            "misalignment_u_arcsec": (f.E_u / ARCSEC).tolist(),
            "angle_names": list(E_NAMES), "covariance_rad2": f.cov.tolist(),
            "axes": f.axes.tolist(), "chi2": f.chi2, "dof": f.dof, "p_value": f.p_value,
            "uncertainty_inflation": f.inflation, "sources": list(f.sources),
            "effects": [e.to_json() for e in f.loop.effects],
            "unexplained_structure": f.loop.unexplained_structure,
            "nuisances": {k: {"estimate": v[0], "u": v[1]} for k, v in f.nuisances.items()},
            "observations": [{"source": r.source, "label": r.label, "value": r.value,
                              "predicted": r.predicted, "u": r.u, "unit": r.unit,
                              "normalised_residual": r.normalised} for r in f.rows],
        })
    pc = platform_calibration(res)
    if pc is not None:
        d["platform_calibration"] = pc.to_dict()
    stages: dict = {}
    if res.calibration is not None:
        stages["calibration"] = calibration_json(res.calibration, res.calibration_poses)
    if res.gonio is not None:
        g = res.session.goniometer
        stages["goniometer"] = run_json(res.gonio, g.faces, g.nominal_rad)
    if res.marks:
        stages["marks"] = [dict(r.to_json(), housing=im.housing, view=im.view,
                                nominal=im.nominal) for im, r in res.marks]
    d["stages"] = stages
    return d
