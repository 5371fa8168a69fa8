"""One lens per camera (issue 18): identifiability before estimation, undetermined optics
carried in u, a given camera trusted, a lens told from a bent mark.

Images are rendered through a physical lens (synth's Brown-Conrady camera, OpenCV's model:
every pixel integrates the scene where the lens maps it from); the pipeline is not told the
lens unless a test gives it a camera model.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from align import lens as lens_mod
from align.camera_lens import camera_lens, lens_lines
from align.cli import main
from align.documents import marks_document
from align.lens import LensRanges
from align.marks import BEND, finish_mark, measure_image
from align.present import mark_lines
from axisbase.errors import InputError
from imaging import CameraModel, measure_frame, measure_marks
from synth import (
    CameraGeometry,
    ImageSpec,
    MarkSpec,
    full_well_for_snr,
    render_marks,
    write_synth,
)
from tests.align.lens_grid import (
    K1_CLASSES,
    PLAUSIBLE,
    POSITIONS,
    draw_lens,
    draw_plausible,
    grid_table,
    run_case,
    scaled_lens,
    wrong_sign,
)
from tests.align.test_marks_loop import _bowed_groove
from tests.conftest import angle_error, real_folder

CHESSBOARD = CameraGeometry(focal_px=530.0, k1=-0.27)  # the issue's lens (radial only)


def _vertical(x: float, y: float, length: float = 150.0) -> MarkSpec:
    a = np.pi / 2 - 0.01
    return MarkSpec(a, x * np.sin(a) + y * np.cos(a), length, 4.0,
                    centre_t_px=x * np.cos(a) - y * np.sin(a))


def _render(marks, camera, seed=1, w=640, h=480):
    spec = ImageSpec(marks=tuple(marks), width=w, height=h, camera=camera, seed=seed,
                     full_well_e=full_well_for_snr(40, -0.6), supersample=4)
    return render_marks(spec, with_crlb=False)


def _z(r, truth_angle):
    return angle_error(r.angle_rad, truth_angle) / r.angle_u_rad


def test_issue_case_short_mark_in_the_top_third_is_lens_limited_not_wrong():
    """The issue's case: a straight 150 px vertical mark in the top third of a 640x480 frame
    through k1 = -0.27 at f = 530 px. Before: k1 of the wrong sign and 1962" off at +-160"
    (12 u). Now: no wrong-sign k1 applied, the error within 3 u, and the angle marked
    lens-limited ("calibrate the camera"), the marks document not ok."""
    m = _vertical(-150.0, -160.0)
    s = _render([m], CHESSBOARD)
    r = measure_image(s.image, "top.png")[0]
    k1 = r.lens["parameters"]["k1"]
    assert not (k1["applied"] and k1["value"] > 0)
    assert abs(_z(r, m.angle_rad)) <= 3
    assert r.lens_limited and any("calibrate the camera" in n for n in r.notes)
    doc = marks_document([r], {}, [])
    assert doc["ok"] is False and any("calibrate the camera" in w for w in doc["warnings"])


def test_two_segments_in_one_frame_share_the_lens_and_stay_within_u():
    """Two such segments (top and bottom third): one lens for both, no wrong sign, both
    angles within 3 u (before: joint k1 ~ 0 and both 2.4-2.7 deg off at 9-17 u)."""
    marks = [_vertical(100.0, -160.0), _vertical(-120.0, 165.0)]
    s = _render(marks, CHESSBOARD, seed=2)
    res = [r for r in measure_image(s.image, "two.png") if r.found]
    assert len(res) == 2 and res[0].lens == res[1].lens and res[0].lens["lines"] == 2
    k1 = res[0].lens["parameters"]["k1"]
    assert not (k1["applied"] and k1["value"] > 0)
    for r in res:
        t = min(marks, key=lambda m: abs(angle_error(r.angle_rad, m.angle_rad)))
        assert abs(_z(r, t.angle_rad)) <= 3


def _camera_model(cam: CameraGeometry, w=640, h=480, k1=None, u_k1=5e-4) -> CameraModel:
    """The lens as `align camera` would save it after a good calibration (u as given)."""
    K = np.array([[cam.focal_px, 0, (w - 1) / 2 + cam.pp_offset_px[0]],
                  [0, cam.focal_px * cam.aspect, (h - 1) / 2 + cam.pp_offset_px[1]],
                  [0, 0, 1]])
    D = np.array([cam.k1 if k1 is None else k1, cam.k2, cam.p1, cam.p2, 0.0])
    u = {"fx": 0.7, "fy": 0.8, "cx": 0.7, "cy": 0.7, "k1": u_k1, "k2": 1e-3,
         "p1": 5e-5, "p2": 5e-5, "k3": 0.0, "aspect": 4e-4}  # aspect: the real chessboards'
    return CameraModel(K, D, (w, h), 0.2, 12, u)


def test_a_given_camera_is_trusted_and_its_u_propagated():
    """--camera: the model is the lens (nothing fitted on top), its u is in the angle, the
    error within 3 u; a model whose k1 is wrong is a warning naming the camera."""
    cam = CameraGeometry(focal_px=530.0, k1=-0.27, k2=0.1, p1=1e-3, p2=-2e-4,
                         pp_offset_px=(12.0, -6.0))
    marks = [_vertical(-150.0, -160.0, 250.0),
             MarkSpec(np.deg2rad(3.0), 170.0, 420.0, 4.0, centre_t_px=20.0)]
    s = _render(marks, cam, seed=3)
    res = [r for r in measure_image(s.image, "cam.png", camera=_camera_model(cam)) if r.found]
    assert len(res) == 2
    for r in res:
        assert r.lens["source"] == "camera model"
        assert not any(k.startswith("lens_") for k in r.u_terms)  # nothing fitted on top
        assert any(k.startswith("camera_") for k in r.u_terms)
        t = min(marks, key=lambda m: abs(angle_error(r.angle_rad, m.angle_rad)))
        assert abs(_z(r, t.angle_rad)) <= 3
    bad = measure_image(s.image, "cam.png", camera=_camera_model(cam, k1=-0.20))
    bad = [r for r in bad if r.found]
    assert all(any("the lens differs from its calibration" in n for n in r.notes) for r in bad)
    for r in bad:
        t = min(marks, key=lambda m: abs(angle_error(r.angle_rad, m.angle_rad)))
        assert abs(_z(r, t.angle_rad)) <= 3


def test_a_camera_model_too_uncertain_says_so_not_give_a_model():
    """A camera model given whose own u makes the angle lens-limited (the real chessboards
    calibrated by `align camera` from 7 views: u(k2) 0.068, marks at +-412-733" mostly
    ``camera_k2``): not ok, and the advice is to recalibrate, not "give it with --camera"
    (which the user did: that was the message before; user11's slow
    ``test_lens_limited_with_a_model_says_what_to_do`` on a real calibration)."""
    cam = CameraGeometry(focal_px=530.0, k1=-0.27)
    m = _vertical(-150.0, -160.0, 250.0)
    s = _render([m], cam, seed=3)
    (r,) = [r for r in measure_image(s.image, "cam.png", camera=_camera_model(cam, u_k1=0.05))
            if r.found]
    assert r.lens_limited and max(r.u_terms, key=r.u_terms.get).startswith("camera_")
    said = [n for n in r.notes if "lens-limited" in n]
    assert said and all("camera model's own u limits it" in n for n in said), r.notes
    assert not any("give it with --camera" in n for n in r.notes), r.notes
    assert "camera model's own u limits it" in "\n".join(mark_lines(r))


@pytest.mark.parametrize("ang", [45.0, -45.0, 30.0])
def test_a_camera_models_non_square_pixels_are_taken_out(ang):
    """A camera with fy/fx = 1.005 and its model: the angle is the pinhole image's (the
    scene's), not the pixel grid's, which differs by (fy/fx - 1) sin(2a) / 2 (516" at 45 deg;
    before: +519" at u 3.3", z 156, ok — an independent user's test)."""
    cam = CameraGeometry(focal_px=600.0, aspect=1.005)
    a = np.deg2rad(ang)
    s = _render([MarkSpec(a, 0.0, 300.0, 4.0)], cam, seed=5)
    (r,) = [r for r in measure_image(s.image, "cam.png", camera=_camera_model(cam)) if r.found]
    grid = np.arctan2(np.sin(a) * 1.005, np.cos(a))  # the same line in the pixel grid
    assert abs(angle_error(grid, a)) > 6 * r.angle_u_rad  # the convention is tested
    assert abs(_z(r, a)) <= 3


@pytest.mark.parametrize("ranges", [LensRanges.none(), None], ids=["flat declared", "default"])
def test_a_bent_mark_is_named_and_covered(ranges):
    """A mark bowed by 0.5 px, 120 px off the centre, on a lens-free camera: named a bent
    mark (declared flat lens) or carried as lens-or-bend (undeclared), |err| / u <= 3 (before:
    the radial correction made it 203" off at +-1.7", silently)."""
    r = measure_image(_bowed_groove(120.0, 0.5, 4), "bent.png", ranges=ranges)[0]
    assert abs(angle_error(r.angle_rad, np.deg2rad(20.0))) <= 3 * r.angle_u_rad
    assert r.notes, "a bent mark must be named"
    if ranges is not None:
        assert BEND in [e.name for e in r.loop.effects]


def test_tangential_lens_on_a_long_off_centre_mark_stays_within_u():
    """p1, p2 bending a long off-centre mark (issue: 24-367" off at +-1.5", ok): within 3 u."""
    cam = CameraGeometry(focal_px=700.0, p1=1e-3, p2=-1e-3)
    m = MarkSpec(np.deg2rad(8.0), -150.0, 500.0, 4.0, centre_t_px=40.0)
    s = _render([m], cam, seed=5)
    r = measure_image(s.image, "tan.png")[0]
    assert abs(_z(r, m.angle_rad)) <= 3
    assert any(k.startswith(("lens_p1", "lens_p2")) for k in r.u_terms)


def test_lens_ranges_flag_and_its_errors():
    r = LensRanges.parse("k1=0.1, p=0,max_u_arcsec=30")
    assert (r.k1, r.p, r.max_u_arcsec, r.aspect) == (0.1, 0.0, 30.0, 0.005)
    for bad, said in (("k9=1", "KEY=VALUE"), ("k1=x", "not a number"), ("k1=-1", ">= 0"),
                      ("max_u_arcsec=0", "> 0")):
        with pytest.raises(InputError, match=said):
            LensRanges.parse(bad)
    # beside a camera model only the bound on u applies; a range would be silently ignored
    assert LensRanges.parse("max_u_arcsec=20", beside="--camera").max_u_arcsec == 20.0
    for given in ("k1=0.1", "max_u_arcsec=20,pp_px=5,aspect=0"):
        with pytest.raises(InputError, match=r"--lens (k1|pp_px,aspect) with --camera"):
            LensRanges.parse(given, beside="--camera")


def test_default_grid_two_cases():
    """Two cells of the lens grid (the full grid is slow): no wrong-sign k1, |z| <= 3."""
    cases = []
    for k1, pos, seed in ((-0.3, "across", 0), (0.1, "corner", 1)):
        cam = draw_lens(k1, (640, 480), np.random.default_rng(1000 + seed))
        cases += run_case(f"k1={k1:+.2f}", cam, pos, (640, 480), seed)
    assert cases and all(c.found for c in cases) and wrong_sign(cases) == 0
    assert max(abs(c.z) for c in cases) <= 3


def _grid_lenses(size: tuple[int, int], seed: int, chessboard) -> list[tuple]:
    """(name, camera, ranges declared to the tool) of every lens class for one seed."""
    out = [(f"k1={k1:+.2f}", draw_lens(k1, size, np.random.default_rng([1000, seed, i])), None)
           for i, k1 in enumerate(K1_CLASSES)]
    out.append(("chessboard", scaled_lens(*chessboard, size), None))
    out.append(("plausible", draw_plausible(size, np.random.default_rng([2000, seed])),
                PLAUSIBLE))
    return out


def grid_cases(chessboard) -> list:
    """The grid: every lens class x position at 640x480 (3 seeds, the first a 3-mark frame;
    the plausible class 12 seeds), and at 5 MP the classes' marks across and in a corner
    (1 seed: a 5 MP frame takes seconds)."""
    cases = []
    for size, seeds, positions in (((640, 480), range(12), POSITIONS),
                                   ((2592, 1944), range(1), ("across", "corner"))):
        for seed in seeds:
            for name, cam, ranges in _grid_lenses(size, seed, chessboard):
                if name != "plausible" and seed >= 3:
                    continue
                for pos in positions:
                    cases += run_case(name, cam, pos, size, seed,
                                      n_marks=1 + 2 * (seed == 0 and size == (640, 480)),
                                      ranges=ranges)
    return cases


@pytest.mark.slow
def test_lens_grid():
    """The issue's grid: lens classes k1 in {-0.3, -0.15, 0, +0.1} (OpenCV at f = 1.325 R;
    random k2, p, principal point, aspect), the real chessboard lens (calibrated here from
    ../shared/data/real/opencv-chessboard) and ``plausible`` (every parameter uniform over the
    range the tool is given), marks at the centre / along / across / corner, 640x480 and 5
    MP. Per class: no wrong-sign k1 applied, no angle beyond 3 u (so max |z| <= 4), RMS z <=
    1.2 (u not understated). The single marks of a frame leave most of the lens undetermined
    and u is then its Type B range: for a fixed lens inside that range RMS z < 1 by design
    (k1 = 0 sits at the range's middle); where the lens is drawn over the range the tool
    carries (``plausible``) RMS z is 0.8-1.2. The table is printed (docs/camera.md)."""
    from imaging import calibrate_chessboard, read_image

    files = sorted(real_folder("opencv-chessboard").glob("left*.jpg"))
    model, _ = calibrate_chessboard({str(f): read_image(f).astype(np.uint8) for f in files},
                                    (9, 6), fix_k3=True)
    cases = grid_cases((model.camera_matrix, model.dist_coeffs))
    print()
    for line in grid_table(cases):
        print(line)
    for lens in sorted({c.lens for c in cases}):
        z = np.array([c.z for c in cases if c.lens == lens and c.found])
        rms = float(np.sqrt(np.mean(z**2)))
        assert rms <= 1.2, (lens, rms)
        if lens == "plausible":
            assert rms >= 0.8, (lens, rms)
    assert wrong_sign(cases) == 0
    over = [c for c in cases if abs(c.z) > 3]
    assert not over, over
    assert {c.size for c in cases if c.found} == {(640, 480), (2592, 1944)}


def test_cli_says_calibrate_the_camera_and_exits_2(tmp_path, capsys):
    from align.cli import main
    from synth import write_synth

    p, _ = write_synth(_render([_vertical(-150.0, -160.0)], CHESSBOARD), tmp_path / "top.png")
    assert main(["marks", str(p), "--json", str(tmp_path / "o.json")]) == 2
    assert "calibrate the camera" in capsys.readouterr().err
    import json

    doc = json.loads((tmp_path / "o.json").read_text())
    assert doc["ok"] is False and doc["marks"][0]["lens_limited"] is True


def _lens_session(tmp_path, seed, **kw):
    from tests.align.test_fusion import _session, _z

    res, truth = _session(tmp_path, f"s{seed}", seed=seed, **kw)
    return res, _z(res.fusion.E, res.fusion.E_u, truth)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10))
