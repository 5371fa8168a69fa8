"""A bias step between two poses (issue 18: 'the loop notices more than it admits';
align/calibration/between.py): the poses before read b, those after b + step. The samples
within the poses do not see it; the pose means do, and the result is not ok with the step
located — where the loop's effects (a bias drift with a misalignment, hysteresis) had
taken its signal and returned ok with a bias between the two values."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from align.calibration import calibrate, poses_from_samples
from align.calibration.between import STEP_ALPHA, between_step
from align.calibration.pipeline import CANDIDATES, CalibrationStage, noise_model
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import triad_of

CUBE = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
                + [[x, y, z] for x in (1, -1) for y in (1, -1) for z in (1, -1)], float)


def _cube(seed: int, step_g: float, after: int = 7):
    """The cube's 14 poses (k = 1, bias 0 before the step), 200 samples each at 20 Hz with
    20 µg of white noise, 5 s turns; the x bias steps by ``step_g`` in the turn before pose
    ``after``."""
    rng = np.random.default_rng(seed)
    pose, u, t = [], [], []
    for p, d in enumerate(CUBE):
        x = d / np.linalg.norm(d) + rng.normal(0, 2e-5, (200, 3))
        x[:, 0] += step_g * (p >= after)
        pose.append(np.full(200, p))
        u.append(x)
        t.append(15.0 * p + np.arange(200) / 20.0)
    return poses_from_samples(np.concatenate(pose), np.concatenate(u), np.concatenate(t))


def _step(poses, signs):
    """The loop's fits as the calibration makes them, and the step they show."""
    stage, rep = noise_model(CalibrationStage(poses, signs), CANDIDATES, 1e-3)
    return between_step(stage, rep)


def test_a_step_between_poses_is_located_and_the_result_not_ok():
    """2 mg between pose 6 and pose 7 of the cube: not ok, the step named with its boundary,
    time, and size within 3 of its u (before: not ok only for an effect ambiguity, 'measure
    with --plan', b_x 1165 ± 748 µg; the synth tumble's below was ok); no step: nothing
    found."""
    cal = calibrate(_cube(0, 2e-3), (1, 1, 1))
    assert not cal.ok
    (why,) = [w for w in cal.problems if "stepped" in w]
    m = re.search(r"the x bias stepped by ([-+.\d]+) ± ([.\d]+) µg between pose 6 and "
                  r"pose 7 \(t ≈ ([.\d]+) s", why)
    assert m, why
    size, u, t = (float(v) for v in m.groups())
    assert abs(size - 2000.0) < 3 * u and 90.0 < t < 105.0, why
    assert not _step(_cube(0, 0.0), (1, 1, 1)).found


def _tumble_step(seed: int, step_g: float, axis: int, after: int, walk: float = 0.0):
    """The paper's 14-pose synth tumble (the 'clean' triad, ``walk`` [g/√s] of bias random
    walk), its ``axis`` bias stepping by ``step_g`` in the turn before pose ``after`` (the
    output after it gains k step: u = K R (a + b)); the poses and the triad."""
    tr = triad_of("clean")
    if walk:
        tr = replace(tr, bias_walk_g=(walk,) * 3)
    d = tumble(TumbleSpec(triad=tr, seed=seed))
    sel = d.pose < d.n_cal
    u, t, pose = d.u[sel].copy(), d.t[sel], d.pose[sel]
    if step_g:
        when = (t[pose == after - 1].max() + t[pose == after].min()) / 2
        u += (np.asarray(tr.k) * np.eye(3)[axis] * step_g) * (t > when)[:, None]
    return poses_from_samples(pose, u, t), tr


@pytest.mark.slow
@pytest.mark.parametrize("step_g", [5e-5, 2e-4, 2e-3])
def test_steps_between_poses_sweep(step_g):
    """10 seeds per size, the step on x, y, z in turn, after poses 2 to 11: each flagged
    (not ok) with the step named at its boundary (or the poses that hold it) and axis, its
    size within 3 of its u — or, not flagged, every bias within 3 of its u of the value
    before or after it. Measured: 0.2 and 2 mg, 20 of 20 flagged, |z| of the size
    at most 0.27 (its u carries the walk the samples allow); 50 µg, 3 of 10 flagged, the
    other 7 biases within 2.37 of their u (5 of them not ok for an effect ambiguity)."""
    for s in range(10):
        axis, after = s % 3, 2 + s
        p, tr = _tumble_step(s, step_g, axis, after)
        cal = calibrate(p, np.sign(tr.k))
        found = _step(p, np.sign(tr.k))
        if found.found:
            assert not cal.ok and any("stepped" in w for w in cal.problems), (s, cal.problems)
            # The boundary named, or a range of poses that holds it (those between did not
            # see the axis: the same fit on either side of them).
            assert found.axis == axis and int(found.before) <= after - 1 and int(
                found.after) >= after and int(found.after) - int(found.before) <= 3, (s, found)
            assert abs(found.size_g - step_g) < 3 * found.size_u_g, (s, found)
        else:
            m, b = cal.model, np.asarray(tr.bias, float)
            z = [np.abs(m.bias - b - step_g * np.eye(3)[axis] * f) / m.u_per_axis("bias")
                 for f in (0, 1)]
            assert min(z[0][axis], z[1][axis]) < 3 and np.all(np.minimum(*z) < 3), (s, z)


