"""Issue 18's loose ends (stop 32's "noticed and left"): each a place where the tool said
something wrong or left a term out."""

from __future__ import annotations

import inspect
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import align.plan_carried as plan_carried
from align.fusion.diagnosis import disagreement_from_dict
from align.lens import LensRanges
from align.lens_design import LineGeometry
from align.lens_terms import check_camera, lens_or_bends, lone_departures
from align.marks import measure_image
from align.session import load_session, run_session
from align.warnings import session_warnings
from imaging.lens import distort_points
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks
from synth.session import SessionSpec, write_session
from tests.conftest import ARCSEC, angle_error


def test_plan_carried_defaults_are_not_shared_mutable_objects():
    """``declared: Mapping = {}`` was one dict shared by every call: a caller that mutated what
    it got back (or a later edit of the function) would change every later call's default."""
    for name, f in inspect.getmembers(plan_carried, inspect.isfunction):
        if f.__module__ != plan_carried.__name__:
            continue
        for p in inspect.signature(f).parameters.values():
            assert not isinstance(p.default, (dict, list, set)), (name, p.name)


def _offset_scene(seed: int, k1: float):
    """Three marks 150-250 px out in a 640x480 frame through a radial lens (k1 OpenCV's at
    f 530 px: -0.27 is the real chessboard camera's), and their truths."""
    cam = CameraGeometry(focal_px=530.0, k1=k1)
    rng = np.random.default_rng([seed, 7])

    def at(x, y, a_deg, length):
        a = np.deg2rad(a_deg)
        return MarkSpec(a, x * np.sin(a) + y * np.cos(a), length, 4.0,
                        centre_t_px=x * np.cos(a) - y * np.sin(a))

    marks = (at(rng.uniform(-200, -120), rng.uniform(-150, -90), rng.uniform(0, 20), 200.0),
             at(rng.uniform(120, 200), rng.uniform(90, 150), rng.uniform(60, 80), 180.0),
             at(rng.uniform(-200, -120), rng.uniform(90, 150), rng.uniform(-80, -60), 180.0))
    spec = ImageSpec(marks=marks, width=640, height=480, camera=cam, seed=seed,
                     full_well_e=full_well_for_snr(40, -0.6), supersample=3)
    s = render_marks(spec, with_crlb=False)
    return s.image, s.truth.marks


def _offset_z(results, truths) -> list[float]:
    """Each found mark's offset error over its u (the truth with the nearest angle; a fit
    either side of the +-90 deg wrap negates the offset)."""
    out = []
    for r in results:
        if not r.found:
            continue
        t = min(truths, key=lambda t: abs(angle_error(r.angle_rad, t.image_angle_rad)))
        e = min(r.offset_px - t.image_offset_px, r.offset_px + t.image_offset_px, key=abs)
        out.append(e / r.offset_u_px)
    return out


def test_offset_u_carries_the_lens_as_the_angle_does():
    """An undeclared k1 -0.27 lens, three marks 150-250 px out: the angles' u carried the lens
    the lines leave undetermined (|z| <= 0.06), the offsets' did not: seed 0's offsets were
    10.2 u off (0.007 px stated; 6 seeds: max |z| 2.1-10.2). Now the lens's share is in the
    offset's u (named ``offset_lens_u_px``) and covers the error."""
    img, truths = _offset_scene(0, -0.27)
    res = [r for r in measure_image(img, "lens.png") if r.found]
    z = _offset_z(res, truths)
    assert len(z) == 3 and np.abs(z).max() <= 3.0, np.round(z, 2)
    assert all(0 < r.offset_lens_u_px <= r.offset_u_px for r in res)
    # Shared by the frame's marks: a family's pitch takes the lens from their moves together
    # and its members' own offsets without it.
    assert all(r.offset_own_u_px < 0.1 * r.offset_lens_u_px for r in res)