def test_session_with_an_undeclared_lens_on_one_camera_names_no_roll(tmp_path, seed):
    """Cameras + goniometer + calibration, camera B with an undeclared k1 = -0.25 lens (one
    lens fitted over its four images, the rest in u): no camera roll named, |err/u| <= 3 --
    over 10 seeds, as issue 18 asks (measured: nothing named, RMS z 1.02, max 2.95 of 60)."""
    res, z = _lens_session(tmp_path, seed, undeclared={"lens_k1_B": -0.25})
    names = [e.name for e in res.fusion.loop.effects]
    print(f"seed {seed}: effects {names}, z {np.round(z, 2)}")
    assert not any(n.startswith("camera_roll") for n in names)
    assert np.max(np.abs(z)) <= 3


@pytest.mark.slow
def test_a_real_30_arcsec_roll_is_still_found(tmp_path):
    """Positive control: camera B rolled by 30" (lens-free cameras, declared so): named.

    Seed 12 used to name an 8° reference_face_offset (28600 ± 7171″, E z up to -5.8, ok): a
    nuisance beyond any undeclared set-up error (1°) is now refused and, once the roll is
    added, no longer significant (align/fusion/plausible.py). Where a 30″ roll is not named
    (seed 13, p 0.006), E's u carries it: tests/align/test_fusion.py
    ``test_an_undeclared_30_arcsec_roll_is_never_a_silent_wrong_answer``."""
    from tests.align.test_fusion import NO_REVERSAL

    res, z = _lens_session(tmp_path, 12, undeclared={"camera_roll_B": 30.0}, **NO_REVERSAL)
    e = [e for e in res.fusion.loop.effects if e.name == "camera_roll[B]"]
    print(f"roll {[(x.estimate / 4.848e-6, x.u / 4.848e-6) for x in e]}, z {np.round(z, 2)}")
    assert e and abs(e[0].estimate / 4.8481368e-6 - 30.0) < 3 * e[0].u / 4.8481368e-6
    assert res.ok and np.max(np.abs(z)) <= 3, z


