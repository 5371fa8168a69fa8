"""Pose geometry: poses clustered in a cone are blamed on geometry (with the cone), never on
mixed units; a pose in another unit is still found among well-spread poses; clean tumbles are
never refused or warned of."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from align.calibration import calibrate, poses_from_samples
from align.calibration.geometry import cone_estimate, cone_half_angle, odd_pose
from align.calibration.static import _check_geometry
from align.errors import InputError

ARCSEC = np.pi / 180 / 3600


def _poses(seed, half_deg, n_poses=14, n=30, sigma=2e-5, scale=1.0, offset=5e-3):
    """Poses uniform in a cap of ``half_deg`` about a random axis, through a triad with
    ~5' misalignment, 1e-3 scale errors and output offsets ``offset`` (u = s (n_i . a) + o)."""
    rng = np.random.default_rng(seed)
    E = rng.normal(0, 300 * ARCSEC, (3, 3))
    np.fill_diagonal(E, 0)
    S = np.eye(3) + E
    S /= np.linalg.norm(S, axis=1, keepdims=True)
    k = scale * (1 + rng.normal(0, 1e-3, 3))
    c = rng.uniform(np.cos(np.radians(half_deg)), 1, n_poses)
    phi = rng.uniform(0, 2 * np.pi, n_poses)
    s = np.sqrt(1 - c * c)
    axis = rng.normal(size=3)
    rot = Rotation.align_vectors([axis / np.linalg.norm(axis)], [[0, 0, 1]])[0].as_matrix()
    d = np.c_[s * np.cos(phi), s * np.sin(phi), c] @ rot.T
    pid = np.repeat(np.arange(n_poses), n)
    u = ((d @ S.T) * k + rng.normal(0, offset, 3))[pid]
    u = u + rng.normal(0, sigma * scale, u.shape)
    return poses_from_samples(pid, u, pid * 1.0), d, k


def _judge(p):
    try:
        _check_geometry(Path("f.csv"), p)
        cal = calibrate(p)
    except InputError as e:
        return "refused", str(e), None
    return ("warned" if any("cone" in w for w in cal.notes) else "clean"), "", cal


def test_cone_estimates():
    for seed in range(5):
        p, d, _ = _poses(seed, 20.0)
        assert np.radians(12) < cone_estimate(p.u) < np.radians(25)
        assert cone_half_angle(d) == pytest.approx(np.arccos(
            np.clip(d @ (d.mean(0) / np.linalg.norm(d.mean(0))), -1, 1)).max())


@pytest.mark.slow
@pytest.mark.parametrize("half", [5.0, 10.0])
def test_a_narrow_cone_is_refused_as_geometry_with_its_angle(half):
    for seed in range(4):
        p, _, _ = _poses(seed, half)
        what, msg, _ = _judge(p)
        assert what == "refused" and msg.startswith("geometry: the 14 poses span only a cone")
        assert "mixed units" not in msg and "tumble the unit" in msg
        cone = float(msg.split("cone of ~")[1].split("°")[0])
        assert 0.5 * half <= cone <= 1.5 * half, msg


def test_a_wider_cone_is_kept_with_a_warning_and_honest_u():
    """30 deg: the fit determines everything (u(k) ~ 0.1-1 %); a warning names the cone,
    and the sensitivities are within their (large) u of the truth."""
    for seed in range(4):
        p, _, k = _poses(seed, 30.0)
        what, _, cal = _judge(p)
        assert what == "warned"
        (w,) = [n for n in cal.notes if "cone" in n]
        assert "geometry: the 14 poses span only a cone of ~" in w
        m = cal.model
        assert np.all(np.abs(m.sensitivity() - k) < 4.5 * m.sensitivity_u())


@pytest.mark.slow
def test_clean_tumbles_are_never_refused_nor_warned():
    """The cube (6 faces + 8 corners, 0.2 deg placement) and 14 random poses over the whole
    sphere: no geometry warning, no 'mixed units', 30 seeds each."""
    faces = np.vstack([np.eye(3), -np.eye(3)])
    corners = np.array([[a, b, c] for a in (1, -1) for b in (1, -1) for c in (1, -1)],
                       float) / np.sqrt(3)
    for seed in range(30):
        p, _, _ = _poses(seed, 180.0)
        assert _judge(p)[0] == "clean", seed
        rng = np.random.default_rng(seed)
        d = np.vstack([faces, corners]) + rng.normal(0, 4e-3, (14, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        u = np.repeat(d * (1 + rng.normal(0, 1e-3, 3)) + rng.normal(0, 5e-3, 3), 20, 0)
        u = u + rng.normal(0, 2e-5, u.shape)
        q = poses_from_samples(np.repeat(np.arange(14), 20), u, np.arange(len(u)) * 0.01)
        assert _judge(q)[0] == "clean", seed


@pytest.mark.parametrize("factor", [9.80665, 1 / 9.80665, 1000.0])
def test_a_pose_in_another_unit_is_still_found(factor):
    for seed in range(10):
        p, _, _ = _poses(seed, 180.0)
        u = p.u.copy()
        j = seed % len(u)
        u[j] *= factor
        assert odd_pose(u)[0] == j
        bad = type(p)(u, p.t, p.temp, p.sigma_u, p.count, p.labels)
        with pytest.raises(InputError, match=f"pose {p.labels[j]} is .* mixed units"):
            _check_geometry(Path("f.csv"), bad)


def test_no_mixed_units_on_clean_poses_in_any_unit():
    """Offsets up to 0.3 g, outputs in g, m/s², V with a 2.5 V offset, counts: 200 seeds."""
    for seed in range(200):
        scale, offset = [(1.0, 5e-3), (9.80665, 3.0), (1.0, 2.5), (4096.0, 800.0)][seed % 4]
        p, _, _ = _poses(seed, 180.0, n=3, scale=scale, offset=offset)
        assert odd_pose(p.u) is None, seed
