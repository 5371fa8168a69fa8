"""Independent user 14: a calibration lab's quality engineer signs off a platform's alignment.

Written from README.md, docs/, align/schemas/ and ``--help`` only; the sessions come from
the generator in ``user14_inputs.py`` (physics rendered with its own conventions, taken from
docs/concepts.md), with effects the tool is not told about: camera A rolled on its mount, the
table axis not level, a ring-laser scale error, an accelerometer bias drifting with the
temperature during the session, a bent scribe mark, one image out of focus, camera B's lens
never calibrated.

What a signer needs: a result that says ok (exit 0) lies within 3 u of the truth; a PASS is
right; the budget adds up to u²; ``align plan``'s predicted u is what the measurement it
advises then gives.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import user14_inputs as gen  # noqa: E402

Z_MAX = 3.5  # |error| / u of a correct result over a sweep of a few seeds x six angles

HERE = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ENV = dict(os.environ, PYTHONPATH=HERE, PYTHONDONTWRITEBYTECODE="1")
HAVE_REAL = os.path.isdir(gen.CHESS)
needs_real = pytest.mark.skipif(not HAVE_REAL, reason="no real chessboard photos beside the clone")

# the marks placed off the principal point, where the lens bends them
OFF = {"x_A": (0, 150), "x_Ar": (0, -140), "y_B": (0, 150), "y_Br": (0, -150),
       "z_A": (200, 0), "z_Ar": (-210, 0), "z_B": (200, 0), "z_Br": (-200, 0)}
CLEAN = dict(roll_A_arcsec=0.0, level_arcsec=(0.0, 0.0), gonio_scale_ppm=0.0,
             bias_drift_ug=0.0, lens_b_model=True)
LAB = dict(roll_A_arcsec=45.0, level_arcsec=(18.0, -12.0), gonio_scale_ppm=80.0,
           bias_drift_ug=60.0, bent_px=1.5, defocus_blur=4.0, lens_b_model=False)


def run(folder, spec, *extra):
    """Write a session and run ``align run`` on it as a user does (a subprocess)."""
    truth = gen.write_session(str(folder), spec)
    out = os.path.join(str(folder), "result.json")
    p = subprocess.run([sys.executable, "-m", "align", "run", str(folder), "--json", out,
                        "-q", "--force", *extra], capture_output=True, text=True, env=ENV)
    assert p.returncode in (0, 2), p.stderr[-2000:]
    with open(out) as f:
        res = json.load(f)
    assert (p.returncode == 0) == bool(res["ok"]), "exit status and the JSON's ok disagree"
    return p, res, truth


def errors(res, truth):
    """Per angle (value, u, truth, z) [″]."""
    table = {}
    for n in gen.E_NAMES:
        i, j = gen.e_index(n)
        v, u = res["misalignment_arcsec"][i][j], res["misalignment_u_arcsec"][i][j]
        table[n] = (v, u, truth[n], (v - truth[n]) / u)
    return table


def plan(result_json, folder):
    out = os.path.join(str(folder), "plan.json")
    p = subprocess.run([sys.executable, "-m", "align", "plan", result_json, "--json", out,
                        "--force", "-q"], capture_output=True, text=True, env=ENV)
    assert p.returncode == 0, p.stderr[-2000:]
    with open(out) as f:
        return json.load(f)


# --------------------------------------------------------------------------- default run
def test_counter_log_with_scale_error_earth_rate_and_wander():
    """The ring laser's 80 ppm scale error, a 1 % wandering table and the Earth rate: the
    face angles from my counter log are within 3.5 u of the azimuths I put in."""
    from align import measure_log

    rng = np.random.default_rng(14)
    E = gen.truth_matrix(rng)
    rows = gen.gonio_rows(E, rng, revolutions=60, scale_error_ppm=80.0)
    run_ = measure_log(rows, 4, latitude_rad=50.45 * gen.DEG)
    S = gen.axes(E)
    az_y = np.arctan2(S[1, 1], S[1, 0])
    az_x = np.arctan2(S[0, 1], S[0, 0])
    az = [np.pi, az_y, az_x, -0.5 * np.pi + 25.0 * gen.ARCSEC]
    want = [az[0] - az[1], az[1] - az[2], az[2] - az[3], 2 * np.pi - (az[0] - az[3])]
    got = np.asarray(run_.angles.angles_rad)
    u = np.asarray(run_.angles.u_rad)
    z = (got - want) / u
    assert np.all(u < 1.0 * gen.ARCSEC), u / gen.ARCSEC
    assert np.all(np.abs(z) < Z_MAX), (z, (got - want) / gen.ARCSEC)


# --------------------------------------------------------------------------- slow sweeps
@needs_real
@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3, 4])
def test_lab_session_ok_is_within_u_and_pass_is_right(tmp_path, seed):
    """Every undeclared lab effect at once, with static poses: when the tool says ok, E is
    within 3.5 u of the truth; a PASS has the truth inside the tolerance; the budget's shares
    add up to u²; camera A's roll is found."""
    spec = gen.Session(seed=seed, tolerance_arcsec=150.0, **LAB)
    p, res, truth = run(tmp_path / "s", spec)
    table = errors(res, truth)
    if res["ok"]:
        bad = {n: t for n, t in table.items() if abs(t[3]) > Z_MAX}
        assert not bad, f"ok result beyond {Z_MAX} u: {bad}"
    disp = res["disposition"]
    if disp["verdict"] == "PASS":
        assert all(abs(t[2]) <= 150.0 for t in table.values())
    for n, a in res["budget"]["angles"].items():
        s = sum(c["u2_arcsec2"] for c in a["contributions"])
        assert s == pytest.approx(a["u_arcsec"] ** 2, rel=0.01), n
        assert a["u_arcsec"] == pytest.approx(table[n][1], rel=1e-6), n
    names = [e["name"] for e in res["effects"]]
    assert "camera_roll[A]" in names, names


