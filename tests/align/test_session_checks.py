"""A session that does not describe one set-up is refused, never fused into a confident E.

* the fusion: chi2 beyond what uncertainties ten times too small would give (a mirrored
  camera) -> not ok, the worst observations named, no platform calibration;
* the platform poses: readings far from 1 g after the calibration (another unit), a pose far
  from its declared 'up' (a scale sign, a column, swapped labels) -> the pose named;
* a mark far from its declared nominal (images swapped) -> the [[images]] file named;
* the pose reader: a label that joins two orientations -> the label and its lines named.

Each is checked not to fire on clean sessions (seeded).
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from align.calibration import read_poses
from align.errors import InputError
from align.session import load_session, run_session
from synth.session import SessionSpec, write_session


@pytest.fixture(scope="module")
def session(session21) -> Path:
    """The run's synthetic session of seed 21 (tests/conftest.py), read-only: a test that
    edits it edits a copy."""
    return session21


def _copy(session: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(session, tmp_path / "copy"))


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def _platform_only(folder: Path):
    """The calibration and the platform poses alone (no images, no log): fast."""
    s = load_session(folder)
    return run_session(replace(s, images=(), goniometer=None))


def _messages(res, stage: str) -> str:
    return " | ".join(e.message for e in res.errors if e.stage == stage)


def test_clean_session_is_ok_and_far_from_the_gross_bound(session21_run):
    res, _ = session21_run  # run_session of the fixture ``session`` (seed 21), shared
    assert res.ok and not res.errors
    f = res.fusion
    assert not f.gross
    # chi2 ~ dof for a clean session; the bound is ~100x the chi2 quantile at 1e-3
    assert f.chi2 < f.gross_bound / 50, (f.chi2, f.gross_bound)


def test_mirrored_camera_is_a_gross_disagreement(session, tmp_path):
    """Every mark image mirrored left-right (a camera set to mirror): each mark stays within
    arc-minutes of its nominal, so only the fusion can see it."""
    folder = _copy(session, tmp_path)
    for p in folder.glob("*.png"):
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        assert cv2.imwrite(str(p), np.ascontiguousarray(img[:, ::-1]))
    res = run_session(load_session(folder))
    assert res.fusion is not None and res.fusion.gross
    assert not res.ok
    msg = _messages(res, "fusion")
    assert "grossly disagree" in msg and "camera" in msg, msg
    assert res.platform_calibration() is None  # nothing for 'align apply'


def test_swapped_mark_images_name_the_file(session, tmp_path):
    folder = _copy(session, tmp_path)
    (folder / "x_A.png").rename(folder / "tmp.png")
    (folder / "z_A.png").rename(folder / "x_A.png")
    (folder / "tmp.png").rename(folder / "z_A.png")
    res = run_session(load_session(folder))
    msg = _messages(res, "marks")
    assert not res.ok
    assert "'x_A.png'" in msg and "'z_A.png'" in msg and "from its declared nominal" in msg, msg
    assert len(res.marks) == 6  # the others are measured and fused


def test_platform_pose_against_its_declared_up_is_named(session, tmp_path):
    folder = _copy(session, tmp_path)
    toml = folder / "session.toml"
    _edit(toml, 'Xup = { up = "+X"', 'Xup = { up = "-X"')
    _edit(toml, 'Xdn = { up = "-X"', 'Xdn = { up = "+X"')
    res = _platform_only(folder)
    msg = _messages(res, "platform static")
    assert "pose Xup declared up -X" in msg and "180°" in msg and "Xdn" in msg, msg
    assert not res.ok and not res.platform


def test_undeclared_scale_sign_is_named(session, tmp_path):
    folder = _copy(session, tmp_path)
    text = (folder / "session.toml").read_text()
    # synth's triad has negative scale factors, declared "-": declare "+" instead
    sign = 'scale_sign = "-"'
    assert sign in text
    _edit(folder / "session.toml", sign, 'scale_sign = "+"')
    res = _platform_only(folder)
    msg = _messages(res, "platform static")
    assert "pose L000 declared up +Z" in msg and "scale_sign" in msg, msg


def test_platform_readings_in_another_unit_are_named(session, tmp_path):
    folder = _copy(session, tmp_path)
    p = folder / "platform.csv"
    lines = p.read_text().splitlines()
    out = [lines[0]]
    for ln in lines[1:]:
        c = ln.split(",")
        out.append(",".join([c[0], *(f"{1000 * float(v):.9e}" for v in c[1:4]), *c[4:]]))
    p.write_text("\n".join(out) + "\n")
    res = _platform_only(folder)
    msg = _messages(res, "platform static")
    assert "pose L000 reads |a| = " in msg and "units" in msg, msg


# ----------------------------------------------------------------------------- pose reader

def _pose_file(path: Path, rng, labels=None, noise=None, drift_deg=0.0, n=50):
    """Samples of 14 well-spread poses (+-1 g on each axis, 8 corners) in V, k ~ 2.4 V/g."""
    dirs = np.vstack([np.eye(3), -np.eye(3),
                      np.array([[a, b, c] for a in (1, -1) for b in (1, -1)
                                for c in (1, -1)]) / np.sqrt(3)])
    labels = labels or [f"P{i:02d}" for i in range(len(dirs))]
    noise = np.full(len(dirs), 5e-5) if noise is None else noise
    rows = ["pose,ux,uy,uz"]
    for lab, d, sd in zip(labels, dirs, noise, strict=True):
        tilt = np.deg2rad(drift_deg) * np.linspace(-0.5, 0.5, n)[:, None] * np.cross(
            d, [0.6, 0.8, 0.0] if abs(d[2]) > 0.9 else [0.0, 0.0, 1.0])
        u = 2.4 * (d + tilt) + 0.01 + rng.normal(0, sd, (n, 3))
        rows += [f"{lab},{a:.9f},{b:.9f},{c:.9f}" for a, b, c in u]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_a_label_joining_two_orientations_is_refused_with_its_lines(tmp_path):
    rng = np.random.default_rng(5)
    labels = [f"P{i:02d}" for i in range(14)]
    labels[9] = "P04"  # P09's rows labelled P04: two orientations, not contiguous
    p = _pose_file(tmp_path / "t.csv", rng, labels)
    for calibration in (True, False):  # align calibrate, and the platform's poses
        with pytest.raises(InputError) as exc:
            read_poses(p, calibration=calibration)
        msg = str(exc.value)
        assert "pose P04: its samples are not one static pose" in msg, msg
        # header line 1; P04's samples are rows 201-250 and 451-500 -> lines 202-251, 452-501
        assert "lines 202-251, 452-501" in msg, msg


def test_clean_pose_files_are_never_refused(tmp_path):
    """Poses whose noise differs 3x from one another, or that creep by 0.3° (settling): no
    refusal over 20 seeds (a mixed label moves ~1 g; the limits are 10x the noise and 1°)."""
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        noise = 5e-5 * rng.uniform(1 / 3, 3, 14)
        p = _pose_file(tmp_path / f"t{seed}.csv", rng, noise=noise,
                       drift_deg=0.3 if seed % 2 else 0.0)
        poses, _ = read_poses(p)
        assert len(poses.labels) == 14


@pytest.mark.slow
def test_clean_sessions_are_never_refused(tmp_path):
    """Ten clean synthetic sessions (every source): no refusal, chi2 far below the bound."""
    for seed in range(600, 610):
        folder = tmp_path / f"s{seed}"
        write_session(folder, SessionSpec(seed=seed))
        res = run_session(load_session(folder))
        assert res.ok, [e.message for e in res.errors]
        assert res.fusion.chi2 < res.fusion.gross_bound / 20


def test_fusion_refuses_a_fit_far_from_the_small_angles(session, tmp_path, monkeypatch):
    """ux and uy swapped in platform.csv, with the platform's own check out of the way: the
    fusion's guard (an axis fitted > 10° from nominal) names the observations, never an
    'internal error'."""
    import align.session.run as run

    folder = _copy(session, tmp_path)
    p = folder / "platform.csv"
    lines = p.read_text().splitlines()
    out = [lines[0]]
    for ln in lines[1:]:
        c = ln.split(",")
        out.append(",".join([c[0], c[2], c[1], *c[3:]]))
    p.write_text("\n".join(out) + "\n")
    res = _platform_only(folder)
    assert "reads along" in _messages(res, "platform static")
    monkeypatch.setattr(run, "_check_attitudes", lambda *a, **k: None)
    res = _platform_only(folder)
    msg = _messages(res, "fusion")
    assert "from its nominal" in msg and "platform static X" in msg, msg
    assert "internal error" not in msg
