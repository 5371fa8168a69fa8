"""Results save and load themselves: to_dict -> strict JSON -> from_dict gives the same result
(the same dict again, the same arrays to the bit), and what is loaded prints and warns as what
was run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from align.loop import EffectReport, LoopSummary, RefusedEffect
from axisbase.output import dumps


@pytest.fixture(scope="module")
def session_result(tmp_path_factory):
    """A seeded synthetic session without images, run once: its result and its JSON."""
    from align.session import load_session, run_session
    from synth.session import SessionSpec
    from tests.conftest import imageless_session

    s = imageless_session(tmp_path_factory.mktemp("io"), SessionSpec(
        seed=8, effects={"reference_offset": 20.0}, undeclared=frozenset({"reference_offset"})))
    res = run_session(load_session(s))
    assert res.fusion is not None
    return res, json.loads(dumps(res.to_dict()))


def test_fusion_result_round_trip(session_result):
    from align.fusion.solve import FusionResult

    res, js = session_result
    f = FusionResult.from_dict(js)
    assert np.array_equal(f.E, res.fusion.E) and np.array_equal(f.cov, res.fusion.cov)
    assert np.array_equal(f.axes, res.fusion.axes)
    assert f.to_dict() == {k: js[k] for k in f.to_dict()}
    # a loaded fusion prints and reports its loop like the one just run
    assert f.loop.summary_lines() == res.fusion.loop.summary_lines()
    assert f.consistent == res.fusion.consistent
    assert [e.name for e in f.loop.effects] == ["reference_face_offset"]


def test_loop_summary_round_trip_keeps_every_field(session_result):
    res, _ = session_result
    s = res.calibration.loop.summary()
    back = LoopSummary.from_dict(json.loads(dumps(s.to_dict())))
    assert back.to_dict() == json.loads(dumps(s.to_dict()))
    assert back.summary_lines() == s.summary_lines()


def test_effect_and_refusal_round_trip_with_non_finite_values():
    e = EffectReport("nonlinearity_k2", 2.5e-5, float("nan"), "1/g", 1e-5, 8e-6, -12.0, 1e-9,
                     "K2", (("x", 1e-5, 2e-6), ("y", -3e-6, 2e-6)))
    back = EffectReport.from_dict(json.loads(dumps(e.to_dict())))  # NaN is saved as null
    assert np.isnan(back.u) and back.components == e.components
    assert back.to_dict().keys() == e.to_dict().keys()
    r = RefusedEffect("nonlinearity_k2", "moves k_z by 4681 %", 1e-99, -400.0)
    assert RefusedEffect.from_dict(r.to_dict()) == r


def test_from_dict_refuses_what_is_not_its_own():
    from align.fusion.solve import FusionResult

    with pytest.raises(KeyError):
        FusionResult.from_dict({"chi2": 1.0})
    with pytest.raises(ValueError, match="angle_names"):
        FusionResult.from_dict({"angle_names": ["a"] * 6})


def test_triad_model_and_platform_calibration_round_trip(session_result):
    from align.apply import PlatformCalibration
    from align.calibration import TriadModel

    res, js = session_result
    m = res.calibration.model
    back = TriadModel.from_dict(json.loads(dumps(m.to_dict())))
    for f in ("k", "beta", "bias", "k2", "drift", "cov"):
        assert np.array_equal(getattr(back, f), getattr(m, f)), f
    pc = PlatformCalibration.from_dict(js["platform_calibration"], "result.json")
    u = np.array([[0.01, -0.02, -2.4]])
    assert np.array_equal(pc.specific_force(u, m.t_ref),
                          res.platform_calibration().specific_force(u, m.t_ref))


def test_mark_results_round_trip():
    """Marks of one frame (shared distortion, loop summary) and a failed image: to_dict ->
    strict JSON -> from_dict -> to_dict is the same dict; what is not saved comes back None."""
    from align.marks import MarkResult, measure_image
    from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks

    marks = tuple(MarkSpec(np.deg2rad(a), off, 500, 4.0)
                  for a, off in ((1.0, -200.0), (-2.0, 150.0), (91.0, 250.0)))
    spec = ImageSpec(marks=marks, width=800, height=600, full_well_e=full_well_for_snr(40, -0.6),
                     seed=3, camera=CameraGeometry(focal_px=800.0, k1=-0.08))
    res = measure_image(render_marks(spec, with_crlb=False).image.astype(float), "a.png")
    res.append(MarkResult(image="b.png", found=False, error="internal error: X", index=0,
                          internal_error=True))
    assert sum(r.found for r in res) == 3 and res[0].lens is not None and res[0].u_terms
    for r in res:
        d = json.loads(dumps(r.to_dict()))
        back = MarkResult.from_dict(d)
        assert back.to_dict() == d
        assert back.measurement is None
        if r.found:
            assert back.angle_rad == r.angle_rad and back.angle_u_rad == r.angle_u_rad
            assert back.lens == r.lens and back.u_terms.keys() == r.u_terms.keys()
            assert back.notes == r.notes and back.lens_limited == r.lens_limited
            assert back.loop.summary_lines() == r.loop.summary_lines()
            assert back.unexplained_structure == r.unexplained_structure
            assert [e.name for e in back.loop.effects] == [e.name for e in r.loop.effects]
        else:
            assert back == r


def test_frame_distortion_with_unbounded_u_round_trips():
    from align.marks import FrameDistortion

    f = FrameDistortion(0.0, float("inf"), False, True, 2, 1.1, 1.1, 1.0)
    back = FrameDistortion.from_dict(json.loads(dumps(f.to_dict())))  # inf saved as null
    assert np.isnan(back.k1_u)
    assert json.loads(dumps(back.to_dict())) == json.loads(dumps(f.to_dict()))


def test_camera_model_round_trip():
    from imaging import CameraModel

    K = np.array([[812.25, 0, 319.5], [0, 811.75, 239.25], [0, 0, 1]])
    m = CameraModel(K, np.array([-0.25, 0.08, 1e-4, -2e-4, 0.0]), (640, 480), 0.31, 13,
                    {"fx": 1.5, "k1": 0.002}, {"left01.jpg": 0.2})
    d = json.loads(dumps(m.to_dict()))
    back = CameraModel.from_dict(d)
    assert np.array_equal(back.camera_matrix, K) and back.to_dict() == d
    assert back.image_size == (640, 480) and back.u == m.u