@needs_real
@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_cameras_without_static_poses_refuse_the_uncalibrated_lens(tmp_path, seed):
    """No static poses: the cameras carry E_xZ ... E_zY. Camera B's lens nobody calibrated,
    marks 150-210 px off the centre: the run is not ok and names the lens-limited images;
    camera A's angles (calibrated lens, roll undeclared, a bent mark, ...) stay within u."""
    spec = gen.Session(seed=seed, with_static=False, mark_offsets_px=OFF,
                       **dict(LAB, level_arcsec=(0.0, 0.0)))
    p, res, truth = run(tmp_path / "s", spec)
    assert not res["ok"] and p.returncode == 2
    assert any("lens-limited" in q for q in res["problems"]), res["problems"]
    table = errors(res, truth)
    for n in ("E_xY", "E_yX", "E_xZ", "E_zX"):
        assert abs(table[n][3]) < Z_MAX, (n, table[n])


@needs_real
@pytest.mark.slow
def test_plan_another_image_predicts_the_u_obtained(tmp_path):
    """Cameras carry the Z angles (no static poses): ``align plan`` offers another image;
    I take it with my generator (same session, one more image of that mark) and the u of the
    critical angle lands within 3 of the plan's stated prediction noise (and 5 %). My lab
    knows its reference face's azimuth to 1″ and declares it (without static poses there is
    no azimuth datum, and the docs say the offset is otherwise carried over ±60″, which then
    sets the critical angle — reviewer's note, stop 32: added when the fusion began to carry
    it; the user's generator writes ``reference_offset_u_arcsec`` for that)."""
    spec = dict(with_static=False, mark_offsets_px=OFF, gonio_ref_u_arcsec=1.0, **CLEAN)
    p, res, truth = run(tmp_path / "a", gen.Session(seed=1, **spec))
    assert res["ok"], res["problems"]
    pl = plan(os.path.join(str(tmp_path / "a"), "result.json"), tmp_path)
    # Reviewer's edit (stop 33): a kept calibration now carries its principal point's
    # stability (0.5 px by default), shared by every image of a camera: camera B's lens sets
    # E_zY (14.6 of 16.0″), which a reversed view cancels and another image does not, so the
    # plan ranks the reversed view first (5.57″). My generator takes another image: the
    # plan's best image option is the one taken and its prediction checked.
    best = next(o for o in pl["options"] if o["kind"] == "image")
    assert pl["options"][0]["u_after_arcsec"] <= best["u_after_arcsec"]
    key = f'{best["detail"]["housing"]}_{best["detail"]["view"]}'
    p2, res2, truth2 = run(tmp_path / "b", gen.Session(seed=1, image_repeat={key: 1}, **spec))
    assert res2["ok"], res2["problems"]
    u_obt = errors(res2, truth2)[pl["target"]][1]
    pred, noise = best["u_after_arcsec"], best["u_after_noise_arcsec"]
    assert abs(u_obt - pred) < max(3 * noise, 0.05 * pred), (u_obt, pred, noise)
    assert u_obt < pl["u_before_arcsec"]


