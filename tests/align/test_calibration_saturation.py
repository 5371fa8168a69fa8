"""Saturation judged per pose and per axis (issue 22, class 5): a pose clipped at a rail or
stuck at one value is left out with a warning naming it when the rest determine the
calibration, refused by name when they do not; valid poses near a rail are unchanged."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from align.calibration import read_poses
from align.calibration.files import calibrate_files
from align.calibration.static import StaticSettings
from align.cli import main
from align.errors import InputError
from synth.tumble import Triad, TumbleSpec, tumble

LSB_V = 1e-4
NOISE_V = 3e-4  # three LSB: a tail of several levels, as an ADC of a quiet sensor gives
SIX = ("+x", "+y", "+z", "-x", "-y", "-z")  # synth order of the faces: eye(3), then -eye(3)


def tumble_csv(path: Path, seed: int, poses: str = "cube14", clip: int | None = None,
               stuck: bool = False, pose: int = 2) -> tuple[Path, float, int]:
    """A quantised tumble (synth truth k < 0) written as pose samples; ``clip``: how many of
    the +z pose's uz samples a bottom rail catches (its reading is the most negative);
    ``stuck``: the whole pose ``pose`` (default +z) at one value on uz, its median. Returns
    the path, the rail [V] and how many samples sit there (quantised ties: >= ``clip``)."""
    tr = Triad(noise_v=NOISE_V, lsb_v=LSB_V)
    d = tumble(TumbleSpec(triad=tr, poses=poses, check_poses=0, seed=seed))
    u = d.u.copy()
    sel = d.pose == pose  # 2: +z up
    x = u[sel, 2]
    rail = float(np.sort(x)[(clip or 1) - 1])
    if clip:
        u[sel, 2] = np.maximum(x, rail)
    if stuck:
        u[sel, 2] = rail = float(np.sort(x)[len(x) // 2])
    labels = SIX if poses == "six" else tuple(str(i + 1) for i in range(d.n_cal))
    path.write_text("pose,ux,uy,uz,t\n" + "".join(
        f"{labels[p]},{a:.5f},{b:.5f},{c:.5f},{t:.2f}\n"
        for p, (a, b, c), t in zip(d.pose, u, d.t, strict=True)))
    return path, rail, int(np.sum(u[sel, 2] == rail))


def run(path: Path, adc_range=None):
    # synth's scale factors are constant: declared (0 ppm), else the default's note is warned.
    return calibrate_files(path, None, "V", None, StaticSettings(), adc_range=adc_range,
                           scale_stability_ppm=0.0)


def test_clipped_pose_left_out_and_named(tmp_path):
    """107 of the +z pose's 200 samples at the rail: 107 < 5 % of the file's 2800, so the
    old file-wide rule let it through and k_z moved silently. Now the pose is left out,
    named with its axis in the warnings, and k_z agrees with the clean file's."""
    clean = run(tumble_csv(tmp_path / "clean.csv", 4)[0])
    path, _, n = tumble_csv(tmp_path / "clip.csv", 4, clip=107)
    res = run(path)
    w = [x for x in res.warnings if f"pose 3: uz piled at its extreme ({n} of its 200" in x]
    assert w and "left out" in w[0], res.warnings
    assert len(res.poses.u) == 13 and "3" not in res.poses.labels
    m, c = res.cal.model, clean.cal.model
    u = np.hypot(m.sensitivity_u()[2], c.sensitivity_u()[2])
    # The same samples less one pose: within the 13-pose fit's own uncertainty of k_z.
    assert abs(m.sensitivity()[2] - c.sensitivity()[2]) < 3 * u


def test_stuck_pose_left_out(tmp_path):
    """A whole pose of one value on uz, not at the file's extreme (the old file-wide rule
    did not see it; the loop called it at most 'unexplained structure')."""
    res = run(tumble_csv(tmp_path / "stuck.csv", 5, stuck=True, pose=6)[0])  # a corner
    assert any("pose 7: uz one value throughout (200 of its 200" in x for x in res.warnings)
    assert len(res.poses.u) == 13