def _bowed_by_the_lens():
    cam = CameraGeometry(focal_px=530.0, k1=-0.27, k2=0.1, p1=1e-3, p2=-2e-4,
                         pp_offset_px=(12.0, -6.0))
    marks = [_vertical(-150.0, -160.0, 250.0),
             MarkSpec(np.deg2rad(3.0), 170.0, 420.0, 4.0, centre_t_px=20.0)]
    return cam, marks


def test_centres_follow_a_groove_the_lens_bows_by_several_px():
    """A 420 px mark near the frame's edge, bowed ~4.7 px by the lens: every centre on the
    imaged curve within 4 of its sigma, the inner ones within 0.05 px, at SNR 400 (before:
    Gauss-Newton stopped after 2 steps of 1 px, the ends 0.2-0.35 px short of the curve, and
    the exact camera model was reported as differing from its calibration)."""
    cam, marks = _bowed_by_the_lens()
    spec = ImageSpec(marks=tuple(marks), width=640, height=480, camera=cam, seed=1,
                     full_well_e=full_well_for_snr(400, -0.6), supersample=4)
    img = render_marks(spec, with_crlb=False).image
    ms = [m for m in measure_marks(img) if not isinstance(m, Exception)]
    m = min(ms, key=lambda m: abs(m.line.angle_rad))  # the near-horizontal one
    mk = marks[1]
    u = np.array([np.cos(mk.angle_rad), -np.sin(mk.angle_rad)])
    n = np.array([np.sin(mk.angle_rad), np.cos(mk.angle_rad)])
    tt = np.linspace(-mk.length_px, mk.length_px, 40001) + mk.centre_t_px
    P = mk.offset_px * n[None] + tt[:, None] * u[None]
    curve = np.column_stack(cam.distort(*cam.scene_to_ideal(P[:, 0], P[:, 1])))
    k = np.argmin(((curve[None] - m.points[:, None]) ** 2).sum(-1), axis=1)
    dist = np.linalg.norm(m.points - curve[k], axis=1)
    assert np.ptp(m.line.residuals_px) > 3  # the bow is several px
    # The centres measured out to the blurred ends (fewer pixels across the groove there)
    # carry a larger sigma: each within 4 of its own, the inner ones within 0.05 px.
    inner = m.sigma < 0.03
    assert inner.sum() > 0.8 * len(dist)
    assert dist[inner].max() < 0.05
    assert np.max(dist / m.sigma) < 4.0


