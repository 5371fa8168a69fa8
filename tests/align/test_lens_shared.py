"""One lens per camera in the fusion (issue 18): the lens error a camera's marks share.

Every mark of a camera is undistorted by one lens (fitted from all its images, or a given
camera model); whatever that lens gets wrong, it gets wrong for all of them at once. The
fusion must not average it down like independent noise: the marks' lens terms are carried
as signed components on the lens's error directions (``MarkResult.lens_coupling``), and the
camera block's covariance holds their products between marks of one camera
(``Block.shared``), which the budget names "lens of camera X".

Images are rendered through a physical lens (synth's Brown-Conrady camera); the pipeline is
not told the lens.
"""

from __future__ import annotations

import numpy as np
import pytest

from align.fusion import mark_block
from align.fusion.observations import MarkObs
from align.marks import MarkResult, measure_camera
from synth import CameraGeometry, ImageSpec, MarkSpec, full_well_for_snr, render_marks, write_synth
from tests.conftest import angle_error

X, Z = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])


def _images(tmp_path, k1: float, n: int, seed: int, cx: float = 0.0) -> tuple[list, float]:
    """``n`` images of one camera (k1 at f = 530 px, principal point ``cx`` px off), each a
    180 px mark at 1.5 deg, 150 px right of and 120 px above the centre; the truth angle."""
    cam = CameraGeometry(focal_px=530.0, k1=k1, pp_offset_px=(cx, 0.0))
    a = np.deg2rad(1.5)
    x, y = 150.0, -120.0
    mark = MarkSpec(a, x * np.sin(a) + y * np.cos(a), 180.0, 4.0,
                    centre_t_px=x * np.cos(a) - y * np.sin(a))
    paths = []
    for j in range(n):
        spec = ImageSpec(marks=(mark,), width=640, height=480, camera=cam, seed=seed * 100 + j,
                         full_well_e=full_well_for_snr(60, -0.6), supersample=3)
        p, _ = write_synth(render_marks(spec, with_crlb=False), tmp_path / f"m{seed}_{j}.png")
        paths.append((p, None))
    return paths, a


def _block(results: list[MarkResult]):
    obs = [MarkObs(f"x{j}", 0, X, Z, "A", 0.0, r.angle_rad, r.angle_u_rad, 0.0, f"x{j}.png",
                   "A", r.lens_coupling, r.lens_group) for j, r in enumerate(results)]
    return mark_block(obs)


