"""Tilt: the exact form against truth, and the paper's regularised roll's bias."""

from __future__ import annotations

import numpy as np
import pytest

from align.tilt import gravity_from_angles, roll_pitch


def test_exact_form_recovers_angles_everywhere():
    rng = np.random.default_rng(0)
    roll = rng.uniform(-np.pi, np.pi, 100000)
    pitch = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6, 100000)
    G = gravity_from_angles(roll, pitch) * 9.81
    r, p = roll_pitch(G)
    assert np.max(np.abs(np.angle(np.exp(1j * (r - roll))))) < 1e-12
    assert np.max(np.abs(p - pitch)) < 1e-12


def test_paper_regularised_roll_is_biased_as_predicted():
    roll, pitch = np.deg2rad(45.0), np.deg2rad(45.0)
    G = gravity_from_angles(np.array([roll]), np.array([pitch]))
    r_paper, _ = roll_pitch(G, method="paper", mu=0.001)
    r_exact, _ = roll_pitch(G)
    predicted = -(0.001 / 2) * np.tan(pitch) ** 2 * np.tan(roll)
    assert r_paper[0] - roll == pytest.approx(predicted, rel=0.01)  # -5e-4 rad
    assert abs(r_exact[0] - roll) < 1e-12


def test_x_axis_vertical_is_defined():
    r, p = roll_pitch(np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]]))
    assert np.all(r == 0) and np.allclose(p, [-np.pi / 2, np.pi / 2])
    r2, _ = roll_pitch(np.array([[1.0, 0.0, 0.0]]), method="paper")
    assert np.isfinite(r2).all()
    with pytest.raises(ValueError):
        roll_pitch(np.ones((1, 3)), method="guess")


# --------------------------------------------------------------- readings through a model

def _model(**kw):
    from align.calibration import TriadModel

    base = dict(k=np.array([2.0, -1.5, 1.8]), beta=np.array([1e-4, -2e-4, 3e-4]),
                bias=np.array([1e-3, -2e-3, 5e-4]), t_ref=40.0)
    return TriadModel(**{**base, **kw})


def _readings(model, a, t=None):
    """Outputs u that ``model`` maps back to specific force ``a`` (N, 3) [g] (its forward
    model: u = k * R (a + bias + drift dt), no k2)."""
    from align.calibration import r_matrix
    from axisbase.table import Table

    dt = 0.0 if t is None else (t - model.t_ref)[:, None]
    u = ((a + model.bias + dt * model.drift) @ r_matrix(model.beta).T) * model.k
    data = {"ux": u[:, 0], "uy": u[:, 1], "uz": u[:, 2], **({} if t is None else {"t": t})}
    return Table(None, None, data, 2)


def test_readings_without_time_get_none_and_a_drift_model_says_what_it_used():
    from align.tilt import tilt_of_readings

    rng = np.random.default_rng(5)
    roll, pitch = rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50)
    a = gravity_from_angles(roll, pitch)
    m = _model()
    res = tilt_of_readings(m, _readings(m, a))
    assert res.t is None and res.warnings == ()
    assert np.allclose(res.roll, roll, atol=1e-12) and np.allclose(res.pitch, pitch, atol=1e-12)
    rows = res.csv_text().splitlines()
    assert rows[0] == "t,roll_deg,pitch_deg" and all(r.startswith(",") for r in rows[1:])
    assert np.allclose(np.loadtxt(rows[1:], delimiter=",", usecols=(1, 2)),
                       np.rad2deg(np.column_stack([roll, pitch])), atol=1e-6)
    drifting = _model(drift=np.array([1e-6, 0, 0]))
    res = tilt_of_readings(drifting, _readings(drifting, a))
    assert len(res.warnings) == 1 and "reference time 40 s" in res.warnings[0]
    # with times, the drift is applied and nothing is said
    t = np.linspace(0, 100, 50)
    res = tilt_of_readings(drifting, _readings(drifting, a, t))
    assert res.warnings == () and np.array_equal(res.t, t)
    assert np.allclose(res.roll, roll, atol=1e-9)


@pytest.mark.parametrize("scale, far", [(1.0, 0), (1.09, 0), (1.11, 50), (0.0, 50)])
def test_readings_far_from_one_g_are_counted_in_a_warning(scale, far):
    from align.tilt import tilt_of_readings

    rng = np.random.default_rng(6)
    a = gravity_from_angles(rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50)) * scale
    m = _model()
    res = tilt_of_readings(m, _readings(m, a))
    assert res.far_from_1g == far and res.to_dict()["far_from_1g"] == far
    assert len(res.warnings) == (1 if far else 0)
    if far:
        assert res.warnings[0].startswith(f"{far} of 50 readings")
        assert res.to_dict()["warnings"] == list(res.warnings)


def test_a_platform_calibration_gives_the_platform_roll_and_pitch():
    """Readings of a triad misaligned by ~5' on a platform at known roll/pitch: through the
    platform calibration tilt gives the platform's angles (as apply --tilt does, the same
    numbers); through the triad model alone they are off by about the misalignment."""
    from align.apply import PlatformCalibration, apply_to_readings
    from align.calibration import r_matrix
    from align.fusion import axes_from
    from align.tilt import tilt_of_readings

    rng = np.random.default_rng(7)
    roll, pitch = rng.uniform(-0.5, 0.5, (2, 60))
    a_p = gravity_from_angles(roll, pitch)
    m = _model()
    e6 = rng.normal(0, 300 / 206264.8, 6)                    # ~5' misalignment
    pc = PlatformCalibration(m, e6, np.eye(6) * 1e-12)
    R = r_matrix(m.beta)
    # w = R a_c = |r_i| s_i . a_P  (the model apply inverts)
    a_c = np.linalg.solve(R, (np.linalg.norm(R, axis=1) * (a_p @ axes_from(e6).T)).T).T
    tab = _readings(m, a_c)
    res = tilt_of_readings(pc, tab)
    assert res.frame == "platform" and res.to_dict()["frame"] == "platform"
    assert np.allclose(res.roll, roll, atol=1e-12) and np.allclose(res.pitch, pitch, atol=1e-12)
    ap = apply_to_readings(pc, tab, tilt=True)
    assert np.array_equal(ap.roll, res.roll) and np.array_equal(ap.pitch, res.pitch)
    triad = tilt_of_readings(m, tab)
    assert triad.frame == "triad"
    assert np.abs(triad.roll - roll).max() > 100 / 206264.8   # the misalignment, not noise