def _exact_model_ps(drawn: bool) -> tuple[np.ndarray, np.ndarray]:
    """(p_marks_agree per seed, every angle's z) over 20 seeds of the bowed marks measured
    with the camera model of :func:`_camera_model`; ``drawn``: each render's lens drawn
    from the model's declared u (each parameter about its value, independently, as the
    model file gives them), else the model's lens itself."""
    cam, marks = _bowed_by_the_lens()
    model = _camera_model(cam)
    ps, zs = [], []
    for seed in range(20):
        lens = cam
        if drawn:
            r = np.random.default_rng(100 + seed)
            u = model.u
            lens = replace(cam, focal_px=cam.focal_px + r.normal(0, u["fx"]),
                           k1=cam.k1 + r.normal(0, u["k1"]), k2=cam.k2 + r.normal(0, u["k2"]),
                           p1=cam.p1 + r.normal(0, u["p1"]), p2=cam.p2 + r.normal(0, u["p2"]),
                           pp_offset_px=(cam.pp_offset_px[0] + r.normal(0, u["cx"]),
                                         cam.pp_offset_px[1] + r.normal(0, u["cy"])),
                           aspect=cam.aspect + r.normal(0, u["aspect"]))
        s = _render(marks, lens, seed=seed)
        res = [r for r in measure_image(s.image, "cam.png", camera=model) if r.found]
        ps.append(res[0].lens["p_marks_agree"])
        for r in res:
            t = min(marks, key=lambda m: abs(angle_error(r.angle_rad, m.angle_rad)))
            zs.append(_z(r, t.angle_rad))
    print(f"\n{'drawn' if drawn else 'exact'} camera model, 20 seeds: p < 1e-3 in "
          f"{sum(p < 1e-3 for p in ps)}, min p {min(ps):.2g}, median p {np.median(ps):.2f}, "
          f"KS p {stats.kstest(ps, 'uniform').pvalue:.2g}; max |z| {np.max(np.abs(zs)):.2f}, "
          f"RMS z {np.sqrt(np.mean(np.square(zs))):.2f}")
    return np.array(ps), np.array(zs)


