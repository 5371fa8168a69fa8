"""Whether a chessboard calibration's views are of ONE camera (imaging/camera_views.py, issue
18): the real stereo rig's left and right views pass alone and fire together, naming the
groups; views of two lenses rendered through known optics fire, of one lens they do not."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from imaging.camera import calibrate_corners, jackknife_estimates, views_one_camera
from imaging.camera_views import best_splits, group_cov, split_count
from tests.conftest import real_folder

K_REAL = np.array([[533.50, 0.0, 340.28], [0.0, 533.75, 234.72], [0.0, 0.0, 1.0]])
D_REAL = np.array([-0.29865, 0.14847, 0.00149, -0.00014, 0.0])
"""The real chessboard camera (left01-07, OpenCV's calibration), k3 at 0."""
OBJ = np.zeros((54, 3), np.float32)
OBJ[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)


def _projected_views(rng: np.random.Generator, K: np.ndarray, n: int, noise_px: float
                     ) -> list[np.ndarray]:
    """n views of the 9x6 board through (K, D_REAL) from random poses over the 640x480
    frame, corners with white noise [px] (no image: the twin's fast route)."""
    out = []
    mid = np.array([4.0, 2.5, 0.0])
    while len(out) < n:
        rvec = rng.uniform(-1, 1, 3) * np.radians([35, 35, 20])
        z = rng.uniform(14, 22)
        R, _ = cv2.Rodrigues(rvec)
        t = np.array([rng.uniform(-0.45, 0.45) * z, rng.uniform(-0.35, 0.35) * z, z]) - R @ mid
        p = cv2.projectPoints(OBJ, rvec, t, K, D_REAL)[0].reshape(-1, 2)
        if p.min() < 25 or p[:, 0].max() > 615 or p[:, 1].max() > 455:
            continue
        out.append((p + rng.normal(0, noise_px, p.shape)).astype(np.float32).reshape(-1, 1, 2))
    return out


def _check(views: list[np.ndarray], names: list[str]) -> dict:
    flags = cv2.CALIB_FIX_K3
    objs = [OBJ] * len(views)
    est = jackknife_estimates(objs, views, (640, 480), None, flags)
    return views_one_camera(objs, views, (640, 480), names, None, flags, est)


def test_two_lenses_mixed_fire_and_are_named_one_lens_does_not():
    """Default twin of the rendered sweep: 4 + 4 views of two lenses whose principal points
    are 12 px apart (projected corners, 0.1 px white noise) fire, the groups exactly the
    two lenses' views; 6 views of one lens do not. Fails if the check is gone, cannot
    split, or takes one camera's scatter for two."""
    rng = np.random.default_rng(18)
    K2 = K_REAL.copy()
    K2[1, 2] += 12.0
    mixed = _projected_views(rng, K_REAL, 4, 0.1) + _projected_views(rng, K2, 4, 0.1)
    names = [f"a{i}" for i in range(4)] + [f"b{i}" for i in range(4)]
    c = _check(mixed, names)
    assert c["tested"] and not c["one_camera"], c
    assert sorted(map(sorted, c["groups"])) == [names[:4], names[4:]], c["groups"]
    assert c["p"] < 1e-3, c
    one = _check(_projected_views(rng, K_REAL, 6, 0.1), [f"v{i}" for i in range(6)])
    assert one["tested"] and one["one_camera"], one


def test_best_split_finds_a_planted_split_and_group_cov_dominates_both():
    """The proposal: 12 points, 6 shifted by 6 sigma along one axis of three, are split
    into exactly those; the groups' covariance is at least the formal and the jackknife
    covariance in every direction, and a few views' scale the formal one up."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal((12, 3))
    x[6:, 1] += 6.0
    _, (g, *_) = best_splits(x)
    assert sorted([list(np.flatnonzero(g)), list(np.flatnonzero(~g))]) == [
        list(range(6)), list(range(6, 12))]
    A = rng.standard_normal((9, 9))
    formal = A @ A.T + np.eye(9)
    B = rng.standard_normal((9, 2))
    jack = 4 * B @ B.T  # rank 2: a few views
    sel = np.ix_((0, 2, 3), (0, 2, 3))
    for views in (3, 7):
        c = group_cov(formal, jack, views)
        for other in (formal[sel], jack[sel]):
            assert np.linalg.eigvalsh(c - other).min() > -1e-9 * np.trace(c)
    assert np.trace(group_cov(formal, jack, 3)) > np.trace(group_cov(formal, jack, 7))
    assert split_count(7) == 35 and split_count(14) == 8086


def test_too_few_views_are_not_tested():
    views = _projected_views(np.random.default_rng(1), K_REAL, 5, 0.1)
    m = calibrate_corners([OBJ] * 5, views, (640, 480), [f"v{i}" for i in range(5)],
                          k3="fixed")
    assert m.views_one_camera["tested"] is False and not m.problems
    assert "needs 6" in m.views_one_camera["why"]


@pytest.mark.slow
def test_real_stereo_views_pass_alone_and_fire_together():
    """The real rig (../shared/data/real/opencv-chessboard): left0*.jpg alone and right0*.jpg
    alone pass; all 14 fire, the groups exactly left and right (printed: W, p)."""
    from imaging import calibrate_chessboard, read_image

    folder = real_folder("opencv-chessboard")
    for pat, one in (("left0*.jpg", True), ("right0*.jpg", True), ("*.jpg", False)):
        files = sorted(folder.glob(pat))
        m, _ = calibrate_chessboard({f.name: read_image(f) for f in files}, (9, 6))
        c = m.views_one_camera
        print(f"{pat}: W {c['W']:.1f}, p {c['p']:.2g}, groups {c['groups']}")
        assert c["one_camera"] is one, c
        assert bool(m.problems) is not one
    assert sorted(map(sorted, c["groups"])) == [
        [f"left0{i}.jpg" for i in range(1, 8)], [f"right0{i}.jpg" for i in range(1, 8)]]
    assert "NOT OK: the views are not of one camera" in m.problems[0]


def _rendered(seed: int, K2: np.ndarray | None, views: int = 14) -> tuple[list, list]:
    """``views`` chessboard photographs rendered through the real-like lens (k3 0) at the
    real photos' noise (:data:`tests.align.test_camera_k3_rendered.NOISE_DN`: 0.16-0.2 px
    RMS), the second half through ``K2`` (None: one lens); their corners found as
    ``align camera`` finds them, and the names (a* first lens, b* second)."""
    from imaging.camera import find_chessboard
    from tests.align.chessboard_render import board_photos
    from tests.align.test_camera_k3_rendered import NOISE_DN

    rng = np.random.default_rng(seed)
    lenses = [(K_REAL, views)] if K2 is None else [(K_REAL, views // 2), (K2, views // 2)]
    corners, names = [], []
    for j, (K, n) in enumerate(lenses):
        for img in board_photos(rng, n, _rays(K.tobytes()), K, D_REAL,
                                noise_dn=NOISE_DN).values():
            c = find_chessboard(img, (9, 6))
            if c is not None:
                corners.append(c.astype(np.float32).reshape(-1, 1, 2))
                names.append(f"{'ab'[j]}{len(names)}")
    return corners, names


_RAYS: dict[bytes, np.ndarray] = {}


def _rays(key: bytes) -> np.ndarray:
    from tests.align.chessboard_render import ray_grid

    if key not in _RAYS:
        _RAYS[key] = ray_grid(np.frombuffer(key).reshape(3, 3), D_REAL, (640, 480))
    return _RAYS[key]


def _sweep(seeds: range, K2: np.ndarray | None) -> tuple[list[float], int, int]:
    """W per seed, how many fired, and how many of those named exactly the two lenses."""
    ws, fired, named = [], 0, 0
    for seed in seeds:
        corners, names = _rendered(seed, K2)
        m = calibrate_corners([OBJ] * len(corners), corners, (640, 480), names)
        c = m.views_one_camera
        ws.append(c["W"])
        if not c["one_camera"]:
            fired += 1
            truth = [sorted(n for n in names if n[0] == ab) for ab in "ab"]
            named += sorted(map(sorted, c["groups"])) == truth
    return ws, fired, named


@pytest.mark.slow
def test_one_lens_rendered_false_alarms_at_most_one_percent():
    """100 seeds x 14 chessboard photographs of one real-like lens, rendered through it at
    the real photos' noise, calibrated as `align camera` does: at most 1 fires."""
    ws, fired, _ = _sweep(range(100), None)
    print(f"one lens: W median {np.median(ws):.1f}, 99th pct {np.percentile(ws, 99):.1f}, "
          f"max {max(ws):.1f}; fired {fired}/100")
    assert fired <= 1