def _gls_mean(values: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    one = np.ones(len(values))
    w = np.linalg.solve(cov, one)
    v = 1.0 / (one @ w)
    return float(v * (w @ values)), float(np.sqrt(v))


def test_marks_of_one_camera_share_its_lens_terms(tmp_path):
    """The signed components reproduce each mark's named lens terms (sizes), all marks of the
    camera carry the same lens group, and the camera block holds their products off the
    diagonal, its diagonal the marks' u²; a saved mark reads back the same components."""
    paths, _ = _images(tmp_path, -0.2, 3, seed=1)
    res = [r[0] for r in measure_camera(paths, label="A", expect_one=True)]
    assert all(r.found for r in res)
    assert {r.lens_group for r in res} == {"camera A"}
    for r in res:
        sizes: dict[str, float] = {}
        for k, v in r.lens_coupling.items():
            sizes[k.split(".")[0]] = float(np.hypot(sizes.get(k.split(".")[0], 0.0), v))
        lens_terms = {k: v for k, v in r.u_terms.items() if k.startswith(("lens_", "camera_"))}
        assert sizes.keys() == lens_terms.keys()
        for k, v in lens_terms.items():
            assert sizes[k] == pytest.approx(v, rel=1e-12, abs=1e-18)
        back = MarkResult.from_dict(r.to_dict())
        assert back.lens_coupling == pytest.approx(dict(r.lens_coupling), rel=1e-15)
        assert back.lens_group == r.lens_group
    b = _block(res)
    assert np.allclose(np.diag(b.cov), [r.angle_u_rad**2 for r in res], rtol=1e-9)
    c = [np.array([r.lens_coupling[k] for k in sorted(r.lens_coupling)]) for r in res]
    assert b.cov[0, 1] == pytest.approx(float(c[0] @ c[1]), rel=1e-9)
    assert b.cov[1, 2] == pytest.approx(float(c[1] @ c[2]), rel=1e-9)
    # Other cameras' marks share nothing with these.
    other = [*res, res[0]]
    obs = [MarkObs(f"x{j}", 0, X, Z, "A" if j < 3 else "B", 0.0, r.angle_rad, r.angle_u_rad,
                   0.0, f"x{j}.png", "A", r.lens_coupling, r.lens_group)
           for j, r in enumerate(other)]
    cov = mark_block(obs).cov
    assert np.all(cov[3, :3] == 0) and cov[3, 3] == pytest.approx(res[0].angle_u_rad**2)


@pytest.mark.slow
def test_averaging_images_of_one_camera_does_not_average_its_lens(tmp_path):
    """Four images of one off-centre mark through one undeclared lens per trial (k1 drawn
    from -0.3..+0.1 at the half-diagonal, principal point up to 15 px off): the lens error is
    common to the four. Their GLS mean with the shared covariance covers the truth
    (|err|/u <= 3 in every trial); treated as independent, the same mean's u is smaller by
    up to sqrt(4) and the normalised errors are larger."""
    rng = np.random.default_rng(7)
    z_shared, z_indep, ratio = [], [], []
    for seed in range(12):
        k1 = float(rng.uniform(-0.3, 0.1)) * 1.325**2  # OpenCV's k1 at f = 530 px: f/R = 1.325
        paths, truth = _images(tmp_path, k1, 4, seed, cx=float(rng.uniform(-15, 15)))
        res = [r[0] for r in measure_camera(paths, label="A", expect_one=True)]
        assert all(r.found for r in res)
        v = np.array([r.angle_rad for r in res])
        b = _block(res)
        m_s, u_s = _gls_mean(v, b.cov)
        m_i, u_i = _gls_mean(v, np.diag(np.diag(b.cov)))
        z_shared.append(angle_error(m_s, truth) / u_s)
        z_indep.append(angle_error(m_i, truth) / u_i)
        ratio.append(u_s / u_i)
    zs, zi = np.array(z_shared), np.array(z_indep)
    print(f"shared: RMS z {np.sqrt((zs**2).mean()):.2f} max {np.abs(zs).max():.2f}; "
          f"independent: RMS z {np.sqrt((zi**2).mean()):.2f} max {np.abs(zi).max():.2f}; "
          f"u ratio {np.min(ratio):.2f}..{np.max(ratio):.2f}")
    assert np.abs(zs).max() <= 3
    assert min(ratio) >= 1.0 - 1e-9  # sharing never makes the mean's u smaller here
    assert max(ratio) > 1.3  # and the lens is what limits it in some trials


@pytest.mark.slow
def test_a_session_budget_names_the_shared_lens_and_still_adds_up(tmp_path):
    """Cameras, goniometer and calibration (no platform statics, so the cameras matter),
    camera B with an undeclared k1 = -0.25 lens: the budget has a "lens of camera B" Type B
    row, every angle's shares add up to its u², the solve's own u; leaving one image of
    camera B out moves u as the linearisation (with the shared lens) predicts."""
    from dataclasses import replace

    from align.fusion import E_INDEX, E_NAMES, fuse
    from align.session import load_session, observation_blocks, run_session
    from synth.session import SessionSpec, write_session

    folder = tmp_path / "s"
    write_session(folder, SessionSpec(seed=3, effects={"lens_k1_B": -0.25},
                                      undeclared=frozenset({"lens_k1_B"}),
                                      platform_static=False))
    s = load_session(folder)
    res = run_session(s)
    f = res.fusion
    assert f is not None and f.budget is not None
    assert any(r.lens_group == "camera B" for _, r in res.marks)
    for n, (i, j) in zip(E_NAMES, E_INDEX, strict=True):
        u, cs = f.budget.angles[n]
        assert sum(c.u2 for c in cs) == pytest.approx(u**2, rel=0.01), n
        assert u == pytest.approx(f.E_u[i, j], rel=0.01), n
    sources = {c.source: c.kind for _, cs in f.budget.angles.values() for c in cs}
    assert sources.get("lens of camera B") == "typeB"
    drop = next(f"image {im.file.name}" for im, _ in res.marks if im.view == "B")
    predicted = f.budget.model.u_with(drop=[drop])
    r2 = replace(res, marks=[(im, m) for im, m in res.marks
                             if f"image {im.file.name}" != drop])
    f2 = fuse(observation_blocks(s, r2))
    # Without static poses there is no azimuth datum: the reference face's offset is carried
    # over its plausible range (align/fusion/undetermined.py), a Type B term beside the
    # linearisation, which predicts what the data give.
    assert [c.name for c in f2.undetermined] == ["reference_face_offset"]
    carried = sum(np.outer(c.shift, c.shift) for c in f2.undetermined)
    refit = np.sqrt(np.diag(f2.cov - carried))
    print("predicted/refit", np.round(predicted / refit, 4))
    assert predicted == pytest.approx(refit, rel=0.02)


def test_a_principal_point_where_the_lens_folds_the_marks_shrinks_its_range_not_inf():
    """A strong lens fitted from long marks far from the centre can fold them with the
    principal point at a corner of its +-40 px range (k1 -0.52 at f 530 px folded a 238 px
    mark near 282 px): that principal point is impossible for those marks, not an infinite
    uncertainty. The spread is taken on the largest fraction of the range where the lens
    folds none (align.lens_pp.pp_corners): finite and not zero; the full range's corners
    fold, the next larger fraction's too, and the smaller square's spread is no larger than
    the full one of a lens that folds nothing (the same marks, k1 a tenth)."""
    from align.lens_design import DEFAULT_RANGES, LineGeometry, _DesignCache
    from align.lens_pp import PP_FRACTIONS, _folds, _pp_probes, _pp_spread, pp_corners

    R = float(np.hypot(320, 240))
    lines = []
    for (x, y), deg in (((150.0, -120.0), 1.5), ((-140.0, 110.0), 60.0), ((20.0, 150.0), -80.0)):
        a = np.deg2rad(deg)
        t = np.arange(-119.0, 120.0, 4.0)
        pts = np.column_stack([x + t * np.cos(a), y - t * np.sin(a)])
        lines.append(LineGeometry(pts, np.full(len(t), 0.05)))
    cache = _DesignCache(lines, R)
    r_max = max(np.hypot(*ln.points.T).max() for ln in lines)
    rng = DEFAULT_RANGES.vector()
    lam = np.zeros(7)
    # Folds 20 px beyond the farthest centre: the sensor's radius r (1 + k1 r^2) is largest,
    # 2/3 of r, where 1 + 3 k1 r^2 = 0.
    lam[0] = -1.0 / (3 * (1.5 * (r_max + 20.0) / R) ** 2)
    det = [0]
    assert not _folds(cache, lam)
    assert any(_folds(cache, p) for p in _pp_probes(lam, det, rng))
    corners = pp_corners(cache, lam, det, rng)
    f = max(abs(corners[0][5]), abs(corners[0][6])) / rng[5]
    assert f in PP_FRACTIONS and f < 1.0
    assert not any(_folds(cache, p) for p in corners)
    larger = PP_FRACTIONS[PP_FRACTIONS.index(f) - 1]
    assert any(_folds(cache, p) for p in _pp_probes(lam, det, rng * larger))
    bound, u = _pp_spread(cache, lam, [0], det, rng)
    assert np.isfinite(u[0]) and 0 < u[0] <= bound[0] < np.inf, (u, bound)
