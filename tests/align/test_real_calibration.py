"""The calibration loop on real recordings (../shared/data/real; skipped when absent).

Reference values come from each folder's README (datasheets, the authors' own calibrations);
they are comparisons, not truth. The residual structure that remains is asserted to be
reported, not hidden.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration import WARMUP, Poses, StaticSettings, calibrate, delta_g, find_static
from align.calibration import formats as F
from tests.conftest import real_folder

G0 = 9.80665


def _poses(t, u, settings):
    iv = find_static(t, u, settings)
    return Poses(np.array([x.mean for x in iv]), np.array([(x.start_s + x.end_s) / 2 for x in iv]),
                 None, np.array([x.sem for x in iv]), np.array([x.samples for x in iv]),
                 tuple(f"{x.start_s:.1f}s" for x in iv))


def test_xsens_scale_factors_and_warmup():
    t, u = F.xsens_text(real_folder("imu_tk-xsens") / "xsens_acc.mat")
    p = _poses(t, u, StaticSettings())  # the defaults
    assert 37 <= len(p.u) <= 40  # README: 1 initial + 37 hand-placed static intervals
    cal = calibrate(p)
    # Datasheet gains 415, 413, 415 counts/(m/s^2).
    assert np.allclose(cal.model.k / G0, [415, 413, 415], rtol=0.01)
    # The residual traces to a warming bias; adding it halves chi2/dof (4.1 -> 2.1) ...
    assert [e.name for e in cal.loop.effects] == [WARMUP]
    before = cal.loop.before.chi2 / cal.loop.before.dof
    after = cal.loop.after.chi2 / cal.loop.after.dof
    assert after < 0.6 * before
    # ... and what remains is an excess of scatter with no pattern left in orientation or
    # time (hand placement, settling): chi2/dof ~2 stays visible in the report.
    assert 1.5 < after < 3.0
    pattern = [t for t in cal.loop.structure_after.tests if t.name.startswith("corr")]
    assert min(t.p_value for t in pattern) > 0.01


@pytest.mark.parametrize("sensor,authors", [("ADXL355", (0.96276, 0.96732, 0.97079)),
                                            ("BMI160", (0.95418, 0.96061, 0.9501))])
def test_openaxes_scale_factors_match_the_authors(sensor, authors):
    path = real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv"
    t, u = F.openaxes(path, sensor)
    p = _poses(t, u, StaticSettings())
    cal = calibrate(p)
    # The authors' imu_tk calibration multiplies raw m/s^2 by ~0.96; ours is raw per g.
    assert np.allclose(cal.model.k, 9.81 / np.array(authors), rtol=0.003)
    dg = np.abs(delta_g(cal.model, p))
    assert np.sqrt(np.mean(dg**2)) < 3e-4  # 0.3 mg RMS over the placements
    if sensor == "BMI160":
        # The BMI160's bias warms during the session: found, and the residual drops 10x.
        assert WARMUP in [e.name for e in cal.loop.effects]
        assert cal.loop.after.rms < 0.2 * cal.loop.before.rms


def test_hassan_means_only_says_noise_unknown():
    v = F.mat_pose_means(real_folder("poses-49-hassan")
                         / "CalibrationOfLowCostTriaxialInertialSensors50.mat")
    p = Poses(v, np.arange(len(v), dtype=float), None, None, np.ones(len(v), int),
              tuple(str(i) for i in range(len(v))))
    cal = calibrate(p)
    assert not cal.noise_known and cal.loop.before.sigma is None
    assert np.allclose(cal.model.k, 1.0, atol=0.02)  # README: scale within ~2 %
    assert cal.residual_rms_g < 1.5e-3
    assert any("noise unknown" in line for line in cal.loop.summary_lines())


def test_mpu6050_offsets_match_the_repository():
    t, u = F.mpu6050(real_folder("mpu6050-tomisuarez") / "example_data_calibration.csv")
    p = _poses(t, u, StaticSettings())
    assert len(p.u) >= 10
    cal = calibrate(p)
    m = cal.model
    offset_counts = m.k * m.bias  # output at zero input, ~ K R b with R ~ 1
    # The repository's fitted biases (-712, +359, +1840) counts, opposite sign convention.
    assert np.allclose(np.abs(offset_counts), [712, 359, 1840], rtol=0.12)
    # Ten hand-placed poses leave beta_z weakly determined: the covariance says so.
    assert m.u_of("beta_z") > 10 * m.u_of("beta_x") or m.u_of("beta_z") > 5e-3
    # Ten poses (1 dof): the loop cannot test K3; the note says so, not the faces' reason
    # (these poses are not the six faces, where x³ = x).
    said = cal.nonlinearity["statement"]
    assert not cal.nonlinearity["k3_separable"]
    assert "cannot determine" in said and "x³ = x" not in said, said


SETTINGS = [StaticSettings(), StaticSettings(window_s=0.5), StaticSettings(window_s=1.0),
            StaticSettings(threshold=2.5), StaticSettings(threshold=4.0),
            StaticSettings(margin_s=0.0), StaticSettings(margin_s=0.3),
            StaticSettings(min_duration_s=1.0)]


@pytest.mark.slow
@pytest.mark.parametrize("name,expected", [("xsens", (WARMUP,)), ("ADXL355", ()),
                                           ("BMI160", (WARMUP, "nonlinearity_k2")),
                                           ("mpu6050", ())])
def test_effects_do_not_depend_on_detection_settings(name, expected):
    """The reported failure: an effect that appears or not with the segmentation. On every
    real recording the same effects are found with every detector setting."""
    if name == "xsens":
        t, u = F.xsens_text(real_folder("imu_tk-xsens") / "xsens_acc.mat")
    elif name == "mpu6050":
        t, u = F.mpu6050(real_folder("mpu6050-tomisuarez") / "example_data_calibration.csv")
    else:
        t, u = F.openaxes(real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv",
                          name)
    for st in SETTINGS:
        cal = calibrate(_poses(t, u, st))
        assert tuple(e.name for e in cal.loop.effects) == expected, st


def test_mat_files_read_by_the_cli_as_by_hand(tmp_path):
    """The .mat files as a user gives them to 'align calibrate' (Hassan's MATLAB v5 means,
    imu_tk's text '.mat'): the same numbers as the hand-written loaders."""
    import json

    from align.calibration import read_poses
    from align.cli import main

    hassan = real_folder("poses-49-hassan") / "CalibrationOfLowCostTriaxialInertialSensors50.mat"
    p, iv = read_poses(hassan)
    assert iv is None and np.array_equal(p.u, F.mat_pose_means(hassan))
    out = tmp_path / "h.json"
    assert main(["calibrate", str(hassan), "--units", "g", "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert js["scale_factor_unit"] == "g/g" and len(js["poses"]) == 49
    xsens = real_folder("imu_tk-xsens") / "xsens_acc.mat"
    p, iv = read_poses(xsens)
    t, u = F.xsens_text(xsens)
    assert len(iv) == len(find_static(t, u)) and np.array_equal(p.u[0], iv[0].mean)


def _recording(name: str, tmp_path):
    """(the pose route's poses, the CLI's arguments) of a real recording. Files the CLI reads
    as they are are given as they are; the rest (OpenAXES' ';' log with its device clock,
    the MPU-6050's four meta lines) as a user would convert them: t,ux,uy,uz in tmp_path."""
    openaxes = real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv"
    if name == "xsens":
        path = real_folder("imu_tk-xsens") / "xsens_acc.mat"
        return _poses(*F.xsens_text(path), StaticSettings()), [str(path)]
    if name == "hassan":
        path = real_folder("poses-49-hassan") / "CalibrationOfLowCostTriaxialInertialSensors50.mat"
        v = F.mat_pose_means(path)
        return (Poses(v, np.arange(len(v), dtype=float), None, None, np.ones(len(v), int),
                      tuple(str(i) for i in range(len(v)))), [str(path), "--units", "g"])
    if name == "imucal":
        folder = real_folder("imucal-ferraris")
        return (F.ferraris_session(folder)[0],
                [str(folder / "example_ferraris_session.csv"), "--rate", "102.4"])
    if name == "mpu6050":
        t, u = F.mpu6050(real_folder("mpu6050-tomisuarez") / "example_data_calibration.csv")
        unit = "counts"
    else:
        t, u = F.openaxes(openaxes, name)
        unit = "m/s2"
    path = tmp_path / f"{name}.csv"
    np.savetxt(path, np.column_stack([t, u]), delimiter=",", header="t,ux,uy,uz",
               comments="", fmt="%.9g")
    return _poses(t, u, StaticSettings()), [str(path), "--units", unit]


@pytest.mark.parametrize("name,expected", [
    pytest.param("xsens", (WARMUP,), marks=pytest.mark.slow),  # ~15 s on the shared host
    pytest.param("ADXL355", (), marks=pytest.mark.slow),
    pytest.param("BMI160", (WARMUP, "nonlinearity_k2"), marks=pytest.mark.slow),  # ~2 s
    ("mpu6050", ()), ("hassan", ()), ("imucal", ())])
def test_the_cli_keeps_the_pose_routes_results(name, expected, tmp_path):
    """`align calibrate <recording>` (the samples, their times: the bias walk the samples
    show is weighed) finds the effects of the pose route (the means alone, the reference) and
    no other; where both are ellipsoid fits of the same intervals, u of the scale factors and
    biases within 10 % of the pose route's. Before: the BMI160 took cross_z_xz under the
    walk its samples show, u 1.6-2.8x the pose route's."""
    import json

    from align.calibration.stability import chosen_ppm
    from align.cli import main

    poses, argv = _recording(name, tmp_path)
    # The reference under the scale stability the CLI assumes (no temperature column: the
    # default's term), so the two routes are compared under one model.
    ppm, default = chosen_ppm(None, poses.temp is not None)
    ref = calibrate(poses, scale_stability_ppm=ppm, stability_default=default)
    assert tuple(e.name for e in ref.loop.effects) == expected  # the reference as it was
    out = tmp_path / "cal.json"
    assert main(["calibrate", *argv, "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert tuple(e["name"] for e in js["effects"]) == expected, js["warnings"]
    if js["method"] == ref.method == "ellipsoid" and name != "hassan":
        u = np.r_[js["scale_factors_u_v_per_g"], js["bias_u_g"]]
        u_ref = np.r_[ref.model.sensitivity_u(), ref.model.u_per_axis("bias")]
        assert np.allclose(u, u_ref, rtol=0.1), u / u_ref