@pytest.mark.slow
def test_the_exact_camera_model_is_not_called_different():
    """With the exact camera model given, the marks' test of disagreement never flags beyond
    its level: 20 seeds, at most 1 below alpha = 1e-3, no excess of small p's (one-sided
    KS), every angle within 3 u (before: 3 of 6 seeds warned 'the lens differs from its
    calibration', p down to 6e-7).

    Conservative by construction, so not uniform: the model's declared u (k1 5e-4, k2 1e-3,
    cx, cy 0.7 px) enters the test's null while this render realises none of it (median p
    0.85, two-sided KS p 1e-5 with the centres out to the grooves' ends, 0.03 stopped where
    the search's ridge fades; RMS z 0.12). Uniform p's are asked of the renders that realise
    it (:func:`test_a_camera_model_within_its_u_is_not_called_different`)."""
    ps, zs = _exact_model_ps(drawn=False)
    assert np.all(np.abs(zs) <= 3), zs
    assert sum(p < 1e-3 for p in ps) <= 1
    assert stats.kstest(ps, "uniform", alternative="greater").pvalue > 1e-3


@pytest.mark.slow
def test_a_camera_model_within_its_u_is_not_called_different():
    """The test's proper null: each render's lens drawn from the model's declared u, the
    model given as it is. Over 20 seeds the p's are uniform (KS), at most 1 below 1e-3,
    and every angle within 3 u (measured: KS p 0.24, min p 0.005, max |z| 2.35, RMS z
    1.07)."""
    ps, zs = _exact_model_ps(drawn=True)
    assert np.all(np.abs(zs) <= 3), zs
    assert sum(p < 1e-3 for p in ps) <= 1
    assert stats.kstest(ps, "uniform").pvalue > 1e-3


