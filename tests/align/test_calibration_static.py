"""Static detection on continuous recordings: synthetic hand-held sessions (10-1000 Hz, 1-3 s
poses, slow handling, 10 µg-10 mg noise) scored against their true poses, and the real
recordings of ../shared/data/real (skipped when absent)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from align.calibration import StaticSettings, calibrate, detect_static, find_static, read_poses
from align.calibration import formats as F
from align.calibration.arrays import MEANS_ROWS
from align.calibration.static import StaticDetection
from synth.handheld import HandheldRecording, HandheldSpec, handheld
from synth.tumble import Triad
from tests.conftest import real_folder


def score(rec: HandheldRecording, det: StaticDetection) -> dict:
    """Found poses (an interval with most of its samples in that pose and none in another),
    intervals spanning two poses, intervals outside every pose, and each found interval's
    mean error against the noise-free output in units of its standard error."""
    dt = 1 / rec.spec.rate_hz
    P = np.array(rec.poses)
    found, span, extra, z = set(), 0, 0, []
    for iv in det.intervals:
        tt = rec.t[(rec.t >= iv.start_s - dt / 4) & (rec.t <= iv.end_s + dt / 4)]
        inside = np.array([np.sum((tt >= a - dt / 4) & (tt <= b + dt / 4)) for a, b in P])
        hit = np.flatnonzero(inside)
        if len(hit) > 1:
            span += 1
        elif len(hit) == 0 or inside[hit[0]] < 0.5 * len(tt):
            extra += 1
        else:
            i = int(hit[0])
            found.add(i)
            clean = rec.spec.triad.outputs(rec.up[i][None], np.zeros(1), np.zeros(1), None)[0]
            z.append(float(np.max(np.abs(iv.mean - clean) / np.maximum(iv.sem, 1e-300))))
    return {"found": len(found), "poses": len(P), "span": span, "extra": extra,
            "z": np.array(z)}


GRID = [(rate, noise) for rate in (10.0, 50.0, 1000.0) for noise in (1e-5, 1e-3, 1e-2)]


@pytest.mark.parametrize("rate,noise", GRID)
def test_handheld_poses_found_by_default(rate, noise):
    rec = handheld(HandheldSpec(rate_hz=rate, noise_g=noise, n_poses=20, seed=int(rate)))
    s = score(rec, detect_static(rec.t, rec.u))
    assert s["span"] == 0
    assert s["found"] >= 0.95 * s["poses"]
    # The found means are unbiased: max over 3 axes of |error| / sem stays Gaussian-sized.
    assert np.percentile(s["z"], 90) < 4.0 and s["z"].max() < 8.0


def _tapped(rec: HandheldRecording, seed: int) -> tuple[HandheldRecording, list[int]]:
    """``rec`` with a tap on the fixture in the middle of every other pose of 2 s or more: a
    0.2 s damped 25 Hz ring of 30x the noise on each axis, which leaves the attitude as it
    was (zero mean over the ring)."""
    rng = np.random.default_rng(seed)
    u = rec.u.copy()
    tapped = []
    for i, (a, b) in enumerate(rec.poses):
        if i % 2 or b - a < 2.0:
            continue
        t0 = (a + b) / 2
        sel = (rec.t >= t0) & (rec.t < t0 + 0.2)
        tau = rec.t[sel] - t0
        ring = np.sin(2 * np.pi * 25 * tau) * np.exp(-tau / 0.05)
        u[sel] += 30 * rec.spec.noise_g * ring[:, None] * rng.choice([-1, 1], 3)
        tapped.append(i)
    return HandheldRecording(rec.t, u, rec.poses, rec.up, rec.spec), tapped


@pytest.mark.parametrize("seed", range(3))
def test_a_tap_that_leaves_the_attitude_is_one_pose(seed):
    """A tap in the middle of a pose breaks the quiet run; the attitude on both sides is the
    same, so the split rule (mean moved by --split-sigma and --split-deg) calls it one pose:
    one interval per tapped pose (before: two, the OpenAXES recording's 6 extra of 44), every
    pose found, none spanning two, the means unbiased."""
    rec, tapped = _tapped(handheld(HandheldSpec(rate_hz=100.0, noise_g=1e-3, n_poses=20,
                                                dwell_s=(2.0, 4.0), seed=seed)), seed)
    assert len(tapped) >= 4
    det = detect_static(rec.t, rec.u)
    a, b = rec.poses[tapped[0]]
    assert det.ratio[(rec.t > a + 0.5) & (rec.t < b - 0.5)].max() > det.limit  # it breaks
    s = score(rec, det)
    assert s["span"] == 0 and s["extra"] == 0 and s["found"] == s["poses"]
    assert len(det.intervals) == s["poses"], (len(det.intervals), s["poses"])
    assert s["z"].max() < 8.0
    # what is left out is samples between the runs: a forward stretch inside the interval
    gaps = [(iv, g) for iv in det.intervals for g in iv.left_out]
    assert gaps and all(iv.start_s < a <= b < iv.end_s for iv, (a, b) in gaps), gaps


@pytest.mark.slow
@pytest.mark.parametrize("rate,noise", [(r, n) for r in (10.0, 25.0, 50.0, 100.0, 400.0, 1000.0)
                                        for n in (1e-5, 1e-4, 1e-3, 3e-3, 1e-2)])
def test_handheld_poses_found_many_seeds(rate, noise):
    tot = {"found": 0, "poses": 0, "span": 0}
    for seed in range(5):
        rec = handheld(HandheldSpec(rate_hz=rate, noise_g=noise, seed=seed))
        s = score(rec, detect_static(rec.t, rec.u))
        for k in tot:
            tot[k] += s[k]
    assert tot["span"] == 0 and tot["found"] >= 0.95 * tot["poses"]


def test_noise_estimated_from_the_recording():
    for noise in (1e-5, 1e-3):
        rec = handheld(HandheldSpec(rate_hz=100.0, noise_g=noise, seed=3))
        det = detect_static(rec.t, rec.u)
        assert np.all(np.abs(det.noise / noise - 1) < 0.15)
        # white noise: the Allan deviation at the window is the white value
        assert np.all(np.abs(det.noise_mean * np.sqrt(det.window) / det.noise - 1) < 0.25)


def test_phone_like_recording_without_time_column(tmp_path):
    """The reported case: 30 orientations, ~50 Hz, m/s², no time column, given --rate."""
    rec = handheld(HandheldSpec(triad=Triad(k=(9.80665,) * 3, bias=(0.01, -0.02, 0.03),
                                            beta=(0.002, -0.001, 0.003), noise_v=0.0),
                                rate_hz=50.0, noise_g=2e-3, seed=11))
    p = rec.write_csv(tmp_path / "phone.csv")
    poses, intervals = read_poses(p, rate_hz=50.0)
    s = score(rec, StaticDetection(tuple(intervals), *([None] * 6)))
    assert s["found"] >= 29 and s["span"] == 0
    cal = calibrate(poses)
    assert np.allclose(cal.model.k, 9.80665, rtol=2e-3)
    assert not cal.loop.effects


@pytest.mark.parametrize("lsb", [0.0383, 0.153])
def test_quantised_phone_output(lsb):
    """A phone's coarse output quantum (m/s²) at or above its noise: the noise floor is
    never below quantum/sqrt(12), so the poses are still found."""
    tr = Triad(k=(9.80665,) * 3, noise_v=0.0, lsb_v=lsb, full_scale_v=1e6)
    rec = handheld(HandheldSpec(triad=tr, rate_hz=50.0, noise_g=1e-3, seed=21))
    s = score(rec, detect_static(rec.t, rec.u))
    assert s["found"] == 30 and s["span"] == 0


def test_row_index_as_time_says_so():
    """Durations are in seconds: a row index as time shrinks every duration setting 50x
    (the reported 148 intervals). The detector says so; with --rate the poses are found."""
    rec = handheld(HandheldSpec(rate_hz=50.0, noise_g=1e-3, n_poses=12, seed=2))
    det = detect_static(np.arange(len(rec.t), dtype=float), rec.u)
    assert any("--rate" in n for n in det.notes)
    good = detect_static(rec.t, rec.u)
    assert not good.notes and score(rec, good)["found"] == 12


SETTINGS = [StaticSettings(), StaticSettings(window_s=0.15), StaticSettings(window_s=0.5),
            StaticSettings(threshold=2.5), StaticSettings(threshold=4.0),
            StaticSettings(margin_s=0.0), StaticSettings(margin_s=0.3),
            StaticSettings(min_duration_s=1.0)]


def _poses(t, u, settings):
    from align.calibration import Poses

    iv = find_static(t, u, settings)
    return Poses(np.array([x.mean for x in iv]), np.array([(x.start_s + x.end_s) / 2 for x in iv]),
                 None, np.array([x.sem for x in iv]), np.array([x.samples for x in iv]),
                 tuple(f"{x.start_s:.1f}s" for x in iv))


# The default run tries the default settings and the two that move the intervals' edges most
# (shortest window, highest threshold: ~0.6 s of calibration each); `-m slow` the other five.
FAST_SETTINGS = (0, 1, 4)


@pytest.mark.parametrize("which", ["fast", pytest.param("rest", marks=pytest.mark.slow)])
@pytest.mark.parametrize("drift", [0.0, 2e-5])
def test_effects_do_not_depend_on_the_detector_settings(drift, which):
    """A clean hand-held session gives no effect with any settings; a real drift is found
    with every setting."""
    tr = Triad(k=(1.0, 1.0, 1.0), noise_v=0.0, drift=(drift, -drift, drift))
    rec = handheld(HandheldSpec(triad=tr, rate_hz=100.0, noise_g=1e-3, seed=5))
    names = set()
    for st in [st for i, st in enumerate(SETTINGS) if (i in FAST_SETTINGS) == (which == "fast")]:
        cal = calibrate(_poses(rec.t, rec.u, st))
        names.add(tuple(e.name for e in cal.loop.effects))
    assert names == ({()} if drift == 0 else {("bias_drift",)})


# ----------------------------------------------------------------------------- real data

def _ferraris():
    folder = real_folder("imucal-ferraris")
    d = np.genfromtxt(folder / "example_ferraris_session.csv", delimiter=",", names=True)
    u = np.column_stack([d["acc_x"], d["acc_y"], d["acc_z"]])
    sec = json.loads((folder / "example_ferraris_session_list.json").read_text())
    return np.arange(len(u)) / 102.4, u, sec


def test_real_ferraris_six_faces_found():
    t, u, sec = _ferraris()
    iv = find_static(t, u)
    for face in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"):
        a, b = sec[face]["start"] / 102.4, sec[face]["end"] / 102.4
        # one interval covers most of the annotated face and nothing of a turn
        best = max(iv, key=lambda x: min(x.end_s, b) - max(x.start_s, a))
        assert min(best.end_s, b) - max(best.start_s, a) > 0.7 * (b - a)
    # The turns are about the vertical axis (x_rot with +x up, ...): the rests either side
    # are one attitude, joined into one pose; no sample of a turn is in an interval.
    for turn in ("x_rot", "y_rot", "z_rot"):
        a, b = sec[turn]["start"] / 102.4, sec[turn]["end"] / 102.4
        assert not any(np.any(x.mask(t) & (t > a) & (t < b)) for x in iv)


@pytest.mark.parametrize("name,loader,lo,hi", [
    ("xsens", lambda: F.xsens_text(real_folder("imu_tk-xsens") / "xsens_acc.mat"), 37, 40),
    ("adxl355", lambda: F.openaxes(real_folder("openaxes-imu9")
                                   / "log_imu9_2022-06-22_22-13-55.csv", "ADXL355"), 37, 40),
    ("bmi160", lambda: F.openaxes(real_folder("openaxes-imu9")
                                  / "log_imu9_2022-06-22_22-13-55.csv", "BMI160"), 37, 40),
    ("mpu6050", lambda: F.mpu6050(real_folder("mpu6050-tomisuarez")
                                  / "example_data_calibration.csv"), 10, 12),
])
def test_real_recordings_poses_found_by_default(name, loader, lo, hi):
    """READMEs: xsens 1 + 37 poses, openaxes 1 + ~38 placements (36-39 by threshold),
    mpu6050 1 + ~10 poses."""
    t, u = loader()
    assert lo <= len(find_static(t, u)) <= hi


@pytest.mark.parametrize("sensor", [
    "ADXL355", pytest.param("BMI160", marks=pytest.mark.slow)])  # ~3 s each alone
def test_real_openaxes_placements_as_the_cli_reads_them(sensor):
    """The OpenAXES log as `align calibrate … --time-unit us` reads it (the host's jittery
    receive TIME): 38 intervals on both triads of the one housing — the initial rest and 37
    placements (README: 40 s still, the 20 faces, then 17-20 random ones; its own detector
    ~38) — each the same placement the device clock's detection finds (means within 5 mean
    standard errors). Before: 44 and 39, six placements split in two by a tap or a burst of
    samples mid-rest (the two halves' means 0.3-3 mg apart, the same attitude)."""
    path = real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv"
    from axisbase import parse_column_map

    cols = parse_column_map(",".join(f"u{a}=ACCEL_{sensor}_{k}" for k, a in enumerate("xyz")))
    _, iv = read_poses(path, columns=cols, time_unit="us")
    ref = find_static(*F.openaxes(path, sensor))
    assert len(iv) == len(ref) == 38, (len(iv), len(ref))
    for a, b in zip(iv, ref, strict=True):
        assert np.all(np.abs(a.mean - b.mean) < 5 * np.hypot(a.sem, b.sem)), (a, b)


def _pose_file(path, counts, seed=0):
    """A pose file: pose i has counts[i] samples around a random direction (noise 1e-4)."""
    rng = np.random.default_rng(seed)
    lines = ["pose,ux,uy,uz"]
    for i, c in enumerate(counts):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        lines += [f"P{i},{','.join(f'{v:.9f}' for v in d + rng.normal(0, 1e-4, 3))}"
                  for _ in range(c)]
    path.write_text("\n".join(lines) + "\n")
    return lines


@pytest.mark.parametrize("short", [1, 2])
def test_a_pose_of_one_or_two_samples_among_sampled_poses_is_refused_by_name(tmp_path, short):
    from align.errors import InputError

    counts = [20] * 12
    counts[7] = short
    lines = _pose_file(tmp_path / "p.csv", counts)
    with pytest.raises(InputError) as exc:
        read_poses(tmp_path / "p.csv")
    line = next(i for i, ln in enumerate(lines, start=1) if ln.startswith("P7,"))
    assert str(exc.value).startswith(f"{tmp_path / 'p.csv'}:{line}: pose: 'P7' has {short} ")
    # as check poses (means only) the file is read
    assert read_poses(tmp_path / "p.csv", calibration=False)[0].count[7] == short


@pytest.mark.parametrize("counts, noise_known", [([20] * 12, True), ([3] * 12, True),
                                                 ([1] * 12, False), ([1, 2] * 6, False)])
def test_sampled_poses_or_per_pose_means_are_read(tmp_path, counts, noise_known):
    _pose_file(tmp_path / "p.csv", counts)
    poses, _ = read_poses(tmp_path / "p.csv")
    assert poses.count.tolist() == counts and (poses.sigma_u is not None) == noise_known


# ----------------------------------------------------------------------------- one rule, two names

def _csv(path, header: str, rows: np.ndarray) -> None:
    path.write_text(header + "\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows)
                    + "\n")


@pytest.fixture
def two_paths(tmp_path):
    """A session folder holding only a [calibration] (its recording named by the test), and
    the two ways to refuse: ``align calibrate FILE FLAGS`` (its stderr line) and session.toml
    keys through ``align run`` (the stage's error, or the load's refusal)."""
    import io
    from contextlib import redirect_stderr

    from align.cli import main
    from align.errors import InputError
    from align.session import load_session, run_session

    def cli(name: str, *flags: str) -> str:
        err = io.StringIO()
        with redirect_stderr(err):
            assert main(["calibrate", str(tmp_path / name), *flags, "-q"]) == 2
        line = err.getvalue().strip().splitlines()[0]
        return line.removeprefix("align calibrate: ")

    def session(name: str, keys: str = "") -> str:
        (tmp_path / "session.toml").write_text(f'[calibration]\nstatic = "{name}"\n{keys}')
        try:
            s = load_session(tmp_path)
        except InputError as exc:
            return str(exc).removeprefix(f"{tmp_path / 'session.toml'}: ")
        errors = run_session(s).errors
        assert errors[0].stage == "calibration"
        return errors[0].message.splitlines()[0]

    return tmp_path, cli, session


@pytest.mark.parametrize("setting,flag,key,value,why", [
    ("threshold", "--threshold", "threshold", "0.5", "must be > 1"),
    ("window_s", "--window", "window_s", "0", "must be > 0"),
    ("margin_s", "--margin", "margin_s", "-0.1", "must be >= 0"),
    ("min_duration_s", "--min-static", "min_static_s", "nan", "not a finite number")])
def test_a_detection_setting_is_refused_alike_naming_the_flag_or_the_key(
        two_paths, setting, flag, key, value, why):
    """One rule (StaticSettings.given) for both paths; each message names what the user
    typed."""
    folder, cli, session = two_paths
    _csv(folder / "rec.csv", "t,ux,uy,uz", np.zeros((4, 4)) + np.arange(4)[:, None])
    by_cli = cli("rec.csv", flag, value)
    by_toml = session("rec.csv", f"{key} = {value}\n")
    assert by_cli.startswith(f"{flag} = ") and why in by_cli
    assert by_toml.startswith(f"[calibration] {key} = ") and why in by_toml
    assert by_cli.split(" = ", 1)[1] == by_toml.split(" = ", 1)[1]
    assert "--" not in by_toml


def test_recording_refusals_name_the_flag_or_the_key(two_paths):
    """A recording without times, and one with too few static intervals: the same refusal
    on both paths, the CLI's naming --rate / --window ..., the session's naming its keys
    (a session user has no flags)."""
    folder, cli, session = two_paths
    rng = np.random.default_rng(2)
    _csv(folder / "no_t.csv", "ux,uy,uz", rng.normal(size=(MEANS_ROWS + 1, 3)))
    a, b = cli("no_t.csv"), session("no_t.csv")
    assert "give --rate HZ" in a and "give [calibration] rate_hz = HZ" in b
    assert a.replace("--rate HZ", "X") == b.replace("[calibration] rate_hz = HZ", "X")
    # never still (a random walk of the attitude): one short interval at most
    t = np.arange(600) / 100
    rng = np.random.default_rng(1)
    walk = np.cumsum(rng.normal(0, 0.05, (600, 3)), 0) + rng.normal(0, 1e-3, (600, 3))
    _csv(folder / "moving.csv", "t,ux,uy,uz", np.column_stack([t, walk]))
    a, b = cli("moving.csv"), session("moving.csv")
    assert "(--window, --threshold, --min-static, --margin)" in a
    assert ("([calibration] window_s, [calibration] threshold, [calibration] min_static_s, "
            "[calibration] margin_s)") in b
    assert "--" not in b and a.split(" (")[0] == b.split(" (")[0]