def test_offset_u_of_a_declared_distortion_free_camera_has_no_lens_share():
    """Control: declared distortion-free, the offset's u is the line fit's alone."""
    img, truths = _offset_scene(1, 0.0)
    res = [r for r in measure_image(img, "flat.png", ranges=LensRanges.none()) if r.found]
    assert len(res) == 3
    assert all(r.offset_lens_u_px == 0.0 and r.offset_u_px == r.offset_own_u_px for r in res)
    assert np.abs(_offset_z(res, truths)).max() <= 4.0


@pytest.mark.slow
@pytest.mark.parametrize("k1", [-0.27, 0.1])
def test_offset_u_carries_the_lens_over_seeds(k1):
    """20 frames of three off-centre marks through an undeclared lens: every offset within
    3 u (before: 32 and 28 of 60 beyond, up to 25.8 u at k1 -0.27 and 46.7 u at +0.1). The u
    is the lens's undetermined range, so the errors sit far inside it (RMS z 0.11, 0.18, as
    the angles' do); the bound is the standard's."""
    z = []
    for seed in range(20):
        img, truths = _offset_scene(seed, k1)
        z += _offset_z([r for r in measure_image(img, f"lens{seed}.png") if r.found], truths)
    assert len(z) >= 57 and np.abs(z).max() <= 3.0, np.round(z, 2)


def _straight(x: float, y: float, a_deg: float, dlam: np.ndarray, seed) -> LineGeometry:
    """A straight 220 px mark through (x, y) px from the centre of a 640x480 frame at
    ``a_deg``, imaged through a lens ``dlam`` off its calibration, centres +- 0.05 px."""
    a = np.radians(a_deg)
    q = np.array([x, y]) + np.outer(np.linspace(-110, 110, 220), [np.cos(a), -np.sin(a)])
    noise = np.random.default_rng(seed).normal(0, 0.05, q.shape)
    return LineGeometry(distort_points(q, dlam, 400.0) + noise, np.full(len(q), 0.05), None)


def _three(ks, seed):
    """Three straight 220 px marks 200-250 px out, each through the calibration plus its own
    lens change (``ks``), checked against the exact calibration (tiny u)."""
    cov = np.diag(np.full(7, 1e-8))
    lines = [_straight(-180, -130, 10, ks[0], [seed, 0]),
             _straight(170, 120, 70, ks[1], [seed, 1]),
             _straight(200, -100, -30, ks[2], [seed, 2])]
    p, _, designs = check_camera(lines, np.zeros(7), cov, 400.0)
    return p, designs, cov


def test_a_departure_the_other_marks_share_is_not_one_mark_bent():
    """One lens whose k1 moved 0.002 beyond its calibration (at the half-diagonal) bows all
    three marks: jointly they depart (p < 1e-3) though none does on its own, the path on
    which ``lone_departures`` decides. Leaving one out, the other two no longer depart, and
    that mark was named bent, the calibration kept (4 of the 20 such seeds of 40; 5 of 22
    with k1 0.003 too) — the others bowing the same way unchecked. Now the others' bow is
    tested against the change that mark calls for (as a lens change): 0 of 20. Control: a
    bent mark (the bow of k1 0.01 on mark 1 alone) beside two straight ones is still named,
    40 of 40."""
    k = np.zeros(7)
    k[0] = 0.002
    path = named = 0
    for seed in range(40):
        p, designs, cov = _three([k, k, k], seed)
        if p < 1e-3 and lens_or_bends(designs, cov) is None:
            path += 1
            named += bool(lone_departures(designs, cov))
    assert path >= 15 and named == 0, (path, named)
    bent = np.zeros(7)
    bent[0] = 0.01
    for seed in range(40):
        p, designs, cov = _three([np.zeros(7), bent, np.zeros(7)], seed)
        assert p < 1e-3 and lone_departures(designs, cov) == (1,), seed


