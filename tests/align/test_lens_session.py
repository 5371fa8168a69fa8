"""Issue 18, failure modes 4 and 5 in a session: undetermined optics on cameras + goniometer.

The sessions are rendered by synth through a physical lens (synth/optics.py: the lens maps the
scene points before the pixels integrate them); the pipeline is told nothing about it. Every
sweep is ``slow``; each has a one-seed default twin that fails on the same defect.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.fusion.budget import SHARED_PREFIX
from align.session import load_session, run_session
from synth.session import SessionSpec, write_session
from tests.align.test_fusion import TOL, _camera_and_goniometer_only, _z
from tests.conftest import ARCSEC

# Issue 18 failure mode 4: non-square pixels, fy/fx = 1.005, on both cameras, undeclared.
ASPECT = {"lens_aspect": 0.005}
# Failure mode 5's geometry: camera A's four images with marks 400-800 px from the centre of
# a 1600x1200 frame (f = 2560 px), 700 px long; k1 (OpenCV) -0.4 or +0.35 bows them
# 2.5-4.4 px at the sagitta (synth's truth says so per image).
FAR = {"image_size": (1600, 1200), "mark_length_px": 700.0,
       "far_marks_px": {"A": (400.0, 800.0)}}


# The rest of the optics declared absent (a corrected lens), the pixel aspect left out: the
# pipeline carries only the default aspect range (+-0.005), as in the session.
REST_OF_THE_LENS = "lens_k1 = 0.0\nlens_k2 = 0.0\nlens_p = 0.0\nlens_pp_px = 0.0\n"


def _run(tmp_path, seed: int, effects: dict, undeclared: bool = True, declare: str = "",
         **spec):
    folder = tmp_path / f"s{seed}"
    truth = write_session(folder, SessionSpec(
        seed=seed, effects=effects, undeclared=frozenset(effects if undeclared else ()),
        **spec))
    _camera_and_goniometer_only(folder)
    toml = (folder / "session.toml").read_text()
    for cam in "AB":
        toml = toml.replace(f"[cameras.{cam}]\n", f"[cameras.{cam}]\n{declare}")
    (folder / "session.toml").write_text(toml)
    f = run_session(load_session(folder)).fusion
    assert set(f.sources) == {"camera", "goniometer"}
    return f, truth


def _aspect_case(tmp_path, seed: int, **spec) -> tuple[np.ndarray, list[str]]:
    f, truth = _run(tmp_path, seed, ASPECT, **spec)
    # The lens (with its aspect range) is carried per camera, shared by its images.
    sources = {c.source for _, cs in f.budget.angles.values() for c in cs}
    assert {f"{SHARED_PREFIX}A", f"{SHARED_PREFIX}B"} <= sources, sorted(sources)
    return _z(f.E, f.E_u, np.array(truth["misalignment_rad"])), [e.name for e in f.loop.effects]


def test_non_square_pixels_in_a_session_within_u(tmp_path):
    """Default twin of the sweep below (one seed): no effect named, every E element within
    3 of its u, the lens carried as the camera's shared term (a shorter goniometer log, to
    stay cheap: the cameras' angles are what the aspect moves; the sweep's sharp marks cost
    ~8 s CPU a session, these ~1.7 s)."""
    z, named = _aspect_case(tmp_path, 0, revolutions=20, image_size=(480, 360),
                            mark_length_px=280.0)
    assert not named
    assert np.max(np.abs(z)) <= 3


@pytest.mark.slow
def test_non_square_pixels_in_a_session_within_u_over_seeds(tmp_path):
    """Failure mode 4: aspect 1.005 (undeclared) on both cameras, cameras + goniometer only,
    12 seeds: no effect named (no false roll), |err|/u <= 3 for every E element. Sharp marks
    (SNR 1500, 440 px) and the rest of the lens declared absent bring the cameras' u down to
    0.5-1″, where the aspect's 0.5 % of a 1-5′ angle matters (declaring square pixels instead
    reads |z| up to 2.9 on seeds 0-2)."""
    zs, named = [], []
    for seed in range(12):
        z, n = _aspect_case(tmp_path, seed, snr=1500.0, mark_length_px=440.0,
                            declare=REST_OF_THE_LENS)
        zs.append(z)
        named += n
    z = np.concatenate(zs)
    print(f"aspect 1.005: effects named {named}; E: RMS z {np.sqrt(np.mean(z**2)):.2f}, "
          f"max |z| {np.max(np.abs(z)):.2f} over {z.size}")
    assert not named
    assert np.max(np.abs(z)) <= 3


def _far_case(tmp_path, seed: int, k1: float):
    f, truth = _run(tmp_path, seed, {"lens_k1_A": k1}, **FAR)
    far = [r for r in truth["images"] if "sagitta_px" in r]
    assert len(far) == 4
    dist = [np.hypot(*r["centre_xy_px"]) for r in far]
    assert 400 <= min(dist) and max(dist) <= 800
    sag = [r["sagitta_px"] for r in far]
    return (_z(f.E, f.E_u, np.array(truth["misalignment_rad"])),
            [e.name for e in f.loop.effects], sag)


@pytest.mark.slow
def test_far_off_centre_marks_under_an_undeclared_lens_name_no_roll(tmp_path):
    """Failure mode 5: camera A's marks 400-800 px out, bowed 2.5-4.4 px by an undeclared
    lens, cameras + goniometer, 10 seeds: no camera roll (nor anything) named, E within 3 u;
    the same geometry with a real 30″ roll of A (no lens) finds it (control)."""
    zs, named, sags = [], [], []
    for k, seed in enumerate(range(10)):
        z, n, s = _far_case(tmp_path, seed, -0.4 if k % 2 == 0 else 0.35)
        zs.append(z)
        named += n
        sags += s
    z = np.concatenate(zs)
    print(f"far marks: sagitta {min(sags):.2f}-{max(sags):.2f} px (median "
          f"{np.median(sags):.2f}); effects named {named}; E: RMS z "
          f"{np.sqrt(np.mean(z**2)):.2f}, max |z| {np.max(np.abs(z)):.2f} over {z.size}")
    assert 2.5 <= np.median(sags) <= 4.4
    assert not named
    assert np.max(np.abs(z)) <= 3
    f, _ = _run(tmp_path / "roll", 1, {"camera_roll_A": 30.0}, **FAR)
    assert [e.name for e in f.loop.effects] == ["camera_roll[A]"]
    e = f.loop.effects[0]
    print(f"control: roll of A {e.estimate / ARCSEC:.1f} ± {e.u / ARCSEC:.1f}″ (truth 30)")
    assert abs(e.estimate / ARCSEC - 30.0) < TOL * e.u / ARCSEC