def test_principal_point_range_enters_as_its_rms_not_its_corners():
    """The principal point is uniform over its range (Type B): a quantity known at the centre
    and the range's corners enters u as its mean square over the square, the quadratic
    through those points averaged exactly (against a Monte Carlo over the square), not the
    largest corner's (the bound it used to be). A corner where the lens folds: inf."""
    from align.lens_pp import _uniform_msq

    rng = np.random.default_rng(5)
    for _ in range(5):
        s0, c, gx, gy, h = rng.normal(size=5)

        def f(x, y, s0=s0, c=c, gx=gx, gy=gy, h=h):
            return s0 + c * (x**2 + y**2) / 2 + gx * x + gy * y + h * x * y

        corners = [np.array([f(sx, sy)]) for sx in (-1, 1) for sy in (-1, 1)]
        got = float(_uniform_msq(corners, np.array([s0]))[0])
        xy = rng.uniform(-1, 1, size=(400_000, 2))
        mc = float(np.mean(f(xy[:, 0], xy[:, 1]) ** 2))
        assert got == pytest.approx(mc, rel=0.01)
    assert not np.isfinite(_uniform_msq([np.array([np.inf])] * 4, np.zeros(1))[0])


# Five straight marks spread over a 640 x 480 frame (centre [px] from the image centre,
# direction [deg], length [px]); p is read at the half-diagonal R = 400 px.
_SPREAD = [((-150.0, -150.0), 5.0, 250), ((150.0, 150.0), -8.0, 250),
           ((-230.0, 40.0), 80.0, 200), ((240.0, -30.0), 95.0, 200), ((30.0, -10.0), 40.0, 220)]