@pytest.mark.slow
@pytest.mark.parametrize("walk", [0.0, 1e-6, 3e-6, 1e-5])
def test_no_step_between_poses_in_clean_or_walking_tumbles(walk):
    """40 tumbles per level (clean; a bias random walk of 1e-6, 3e-6, 1e-5 g/√s), no step:
    the test's false alarms at its STEP_ALPHA (1e-3): at most 1 of 40 (binomial, P(≥ 2)
    = 7.8e-4 at the nominal rate)."""
    alarms = [s for s in range(40)
              if _step(*(lambda pt: (pt[0], np.sign(pt[1].k)))(_tumble_step(s, 0.0, 0, 7, walk)))
              .found]
    assert STEP_ALPHA == 1e-3 and len(alarms) <= 1, alarms


def _handheld_run(seed: int, step_g: float, when_of, tmp_path):
    """``align calibrate`` on a hand-held recording in the documented CSV (t and three
    outputs in m/s², the static intervals detected; 30 poses of 3-6 s, 0.2 mg of noise at
    50 Hz) whose x bias steps by ``step_g`` [g] at ``when_of(recording)`` [s]: the exit
    status, the JSON's problems and the recording."""
    import json

    from align.cli import main
    from synth.handheld import HandheldSpec, handheld
    from synth.tumble import Triad

    g0 = 9.80665
    tr = Triad(k=(g0 * 1.01, g0 * 0.99, g0), bias=(0.01, -0.02, 0.03),
               beta=(0.002, -0.001, 0.003), noise_v=0.0, full_scale_v=1e6)
    rec = handheld(HandheldSpec(triad=tr, rate_hz=50.0, noise_g=2e-4, n_poses=30,
                                dwell_s=(3.0, 6.0), seed=seed))
    u = rec.u + np.array(tr.k) * np.eye(3)[0] * step_g * (rec.t > when_of(rec))[:, None]
    path = replace(rec, u=u).write_csv(tmp_path / f"rec{seed}_{step_g}.csv", with_time=True)
    out = tmp_path / f"cal{seed}_{step_g}.json"
    rc = main(["calibrate", str(path), "--units", "m/s2", "--json", str(out)])
    return rc, json.loads(out.read_text())["problems"], rec


@pytest.mark.slow
def test_a_recording_with_a_step_between_poses(tmp_path):
    """The hand-held recording, the x bias stepping by 2 mg in the turn after its 15th pose:
    exit 2 and the JSON names the step, its size within 3 of its u, its time in the turn
    (before: not ok only for an effect ambiguity, 'measure with --plan'); the same recording
    without the step: exit 0."""
    def turn(rec):
        return (rec.poses[14][1] + rec.poses[15][0]) / 2

    for seed in (0, 1):
        assert _handheld_run(seed, 0.0, turn, tmp_path)[:2] == (0, [])
        rc, problems, rec = _handheld_run(seed, 2e-3, turn, tmp_path)
        (_, end), (start, stop) = rec.poses[14], rec.poses[15]
        (why,) = [w for w in problems if "stepped" in w]
        m = re.search(r"the x bias stepped by ([-+.\d]+) ± ([.\de+]+) µg between pose "
                      r"static@([.\d]+)s and pose static@([.\d]+)s \(t ≈ ([.\d]+) s", why)
        assert rc == 2 and m, (seed, why)
        size, u, t0, t1, t = (float(v) for v in m.groups())
        assert abs(size - 2000.0) < 3 * u and t0 < end and start <= t1 + 0.5, (seed, why)
        assert t0 < t < t1 + (stop - start), (seed, why)


@pytest.mark.slow
def test_a_step_within_a_detected_interval_is_named(tmp_path):
    """The hand-held recording's x bias stepping by 2 mg at 40 % of its 16th pose (seeds 0,
    2: the detector keeps the pose whole): exit 2, the step named within that static interval
    at its time (before: steps in detected intervals were not judged; the exit 2 was an effect
    ambiguity's); once, not again as a step between poses."""
    def inside(rec):
        return rec.poses[15][0] + 0.4 * np.ptp(rec.poses[15])

    for seed in (0, 2):
        rc, problems, rec = _handheld_run(seed, 2e-3, inside, tmp_path)
        (why,) = [w for w in problems if "stepped" in w]
        m = re.search(r"the x bias stepped by ([-+.\d]+) µg within pose static@([.\d]+)s "
                      r"\(t ≈ ([.\d]+) s", why)
        assert rc == 2 and m, (seed, why)
        size, start, t = (float(v) for v in m.groups())
        assert abs(size - 2000.0) < 100.0, why
        assert abs(t - inside(rec)) < 0.1 and start <= rec.poses[15][0] + 0.5, why