def test_declared_rail(tmp_path):
    """--adc-range: the three lowest samples of the file at the declared rail are clipping
    (the pile-up rule alone cannot see so few); a rail one LSB beyond every sample (a pose
    near the rail, not at it) changes nothing."""
    path = tumble_csv(tmp_path / "rail.csv", 6)[0]
    plain = run(path)
    assert not plain.warnings and len(plain.poses.u) == 14
    u = np.loadtxt(path, delimiter=",", skiprows=1, usecols=(1, 2, 3))
    low = np.sort(u.ravel())
    at = run(path, (low[2], 10.0))
    ax = "xyz"[int(np.argmin(u.min(0)))]
    hit = [x for x in at.warnings if f"u{ax} at the declared rail (" in x]
    assert hit and "left out" in hit[0] and len(at.poses.u) == 13, at.warnings
    near = run(path, (low[0] - LSB_V, 10.0))
    assert not near.warnings
    assert np.array_equal(near.cal.model.k, plain.cal.model.k)


def test_six_faces_without_the_clipped_face_refused_by_name(tmp_path):
    path = tumble_csv(tmp_path / "six.csv", 7, poses="six", clip=107)[0]
    with pytest.raises(InputError, match=r"pose \+z: uz piled at its extreme.*remaining 5 "
                       "poses do not determine"):
        read_poses(path)


def test_clean_quantised_tumbles_untouched(tmp_path):
    """No pose of a clean quantised tumble is called saturated (40 seeds, 560 poses x 3
    axes; noise 0.5 to 5 LSB, where an extreme level may hold many samples)."""
    for seed in range(40):
        tr = Triad(noise_v=LSB_V * (0.5, 1, 2, 3, 5)[seed % 5], lsb_v=LSB_V)
        d = tumble(TumbleSpec(triad=tr, check_poses=0, seed=seed))
        from align.calibration.saturation import find_saturated

        samples = [d.u[d.pose == i] for i in range(d.n_cal)]
        assert find_saturated(samples, [str(i) for i in range(d.n_cal)]) == [], seed


def test_cli_json_warnings_and_flag(tmp_path, capsys):
    path, _, n = tumble_csv(tmp_path / "clip.csv", 8, clip=107)
    out = tmp_path / "o.json"
    assert main(["calibrate", str(path), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert any(f"pose 3: uz piled at its extreme ({n} of" in w for w in doc["warnings"])
    assert main(["calibrate", str(path), "--adc-range", "3,1"]) == 2
    assert "LO < HI" in capsys.readouterr().err


def test_session_key_adc_range(tmp_path):
    """[calibration] adc_range reaches the reader; a malformed one is refused naming the key;
    without scale_sign the signs are left to the labels (None)."""
    from align.session.config import load_session

    tumble_csv(tmp_path / "tumble.csv", 9)
    toml = tmp_path / "session.toml"
    toml.write_text('[calibration]\nstatic = "tumble.csv"\nadc_range = [-5.0, 5.0]\n')
    c = load_session(tmp_path).calibration
    assert c.adc_range == (-5.0, 5.0) and c.scale_sign is None
    toml.write_text('[calibration]\nstatic = "tumble.csv"\nadc_range = [5.0, -5.0]\n')
    with pytest.raises(InputError, match=r"\[calibration\] adc_range = \[5.0, -5.0\]: need LO "
                       "< HI"):
        load_session(tmp_path)


def test_recording_interval_clipped(tmp_path):
    """A continuous recording: the static interval of the +z pose clipped on uz in half its
    samples is judged on its own (0.6 % of the file) and left out, named by its time."""
    from synth.tumble import recording

    t, u, iv = recording(TumbleSpec(triad=Triad(noise_v=NOISE_V, lsb_v=LSB_V), check_poses=0,
                                    seed=10))
    means = np.array([u[(t >= a) & (t <= b)].mean(0) for a, b in iv])
    a, b = iv[int(np.argmin(means[:, 2]))]  # the pose reading the most negative uz: +z
    sel = (t >= a) & (t <= b)
    rail = float(np.median(u[sel, 2]))
    u[sel, 2] = np.maximum(u[sel, 2], rail)
    path = tmp_path / "rec.csv"
    path.write_text("t,ux,uy,uz\n" + "".join(
        f"{x:.2f},{p:.5f},{q:.5f},{r:.5f}\n" for x, (p, q, r) in zip(t, u, strict=True)))
    got: list[str] = []
    poses = read_poses(path, warnings=got)[0]
    assert len(got) == 1 and ": uz piled at its extreme (" in got[0], got
    assert got[0].split(": pose ")[1].startswith("static@")
    assert len(poses.u) == len(iv) - 1