def _static_rows(shift_x_pair_y: float, e_yx: float, seed: int):
    """A static block's rows as the fusion whitens them: levelled poses (Z up, four table
    angles) and the gimbal poses X up/down, Y up/down, each reading the two accelerometers
    across its up; a solve with the angle each reads (±E with the pose's sign) and a bias per
    accelerometer. Into the data: E_yX moved by ``e_yx`` on the gimbal poses (what creep
    does: opposite in up and down) and the X pair's y readings shifted together by
    ``shift_x_pair_y`` [g] (what a tilted base does). Noise 1e-6 g; the biases known to
    1e-6 g from the tumble (three rows after the static ones, as the fusion's ellipsoid
    block gives them)."""
    poses = [("L0", "+Z"), ("L90", "+Z"), ("L180", "+Z"), ("L270", "+Z"), ("Xup", "+X"),
             ("Xdn", "-X"), ("Yup", "+Y"), ("Ydn", "-Y")]
    meta = [{"pose": p, "up": up, "housing": h} for p, up in poses for h in "xyz"
            if h != up[1].lower()]
    u = np.full(len(meta), 1e-6)
    rng = np.random.default_rng(seed)
    # Columns: the angle each (up axis, housing) reads, signed by the pose; a bias per housing.
    angles = sorted({(m["up"][1], m["housing"]) for m in meta})
    J = np.array([[(1.0 if m["up"][0] == "+" else -1.0) * ((m["up"][1], m["housing"]) == a)
                   for a in angles] + [float(m["housing"] == h) for h in "xyz"]
                  for m in meta]) / u[:, None]
    prior = np.hstack([np.zeros((3, len(angles))), np.eye(3) / 1e-6])
    J = np.vstack([J, prior])
    data = rng.normal(0, 1e-6, len(meta) + 3)
    for k, m in enumerate(meta):
        sign = 1.0 if m["up"][0] == "+" else -1.0
        if m["up"][1] == "X" and m["housing"] == "y":
            data[k] += shift_x_pair_y + sign * e_yx
    w = data / np.concatenate([u, np.full(3, 1e-6)])
    r = w - J @ np.linalg.lstsq(J, w, rcond=None)[0]
    return r, J, meta, u


def test_up_down_pairs_shifting_together_are_told_from_another_E():
    """An X up/down pair whose y readings moved together by 20 µg (a base tilted 4″ under the
    gimbal poses) is found, its shift within 4 u; the same pair's readings moved oppositely
    by 20 µg (another E_yX, as creep gives the static poses) is not: the fusion named the
    latter's cause and the former's alike "the triad moved between the measurements
    (creep)"."""
    from align.fusion.pairs import pair_shift
    for seed in range(3):
        r, J, meta, u = _static_rows(20e-6, 0.0, seed)
        found = pair_shift(r, J, np.arange(len(meta)), meta, np.diag(1 / u))
        assert found is not None and found.significant(1e-3), found
        got = {(a, h): (v, s) for a, h, v, s in found.shifts}
        v, s = got[("X", "y")]
        assert abs(v - 20e-6) < 4 * s, (v, s)
        r, J, meta, u = _static_rows(0.0, 20e-6, seed)
        assert not pair_shift(r, J, np.arange(len(meta)), meta,
                              np.diag(1 / u)).significant(1e-3)


def test_a_disagreement_with_shifting_pairs_does_not_suggest_creep():
    """The message: with the pairs' shift, their tilt or drift is named and creep is not;
    without it, creep as before."""
    from align.fusion.diagnosis import SourceDisagreement
    from align.fusion.pairs import PairShift
    d = SourceDisagreement("platform static", ("camera",), np.array([np.nan] * 5 + [2e-4]),
                           np.array([np.nan] * 5 + [1e-5]), 400.0, 6, 1e-80, 10.0, 12)
    assert "creep" in d.message()
    tilted = replace(d, pairs=PairShift((("X", "y", -8e-5, 1e-6),), 1e4, 4, 0.0))
    m = tilted.message()
    assert "creep" not in m.replace("nor creep", "") and "tilted under the gimbal poses" in m
    assert "X up/down y -16.5″" in m
    assert disagreement_from_dict(tilted.to_dict()).pairs == tilted.pairs