def test_what_the_reader_said_of_the_file_reaches_the_json(tmp_path, caplog):
    """A readings file whose plain ``t`` is in ms (read as s: a sample every 10 s) gets the
    reader's warning ("were the times in ms?") among the result's warnings, so ``align tilt
    --json`` carries it (it was only logged); the same file with ``t [ms]`` gets none."""
    from align.tilt import read_readings_noted, tilt_of_readings

    rng = np.random.default_rng(8)
    m = _model()
    a = gravity_from_angles(rng.uniform(-1, 1, 40), rng.uniform(-1, 1, 40))
    tab = _readings(m, a)
    u = np.column_stack([tab["ux"], tab["uy"], tab["uz"]])
    rows = [f"{10 * k}," + ",".join(repr(float(v)) for v in u[k]) for k in range(40)]
    said = {}
    for head in ("t", "t [ms]"):
        f = tmp_path / "r.csv"
        f.write_text(f"{head},ux,uy,uz\n" + "\n".join(rows) + "\n")
        read_tab, read = read_readings_noted(f)
        said[head] = tilt_of_readings(m, read_tab, read_warnings=read).to_dict()["warnings"]
    assert len(said["t"]) == 1 and "were the times in ms?" in said["t"][0]
    assert said["t [ms]"] == []
    assert not [r for r in caplog.records if "were the times" in r.getMessage()]  # said once


def test_triad_frame_is_z_along_accelerometer_z_y_in_the_z_y_plane():
    """docs/commands/tilt.md: through a triad calibration, roll and pitch are those of the
    frame of R(β) (eq. 5, upper triangular): z along accelerometer z, y in the plane of
    accelerometers z and y. A triad built in such a lab frame (x tilted 1 mrad toward y and
    0.8 mrad out of the x-y plane, y 0.6 mrad toward -z), calibrated from 18 noisy poses: tilt
    of exact readings is the lab's within 5 x the calibration's bound (roll and pitch move at
    most 1 rad per unit of each of the nine parameters' normalised errors); the frame with x
    along accelerometer x is ~1 mrad away (the contrast: the test can fail)."""
    from align.calibration import calibrate, poses_from_samples
    from align.tilt import tilt_of_readings
    from axisbase.table import Table

    rng = np.random.default_rng(11)
    S = np.array([[1.0, 1e-3, 8e-4], [0.0, 1.0, -6e-4], [0.0, 0.0, 1.0]])
    S /= np.linalg.norm(S, axis=1, keepdims=True)
    k, o = np.array([2.0, -1.5, 1.8]), np.array([2e-3, -1e-3, 3e-3])
    d = rng.normal(size=(18, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    pid = np.repeat(np.arange(18), 40)
    u = ((d @ S.T) * k + o)[pid] + rng.normal(0, 2e-5, (len(pid), 3))
    cal = calibrate(poses_from_samples(pid, u, pid * 3.0), signs=(1, -1, 1))
    roll, pitch = rng.uniform(-0.6, 0.6, (2, 30))
    g = gravity_from_angles(roll, pitch)                      # in the lab frame
    ur = (g @ S.T) * k + o
    res = tilt_of_readings(cal.model, Table(None, None, {"ux": ur[:, 0], "uy": ur[:, 1],
                                                         "uz": ur[:, 2]}, 2))
    m = cal.model
    bound = np.sqrt(np.sum(m.u_per_axis("bias") ** 2) + np.sum(m.u_per_axis("beta") ** 2)
                    + np.sum((m.sensitivity_u() / np.abs(m.sensitivity())) ** 2))
    err = max(np.abs(res.roll - roll).max(), np.abs(res.pitch - pitch).max())
    assert err < 5 * bound, (err, bound)
    # x along accelerometer x, y in the x-y plane: Gram-Schmidt from s_x, s_y
    ex = S[0]
    ey = S[1] - (S[1] @ ex) * ex
    ey /= np.linalg.norm(ey)
    fx = np.array([ex, ey, np.cross(ex, ey)])
    rx, px = roll_pitch(g @ fx.T)
    assert max(np.abs(res.roll - rx).max(), np.abs(res.pitch - px).max()) > 5e-4


@pytest.mark.parametrize(("temp", "warned"), [(25.0, True), (300.0, False), (330.0, False)])
def test_readings_on_another_temperature_scale_than_the_calibration_are_warned(temp, warned):
    """A calibration with a temperature model referred to 298.15 K: readings at 25 (°C written
    as a plain number) are said to be on another scale; at 300 K or 330 K nothing is said."""
    from align.tilt import tilt_of_readings
    from axisbase.table import Table

    m = _model(temp_coeff=np.array([3e-5, 0, 0]), temp_ref=298.15)
    tab = _readings(m, gravity_from_angles(np.zeros(5), np.zeros(5)))
    tab = Table(None, None, {**tab.data, "temp": np.full(5, temp)}, 2)
    said = [w for w in tilt_of_readings(m, tab).warnings if "another" in w or "°C" in w]
    assert bool(said) is warned, said