@needs_real
@pytest.mark.slow
def test_plan_static_poses_repeated_predicts_the_u_obtained(tmp_path):
    """The full session: the plan advises the static poses repeated; twice the samples per
    pose gives the u it predicted (within 3 of its stated noise, and 5 %)."""
    p, res, truth = run(tmp_path / "a", gen.Session(seed=1, **CLEAN))
    assert res["ok"], res["problems"]
    pl = plan(os.path.join(str(tmp_path / "a"), "result.json"), tmp_path)
    best = pl["options"][0]
    assert best["kind"] == "static", best
    p2, res2, truth2 = run(tmp_path / "b", gen.Session(seed=1, static_samples=200, **CLEAN))
    u_obt = errors(res2, truth2)[pl["target"]][1]
    pred, noise = best["u_after_arcsec"], best["u_after_noise_arcsec"]
    assert abs(u_obt - pred) < max(3 * noise, 0.05 * pred), (u_obt, pred, noise)


# --------------------------------------------------------------------------- defects found
def camera_session(seed, **kw):
    """Goniometer + tumble + cameras A, B with calibrated lenses, no static poses."""
    d = dict(CLEAN, with_static=False, mark_offsets_px=OFF)
    d.update(kw)
    return gen.Session(seed=seed, **d)


@needs_real
@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_undeclared_roll_without_reversal_views_is_not_a_silent_wrong_answer(tmp_path, seed):
    p, res, truth = run(tmp_path / "s", camera_session(seed, roll_A_arcsec=40.0,
                                                       views=("A", "B")))
    table = errors(res, truth)
    if res["ok"]:
        bad = {n: round(t[3], 2) for n, t in table.items() if abs(t[3]) > Z_MAX}
        assert not bad, f"ok (exit {p.returncode}) with E beyond {Z_MAX} u: {bad}"


@needs_real
@pytest.mark.slow
def test_pass_is_right_with_an_undeclared_roll_and_no_reversal_views(tmp_path):
    spec = camera_session(1, roll_A_arcsec=40.0, views=("A", "B"), tolerance_arcsec=150.0,
                          tolerance_angles={"E_xZ": 60.0})
    p, res, truth = run(tmp_path / "s", spec)
    assert abs(truth["E_xZ"]) > 60.0  # the unit truly does not conform
    assert res["disposition"]["verdict"] != "PASS", res["disposition"]["reason"]


@needs_real
@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_reference_face_offset_without_azimuth_datum_is_not_silent(tmp_path, seed):
    p, res, truth = run(tmp_path / "s", camera_session(seed, gonio_ref_offset_arcsec=30.0))
    table = errors(res, truth)
    if res["ok"]:
        bad = {n: round(t[3], 1) for n, t in table.items() if abs(t[3]) > Z_MAX}
        assert not bad, f"ok (exit {p.returncode}) with E beyond {Z_MAX} u: {bad}"


@needs_real
@pytest.mark.slow
def test_pass_is_right_with_a_reference_face_offset_and_no_azimuth_datum(tmp_path):
    spec = camera_session(1, gonio_ref_offset_arcsec=30.0, tolerance_arcsec=150.0,
                          tolerance_angles={"E_xY": 100.0})
    p, res, truth = run(tmp_path / "s", spec)
    assert abs(truth["E_xY"]) > 100.0  # the unit truly does not conform
    assert res["disposition"]["verdict"] != "PASS", res["disposition"]["reason"]