def _gimbal_session(tmp_path, seed: int, eff: dict):
    folder = tmp_path / f"s{seed}"
    write_session(folder, SessionSpec(seed=seed, effects=eff, undeclared=frozenset(eff)))
    return run_session(load_session(folder)).fusion


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_tilted_gimbal_poses_are_named_as_such_not_creep(tmp_path, seed):
    """The base under the gimbal (X/Y up/down) poses tilted 20″, -15″ (synth's
    ``gimbal_tilt_x/y``): the platform static poses are named, and the cause given was "the
    triad moved between the measurements (creep)". Now the pairs' common shift is named (the
    X pair's y readings by the y tilt, the Y pair's x by the x tilt, signs and sizes within
    30 %), and creep is not."""
    f = _gimbal_session(tmp_path, seed, {"gimbal_tilt_x": 20.0, "gimbal_tilt_y": -15.0})
    d = f.disagreement
    assert d is not None and "platform static" in (d.source, *d.also)
    assert d.pairs is not None and "creep" not in d.message().replace("nor creep", "")
    got = {(a, h): v / ARCSEC for a, h, v, _ in d.pairs.shifts}
    assert abs(got[("X", "y")] + 15.0) < 4.5 and abs(got[("Y", "x")] - 20.0) < 6.0, got


@pytest.mark.slow
def test_creep_is_still_named_creep(tmp_path):
    """Control: a triad that crept 30″ about Y between the images and the static poses moves
    each pair's readings oppositely: no pair shift, creep named."""
    d = _gimbal_session(tmp_path, 3, {"creep_y": 30.0}).disagreement
    assert d is not None and d.pairs is None and "(creep)" in d.message()


def test_not_ok_names_every_alternative_u_covers():
    """The calibration's NOT OK named the chosen effects and the one alternative that moves
    the worst parameter most: which that is changes with the seed (a pure bias drift of
    300 µg/h on user 14's tumble, seeds 1-3: "nonlinearity_k2 and scale_drift", "scale_drift
    and scale_asymmetry", "bias_drift and scale_drift" — the true effect named in 1 of 3).
    Now every alternative u covers is named, the largest first; one alternative reads as
    before."""
    from align.calibration.widen import Alternative, Widening

    names = tuple(f"p{i}" for i in range(12))

    def alt(effects, shift0):
        shift = np.zeros(9)
        shift[0] = shift0
        return Alternative(effects, "", 1.0, float("nan"), shift, np.zeros((9, 9)))

    alts = (alt("bias_drift", 40.0), alt("scale_drift", 100.0), alt("scale_asymmetry", 60.0))
    why = Widening((), names, np.ones(12), (), np.ones(12), alts).undetermined(
        ("nonlinearity_k2",), 28, "wander")
    assert why.startswith("calibration NOT OK: nonlinearity_k2 and scale_drift cannot be told "
                          "apart on this pose order, nor from scale_asymmetry, bias_drift "
                          "(u of p0 widened"), why
    one = Widening((), names, np.ones(12), (), np.ones(12), alts[:1]).undetermined(
        ("nonlinearity_k2",), 28, "wander")
    assert "nonlinearity_k2 and bias_drift cannot be told apart on this pose order (u of" in one


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_pure_bias_drift_is_among_what_the_not_ok_names(tmp_path, seed):
    """User 14's session generator, clean but for a bias drift of 300 µg/h (x; -0.7, 0.4 of
    it on y, z) through the tumble and the static poses: the calibration is not ok (its 14
    poses cannot tell the drift from K2, a scale drift, ...), and the NOT OK line now names
    bias_drift in every seed (before: seed 3 only; seeds 1, 2 named "nonlinearity_k2 and
    scale_drift", "scale_drift and scale_asymmetry")."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    import user14_inputs as gen

    spec = gen.Session(seed=seed, roll_A_arcsec=0.0, level_arcsec=(0.0, 0.0),
                       gonio_scale_ppm=0.0, bias_drift_ug=300.0, lens_b_model=True)
    gen.write_session(str(tmp_path), spec)
    res = run_session(load_session(tmp_path))
    lines = [w for w in session_warnings(res) if w.startswith("calibration NOT OK")]
    assert len(lines) == 1 and "bias_drift" in lines[0], lines