def _spread_results(cam: CameraGeometry, seed: int):
    ms = []
    for (x, y), deg, length in _SPREAD:
        a = np.deg2rad(deg)
        ms.append(MarkSpec(a, x * np.sin(a) + y * np.cos(a), length, 4.0,
                           centre_t_px=x * np.cos(a) - y * np.sin(a)))
    s = _render(ms, cam, seed=seed)
    rs = [r for r in measure_image(s.image, "spread.png") if r.found]
    assert len(rs) == len(ms)
    for r in rs:  # each angle honest: within 3 u, or said to be lens-limited
        t = min(ms, key=lambda m: abs(angle_error(r.angle_rad, m.angle_rad)))
        assert abs(_z(r, t.angle_rad)) <= 3 or r.lens_limited
    return rs


def _spread_marks(cam: CameraGeometry, seed: int):
    return {n for r in _spread_results(cam, seed) for n in r.notes}


def _decentred_cases(seeds):
    for seed in seeds:
        rng = np.random.default_rng(seed)
        pp = tuple(rng.uniform(8.0, 15.0, 2) * rng.choice([-1, 1], 2))  # within pp_px = 20
        k1 = rng.uniform(0.08, 0.15)  # pincushion, +0.044..+0.082 at the half-diagonal
        notes = _spread_marks(CameraGeometry(focal_px=540.0, k1=k1, pp_offset_px=pp), seed)
        assert not [n for n in notes if "not a lens" in n], (seed, k1, pp, notes)


def test_radial_lens_about_an_offset_principal_point_is_not_called_not_a_lens():
    """k1 about a principal point 10 px off the centre looks like k1 + p about the centre
    (p1 = -k1 cy/R, p2 = -k1 cx/R): a plausible lens (before: 'p1 = 0.00139 ... beyond any
    lens: not a lens'). Positive controls: a real tangential lens inside the range is found
    (its p1 within 3 u of the truth, not refused), and (slow) one ten times beyond any
    lens, with no radial term to explain it, is still called not a lens."""
    _decentred_cases([1])
    f, R = 540.0, 400.0
    rs = _spread_results(CameraGeometry(focal_px=f, p1=1e-3, p2=-0.8e-3), 1)
    notes = {n for r in rs for n in r.notes}
    assert not [n for n in notes if "not a lens" in n], notes
    # Determined by the lines, applied or (its sign open) carried: its estimate either way.
    p1 = rs[0].lens["parameters"]["p1"]
    assert p1["determined"], p1
    assert abs(p1["estimate"] - 1e-3 * R / f) < 3 * p1["u_from_lines"], p1


@pytest.mark.slow
def test_decentred_radial_lenses_over_seeds():
    _decentred_cases(range(2, 10))
    notes = _spread_marks(CameraGeometry(focal_px=540.0, p1=1e-2), 1)  # the control above
    assert [n for n in notes if "lens p1" in n and "beyond any lens" in n], notes


