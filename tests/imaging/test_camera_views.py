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
@pytest.mark.xfail(strict=True, reason="principal points 10 px apart, 7 + 7 rendered views: "
                   "8 of 20 fire (W median 28, the Bonferroni bound at 14 views 30.5; one "
                   "camera's W reaches 27.7 over 100 seeds), 5 naming exactly the two lenses. "
                   "Achievable on these renders (their views scatter 1.5x white noise: the "
                   "best test knowing the split has 100 % power; the likelihood ratio "
                   "searched over the splits, calibrated on 100 one-lens renders, fires on "
                   "38 of 40 but names 11), not by a test that takes the residuals' noise "
                   "for the views' (the real photos scatter 4.8-5.3x: it would fire on one "
                   "real camera) nor yet by one estimating that scatter from 7 views a group "
                   "(over 40 seeds 20 fire; with the one-lens renders' 99th percentile of W, "
                   "21.8, as threshold instead of Bonferroni's 30.5, 34 would; issue 18, "
                   "open; on real-like views 10 px is beyond any test: "
                   "test_what_7_plus_7_views_can_tell...)")
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


def _k3_fixed_fit(corners: list) -> tuple[np.ndarray, np.ndarray]:
    """The 8 free intrinsics' (fx fy cx cy k1 k2 p1 p2) formal covariance [px², px, 1] of a
    k3-fixed calibration of ``corners``, and their jackknife covariance (delete one view)."""
    from imaging.camera_cov import formal_cov, jackknife_cov

    objs, flags = [OBJ] * len(corners), cv2.CALIB_FIX_K3
    _, K, D, rv, tv = cv2.calibrateCamera(objs, corners, (640, 480), None, None, flags=flags)
    formal = formal_cov(objs, corners, K, D, rv, tv, fix_k3=True)[:8, :8]
    est = jackknife_estimates(objs, corners, (640, 480), None, flags)[:, :8]
    return formal, jackknife_cov(est)


def _excess(formal: np.ndarray, jack: np.ndarray) -> float:
    """φ: the views' scatter of (fx, cx, cy) over white corner noise's, the mean generalised
    eigenvalue of the jackknife over the formal covariance (1 when the corners' errors are
    independent and the model exact)."""
    sel = np.ix_((0, 2, 3), (0, 2, 3))
    Li = np.linalg.inv(np.linalg.cholesky(formal[sel]))
    return float(np.linalg.eigvalsh(Li @ jack[sel] @ Li.T).mean())


@pytest.mark.slow
def test_what_7_plus_7_views_can_tell_principal_points_10px_focal_1_percent():
    """The information bound behind the documented limit (docs/camera.md): the best
    possible test, the Neyman–Pearson one that KNOWS the split and the direction of the
    difference (1 dof, two-sided, α 0.01), given the two halves' covariance of the 8
    intrinsics from rendered 7 + 7 views (8 seeds) times φ, the views' excess scatter over
    white corner noise measured on the real photographs (jackknife / formal; 4.8 and 5.3
    on left and right). At the real φ even that test has less than 90 % power at 10 px,
    and a 1 % focal difference is below 90 % even with white noise (φ = 1). Fails if the
    real views' excess drops below 3 (a lower φ would make 10 px reachable) or the bound
    reaches 90 %."""
    from scipy.special import ndtr, ndtri

    from imaging import read_image
    from imaging.camera import find_chessboard

    folder = real_folder("opencv-chessboard")
    phis = []
    for pat in ("left0*.jpg", "right0*.jpg"):
        corners = [find_chessboard(read_image(f), (9, 6)).astype(np.float32).reshape(-1, 1, 2)
                   for f in sorted(folder.glob(pat))]
        phis.append(_excess(*_k3_fixed_fit(corners)))
    phi = min(phis)
    z = ndtri(1 - 0.01 / 2)
    pp = np.r_[0, 0, 1, 1, 0, 0, 0, 0] * 10 / np.sqrt(2)          # 10 px, 7.07 in x and y
    focal = np.r_[K_REAL[0, 0], K_REAL[1, 1], 0, 0, 0, 0, 0, 0] * 0.01  # 1 %
    lam: dict[str, list[float]] = {"pp": [], "focal": []}
    render_phi = []
    for seed in range(8):
        corners, _ = _rendered(seed, None)
        half = len(corners) // 2
        (fa, ja), (fb, _) = _k3_fixed_fit(corners[:half]), _k3_fixed_fit(corners[half:])
        render_phi.append(_excess(fa, ja))
        for key, d in (("pp", pp), ("focal", focal)):
            lam[key].append(float(d @ np.linalg.solve(fa + fb, d)))  # white noise, φ = 1

    def power(key: str, f: float) -> float:
        return float(np.median([ndtr(np.sqrt(x / f) - z) for x in lam[key]]))

    s90 = {f: 10 * np.sqrt(f) * (z + ndtri(0.9)) / np.sqrt(np.median(lam["pp"]))
           for f in (1.0, phi)}
    print(f"phi: real left {phis[0]:.2f}, right {phis[1]:.2f}; rendered one lens (7 views) "
          f"median {np.median(render_phi):.2f}; known-split 1-dof power at 10 px: "
          f"{power('pp', 1.0):.2f} (phi 1), {power('pp', phi):.2f} (phi {phi:.1f}); focal 1 %: "
          f"{power('focal', 1.0):.2f} (phi 1), {power('focal', phi):.2f}; principal points "
          f"for 90 %: {s90[1.0]:.1f} px (phi 1), {s90[phi]:.1f} px (phi {phi:.1f})")
    assert phi >= 3.0, phis
    assert power("pp", phi) < 0.9
    assert power("focal", 1.0) < 0.9
