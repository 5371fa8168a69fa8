"""A camera model without a joint covariance (a file written elsewhere, or before camera
format 4: only each parameter's u): its u must cover a lens that differs from it by that u.

The test's null is the model's own: the rendered lens is drawn from the model's declared u
(each parameter independently, as the file states them), so the angles' errors are what
the model's u says they are. The same u given as a diagonal joint covariance is the control.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from align import LensRanges, measure_image
from imaging.camera_cov import INTRINSICS
from tests.align.test_lens import _bowed_by_the_lens, _camera_model, _render, _z
from tests.conftest import angle_error

SEEDS = range(20)


def _drawn_lens_z(with_cov: bool) -> tuple[np.ndarray, np.ndarray]:
    """(z of each mark's angle, whether it is reported ok) over :data:`SEEDS`: the two marks
    of :func:`tests.align.test_lens._bowed_by_the_lens` through a lens drawn from the model's
    u (k1, k2, p1, p2, f, principal point), the camera declared unmoved since calibration."""
    cam, marks = _bowed_by_the_lens()
    model = _camera_model(cam)
    u = model.u
    if with_cov:
        model = replace(model, cov=np.diag([u.get(k, 0.0) ** 2 for k in INTRINSICS]))
    zs, ok = [], []
    for seed in SEEDS:
        r = np.random.default_rng(100 + seed)
        drawn = replace(cam, k1=cam.k1 + r.normal() * u["k1"], k2=cam.k2 + r.normal() * u["k2"],
                        p1=cam.p1 + r.normal() * u["p1"], p2=cam.p2 + r.normal() * u["p2"],
                        focal_px=cam.focal_px + r.normal() * u["fx"],
                        pp_offset_px=(cam.pp_offset_px[0] + r.normal() * u["cx"],
                                      cam.pp_offset_px[1] + r.normal() * u["cy"]))
        s = _render(marks, drawn, seed=seed)
        for x in measure_image(s.image, "cam.png", camera=model,
                               ranges=LensRanges(pp_stability_px=0)):
            assert x.found, x.error
            t = min(marks, key=lambda m: abs(angle_error(x.angle_rad, m.angle_rad)))
            zs.append(_z(x, t.angle_rad))
            ok.append(not (x.lens_limited or x.kinked or x.unexplained_structure
                           or any("NOT OK" in n for n in x.notes)))
    return np.array(zs), np.array(ok)


@pytest.mark.slow
@pytest.mark.parametrize("with_cov", [
    True,
    pytest.param(False, marks=pytest.mark.xfail(strict=True, reason=(
        "without a joint covariance the model's u is carried by align.camera_lens's "
        "camera_coupling at no lens on top of the model, where the principal point's "
        "columns are 0 (camera_cx, camera_cy 0.0″) and f has none: 19 of 40 angles ok "
        "beyond 3 u (|z| to 10.0, RMS 4.06), no warning; a cx 3 u (2.1 px) off moves "
        "these marks' angles 143″ and 137″. The same u as a diagonal covariance "
        "(model_coupling, through the model): RMS z 0.99, max 2.03"))),
])
def test_a_lens_within_the_models_u_is_within_the_angles_u(with_cov):
    zs, ok = _drawn_lens_z(with_cov)
    assert not np.any(ok & (np.abs(zs) > 3)), np.round(zs, 2)