@pytest.mark.slow
def test_a_lens_ten_times_beyond_any_is_not_ok_everywhere(tmp_path, capsys):
    """p1 = 1e-2 (ten times any plausible lens), five marks spread over the frame, no camera
    model: the angles are 4-7 u off, so each such angle must be not ok wherever a user looks
    — exit status 2, the JSON's ``ok`` false and the mark's ``lens_limited``, a NOT OK line
    on the terminal for it, and the lens named as beyond any lens."""
    ms = []
    for (x, y), deg, length in _SPREAD:
        a = np.deg2rad(deg)
        ms.append(MarkSpec(a, x * np.sin(a) + y * np.cos(a), length, 4.0,
                           centre_t_px=x * np.cos(a) - y * np.sin(a)))
    png, _ = write_synth(_render(ms, CameraGeometry(focal_px=540.0, p1=1e-2), seed=1),
                         tmp_path / "p10.png")
    out = tmp_path / "p10.json"
    assert main(["marks", str(png), "--json", str(out)]) == 2
    js = json.loads(out.read_text())
    assert js["ok"] is False
    assert any("beyond any lens" in w and "p1" in w for w in js["warnings"]), js["warnings"]
    text = capsys.readouterr()
    shown = text.out + text.err
    found = [m for m in js["marks"] if m["found"]]
    assert len(found) == len(ms)
    far = 0
    for m in found:
        a = np.deg2rad(m["angle_deg"])
        t = min(ms, key=lambda s: abs(angle_error(a, s.angle_rad)))
        z = angle_error(a, t.angle_rad) / np.deg2rad(m["angle_u_deg"])
        far += abs(z) > 3
        if abs(z) > 3:
            assert m["lens_limited"], (m["index"], z)
            assert f"mark {m['index']}: NOT OK" in shown, (m["index"], shown)
    assert far  # the control is one: some angle is beyond 3 u (u cannot cover this lens)


def test_a_sign_open_k1_is_fitted_free_when_that_gives_the_smaller_u(monkeypatch):
    """The default twin of tests/align/test_lens_crlb.py (issue 18, failure mode 5): one
    300 px mark under an undeclared barrel lens whose k1 sign the mark does not determine.
    The angle is read with k1 fitted free (the estimator with the smaller u: min u over the
    two readings, from the lines' information alone), reported as ``free`` and not as an
    applied lens, and its u holds the lens terms' own (``lens_fit``,
    :func:`align.lens.lens_angle_var`); the mark's error is within 3 u, and so is the same
    mark's without a lens."""
    k1_only = LensRanges(k1=0.3, k2=0.0, p=0.0, aspect=0.0, pp_px=0.0)
    rng = np.random.default_rng(4)  # a mark of the held-out sweep whose k1 sign is open
    mark = MarkSpec(rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(-150, 150), 300.0, 4.0,
                    centre_t_px=rng.uniform(-80, 80))
    spec = ImageSpec(marks=(mark,), width=640, height=480, seed=4, supersample=4,
                     camera=CameraGeometry(focal_px=1024.0, k1=-0.3),
                     full_well_e=full_well_for_snr(40, -0.6))
    s = render_marks(spec, with_crlb=False)
    ms = measure_frame(s.image.astype(float), None, expect_one=True).items
    r = finish_mark(ms[0], camera_lens(ms, None, k1_only), 0, "image", 0)
    k1 = r.lens["parameters"]["k1"]
    assert k1["estimator"] == "free" and not k1["applied"], k1
    assert "lens_fit" in r.u_terms and "lens_k1_small" not in r.u_terms, r.u_terms
    assert abs(angle_error(r.angle_rad, s.truth.marks[0].image_angle_rad)) <= 3 * r.angle_u_rad
    lines = lens_lines(ms)
    R = np.hypot(639, 479) / 2
    sol, (d,) = lens_mod.solve_lens(lines, R, k1_only)
    assert sol.free[0]
    # The chosen estimator's variance is what the mark carries (its lens terms in its u).
    assert lens_mod.lens_angle_var(sol, d) <= r.angle_u_rad**2
    monkeypatch.setattr(lens_mod, "FREE_CANDIDATES", ())
    carried, (dc,) = lens_mod.solve_lens(lines, R, k1_only)
    assert not any(carried.free) and not carried.applied[0]
    assert lens_mod.lens_angle_var(sol, d) < lens_mod.lens_angle_var(carried, dc)
    # Without a lens (the same mark and noise, k1 still free over its range): the free fit's
    # u covers its own scatter (the held-out sweep's k1 = 0 half).
    s0 = render_marks(replace(spec, camera=CameraGeometry(focal_px=1024.0)), with_crlb=False)
    ms0 = measure_frame(s0.image.astype(float), None, expect_one=True).items
    r0 = finish_mark(ms0[0], camera_lens(ms0, None, k1_only), 0, "image", 0)
    assert abs(angle_error(r0.angle_rad, s0.truth.marks[0].image_angle_rad)) <= 3 * r0.angle_u_rad