@pytest.mark.slow
def test_two_lenses_principal_points_20px_apart_fire_and_are_named():
    """7 + 7 photographs of two real-like lenses whose principal points are 20 px apart (the
    real rig's are 19.7 px), 10 seeds: every one fires, naming exactly the two lenses'
    photographs."""
    K2 = K_REAL.copy()
    K2[:2, 2] += 20 / np.sqrt(2)
    ws, fired, named = _sweep(range(10), K2)
    print(f"principal points 20 px apart: W median {np.median(ws):.1f}, min {min(ws):.1f}; "
          f"fired {fired}/10, named {named}")
    assert fired == 10 and named == 10


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="principal points 10 px apart, 7 + 7 views: 8 of 20 "
                   "fire (W median 28, the Bonferroni bound at 14 views 30.5; one camera's "
                   "W reaches 27.7 over 100 seeds), 5 of them naming exactly the two "
                   "lenses: power 40 %, not the 90 % issue 18 asks (open)")
def test_two_lenses_principal_points_10px_apart_fire_90_percent():
    """7 + 7 photographs of two real-like lenses whose principal points are 10 px apart
    (7.07 px in x and y), 20 seeds: at least 18 should fire, each naming exactly the two
    lenses' photographs (they do not: the check's limit, kept visible)."""
    K2 = K_REAL.copy()
    K2[:2, 2] += 10 / np.sqrt(2)
    ws, fired, named = _sweep(range(20), K2)
    print(f"principal points 10 px apart: W median {np.median(ws):.1f}, min {min(ws):.1f}; "
          f"fired {fired}/20, named {named}")
    assert fired >= 18 and named == fired


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="focal lengths 1 % apart (5.3 px) are within what 7 "
                   "views' own scatter of fx allows (0 of 10 fire, W median 10.5, one "
                   "camera's 11.0): no power there (issue 18, open)")
def test_two_lenses_focal_lengths_1_percent_apart_fire_90_percent():
    """7 + 7 photographs of two real-like lenses whose focal lengths are 1 % apart, 10
    seeds: at least 9 should fire (they do not: the limit of the check, kept visible)."""
    K2 = K_REAL.copy()
    K2[0, 0] *= 1.01
    K2[1, 1] *= 1.01
    ws, fired, _ = _sweep(range(10), K2)
    print(f"focal lengths 1 % apart: W median {np.median(ws):.1f}; fired {fired}/10")
    assert fired >= 9
