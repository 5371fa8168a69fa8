"""Fusion of every instrument into E against synth's truth, and the fusion loop.

Tolerances: each estimate against truth within 4.5 of its own stated uncertainty (the
uncertainty is propagated from every source's noise; 4.5 sigma keeps a correct estimator's
false-failure rate per test below ~1e-4 over the six angles).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from align.fusion import E_INDEX, E_NAMES, NOT_EXCLUDED_TAG, REF, TILT
from align.session import load_session, run_session
from align.warnings import session_warnings
from synth.session import SessionSpec, write_session
from tests.conftest import ARCSEC

TOL = 4.5


def _session(root: Path, name: str, seed: int, undeclared: dict | None = None,
             declared: dict | None = None, **spec):
    eff = {**(declared or {}), **(undeclared or {})}
    folder = root / name
    truth = write_session(folder, SessionSpec(seed=seed, effects=eff,
                                              undeclared=frozenset(undeclared or {}), **spec))
    return run_session(load_session(folder)), np.array(truth["misalignment_rad"])


def _z(E: np.ndarray, U: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.array([(E[i, j] - truth[i, j]) / U[i, j] for i, j in E_INDEX])


def _z_before(loop, truth: np.ndarray) -> np.ndarray:
    q = loop.before.quantities
    return np.array([(q[n][0] - truth[i, j]) / q[n][1] for n, (i, j) in
                     zip(E_NAMES, E_INDEX, strict=True)])


@pytest.fixture(scope="module")
def clean(session21_run):
    """A clean session (seed 21, shared with the run: tests/conftest.py) and its truth."""
    return session21_run


@pytest.mark.slow
def test_clean_session_recovers_E_within_its_uncertainty(clean):
    res, truth = clean
    f = res.fusion
    assert not res.errors
    assert set(f.sources) == {"camera", "goniometer", "ellipsoid", "platform static"}
    z = _z(f.E, f.E_u, truth)
    assert np.all(np.abs(z) < TOL), z
    # The inputs allow sub-arc-second angles: every u is below 0.5" (E is 1-5 arc-minutes).
    assert f.E_u[~np.eye(3, dtype=bool)].max() < 0.5 * ARCSEC
    assert not f.loop.effects, [e.name for e in f.loop.effects]
    assert f.consistent and f.inflation == 1.0
    assert 0.001 < f.p_value


# No reversal images, only levelled platform poses and a MEMS-grade triad (1 mV noise, ~400 ug
# a sample): the cameras then weigh as much as the other sources for E_zx, E_zy, so a roll
# biases E; the levelled readings (E_xz, E_yz) and the ellipsoid's non-orthogonality are the
# redundancy that exposes it. (With a navigation-grade triad the ellipsoid and the platform
# readings outweigh the cameras ~100:1 and a roll hardly moves E: see the reversal test.)
NO_REVERSAL = dict(views=("A", "B"), platform_poses=("L000", "L090", "L180", "L270"),
                   noise_v=1e-3)


@pytest.mark.slow
def test_reversal_makes_E_immune_to_camera_roll(tmp_path):
    """With reversal images the roll cancels in E even before the loop names it."""
    res, truth = _session(tmp_path, "roll_rev", seed=12, undeclared={"camera_roll_B": 60.0})
    f = res.fusion
    assert [e.name for e in f.loop.effects] == ["camera_roll[B]"]
    assert np.all(np.abs(_z_before(f.loop, truth)) < TOL)
    assert np.all(np.abs(_z(f.E, f.E_u, truth)) < TOL)


def test_undeclared_camera_roll_is_found_through_redundant_sources(tmp_path):
    roll = 60.0
    res, truth = _session(tmp_path, "roll", seed=12, undeclared={"camera_roll_B": roll},
                          **NO_REVERSAL)
    f = res.fusion
    names = [e.name for e in f.loop.effects]
    assert names == ["camera_roll[B]"], names
    e = f.loop.effects[0]
    assert abs(e.estimate / ARCSEC - roll) < TOL * e.u / ARCSEC
    after = _z(f.E, f.E_u, truth)
    before = _z_before(f.loop, truth)
    assert np.all(np.abs(after) < TOL), after
    assert np.max(np.abs(before)) > 2 * TOL, before
    assert f.consistent


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(12, 20))
def test_an_undeclared_30_arcsec_roll_is_never_a_silent_wrong_answer(tmp_path, seed):
    """Camera B rolled by an undeclared 30″ without reversal views: the loop names the roll,
    or E's u carries it (a candidate the data cannot exclude: Type B), or the result is not
    ok — never an ok E off by more than its u says. Before align/fusion/plausible.py seed 12
    named an 8° reference-face offset (E z -5.8) and seed 13 nothing (z -9.4), both ok; seed
    18 named the platform's levelling in place of the roll (Δχ² 3.7 apart; the roll, judged
    only beside the levelling, ran away to -6147 ± 7292″) and carried nothing (z +4.91, ok):
    the roll in place of the levelling is now carried — or, where the data cannot determine
    it beside the levelling (u freed beyond its range's σ: seed 18, E z within 0.72), carried
    over its plausible range (align/fusion/undetermined.py)."""
    res, truth = _session(tmp_path, "roll30", seed=seed, undeclared={"camera_roll_B": 30.0},
                          **NO_REVERSAL)
    f = res.fusion
    z = _z(f.E, f.E_u, truth)
    carried = {c.source for _, cs in f.budget.angles.values() for c in cs
               if NOT_EXCLUDED_TAG in c.source}
    print(f"seed {seed}: ok {res.ok}, effects {[e.name for e in f.loop.effects]}, "
          f"carried {sorted(carried)}, undetermined {[c.name for c in f.undetermined]}, "
          f"z {np.round(z, 2)}")
    # No effect beyond any set-up error is an explanation.
    assert all(abs(e.estimate) < np.deg2rad(1.0) for e in f.loop.effects), f.loop.effects
    assert not res.ok or np.all(np.abs(z) < TOL), z
    # The roll is named or carried (not excluded, or over its range), never silently dropped.
    names = [e.name for e in f.loop.effects]
    ranged = [c.name for c in f.undetermined]
    assert ("camera_roll[B]" in names or "camera_roll[B]" in ranged
            or any(c.startswith("camera_roll[B]") for c in carried)), (names, ranged, carried)


@pytest.mark.slow
def test_declared_camera_roll_is_applied_not_searched(tmp_path):
    res, truth = _session(tmp_path, "roll_declared", seed=12, declared={"camera_roll_B": 40.0})
    f = res.fusion
    assert not f.loop.effects
    assert np.all(np.abs(_z(f.E, f.E_u, truth)) < TOL)


@pytest.mark.slow
def test_undeclared_reference_face_offset_is_found(tmp_path):
    off = 25.0
    res, truth = _session(tmp_path, "ref", seed=13, undeclared={"reference_offset": off})
    f = res.fusion
    assert [e.name for e in f.loop.effects] == [REF]
    e = f.loop.effects[0]
    assert abs(e.estimate / ARCSEC - off) < TOL * e.u / ARCSEC
    assert np.all(np.abs(_z(f.E, f.E_u, truth)) < TOL)
    assert np.max(np.abs(_z_before(f.loop, truth))) > 3 * TOL


def test_undeclared_table_tilt_is_found(tmp_path):
    res, truth = _session(tmp_path, "tilt", seed=14,
                          undeclared={"table_tilt_x": 15.0, "table_tilt_y": -10.0})
    f = res.fusion
    assert [e.name for e in f.loop.effects] == [TILT]
    comp = dict((c, (v, u)) for c, v, u in f.loop.effects[0].components)
    for axis, true in (("x", 15.0), ("y", -10.0)):
        v, u = comp[axis]
        assert abs(v / ARCSEC - true) < TOL * u / ARCSEC
    assert np.all(np.abs(_z(f.E, f.E_u, truth)) < TOL)
    # The one number of a two-component effect is its length, not one of its components;
    # the warning names both components, and the key to declare them with.
    e = f.loop.effects[0]
    assert e.estimate == pytest.approx(np.hypot(comp["x"][0], comp["y"][0]))
    msg = next(w for w in session_warnings(res) if "tilt of the table axis" in w)
    for axis in ("x", "y"):
        assert f"{axis} {comp[axis][0] / ARCSEC:+.1f} ± {comp[axis][1] / ARCSEC:.1f}″" in msg
    assert (f"table_tilt_arcsec = [{comp['x'][0] / ARCSEC:+.1f}, "
            f"{comp['y'][0] / ARCSEC:+.1f}]") in msg, msg


def test_inconsistency_no_candidate_explains_is_reported(clean):
    """One mark scribed crooked on its housing (one image, one view, 15 of its u): no fusion
    candidate explains a single observation, so the fusion must say so, inflate its
    uncertainty and point at the observation. (The clean session of the module, its marks
    copied before one is changed: the fixture is shared.)"""
    from dataclasses import replace

    from align.fusion import fuse
    from align.session import observation_blocks

    res, _ = clean
    s = res.session
    assert res.fusion.consistent
    k = int(np.argmin([r.angle_u_rad for _, r in res.marks]))
    im, r = res.marks[k]
    marks = list(res.marks)
    marks[k] = (im, replace(r, angle_rad=r.angle_rad + 15 * r.angle_u_rad))
    f = fuse(observation_blocks(s, replace(res, marks=marks)))
    assert not f.consistent
    assert f.inflation > 1.5
    worst = max(f.rows, key=lambda row: abs(row.normalised))
    assert worst.source == "camera" and im.file.name in worst.label


def test_platform_calibration_applied_to_readings(clean, tmp_path):
    """Readings at known platform attitudes come back as those directions in P."""
    from synth.session import TABLE1_K, Triad

    res, truth = clean
    pc = res.platform_calibration()
    tj = json.loads((Path(res.session.folder) / "truth.json").read_text())
    triad = Triad(k=TABLE1_K, bias=tuple(tj["bias_platform_g"]), noise_v=4.8e-5,
                  axes=tuple(map(tuple, tj["axes"])))
    rng = np.random.default_rng(5)
    g = rng.normal(size=(6, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    n = 4000
    for gp in g:
        u = triad.outputs(np.repeat(gp[None], n, 0), np.zeros(n), np.zeros(n), rng)
        a = pc.specific_force(u).mean(0)
        # Noise of the mean (20 ug per sample), E's u (< 0.5" ~ 2.4 urad) and the
        # calibration's bias and scale uncertainty (a few ug): 15 ug is > 4.5 sigma.
        assert np.max(np.abs(a - gp)) < 15e-6, (a - gp) * 1e6
    # Without the misalignment (the seed paper's floating frame) the error is arc-minutes.
    a_c = pc.model.specific_force(u).mean(0)
    assert np.max(np.abs(a_c - g[-1])) > 100e-6


@pytest.mark.slow
def test_clean_sessions_normalised_errors_and_no_false_effects(tmp_path):
    """12 clean sessions: the RMS of the 72 normalised errors is 1 within 3 of its sampling
    sd (1/sqrt(2 x 72) = 0.083), and the loop adds nothing (~4 candidates at alpha 1e-3: 0.05
    false additions expected over 12 sessions; one is tolerated)."""
    z, added = [], 0
    for seed in range(12):
        res, truth = _session(tmp_path, f"c{seed}", seed=500 + seed)
        f = res.fusion
        z.append(_z(f.E, f.E_u, truth))
        added += len(f.loop.effects)
    z = np.concatenate(z)
    assert 0.75 < np.sqrt(np.mean(z**2)) < 1.25, np.sqrt(np.mean(z**2))
    assert abs(np.mean(z)) < 3 / np.sqrt(len(z))
    assert added <= 1


def _camera_and_goniometer_only(folder: Path) -> None:
    """session.toml without the tumble and the platform poses: the cameras and the
    goniometer are the only sources (where a camera's angle weighs most)."""
    out, skip = [], False
    for line in (folder / "session.toml").read_text().splitlines():
        if line.startswith("["):
            skip = line.startswith(("[calibration", "[platform"))
        if not skip:
            out.append(line)
    (folder / "session.toml").write_text("\n".join(out) + "\n")


@pytest.mark.slow
def test_lens_on_one_camera_is_no_camera_roll(tmp_path):
    """Issue 9 item 4: an undeclared radial distortion on camera A only (k1 -0.3 or +0.2,
    OpenCV units), camera + goniometer sessions over 10 seeds: the marks' loop takes the
    distortion out and carries its u, so the fusion names no camera roll (nor anything
    else) and E stays within ~3.5 of its u (60 angles: P(|z| > 3.5) ~ 5e-4 each)."""
    z, named, z_lens = [], [], []
    for k, seed in enumerate(range(300, 310)):
        k1 = -0.3 if k % 2 == 0 else 0.2
        folder = tmp_path / f"s{seed}"
        truth = write_session(folder, SessionSpec(seed=seed, effects={"lens_k1_A": k1},
                                                  undeclared=frozenset({"lens_k1_A"})))
        _camera_and_goniometer_only(folder)
        res = run_session(load_session(folder))
        f = res.fusion
        assert set(f.sources) == {"camera", "goniometer"}
        named += [e.name for e in f.loop.effects]
        zs = _z(f.E, f.E_u, np.array(truth["misalignment_rad"]))
        z.append(zs)
        # No azimuth datum (no X/Y-up poses): the reference face's offset is carried over
        # its plausible range and sets E_xY's, E_yX's u (align/fusion/undetermined.py); the
        # lens's share is judged on the other angles (camera A's roll, with its lens
        # undeclared, may be carried too: freed, its u beyond its range's).
        undet = {c.name: c.shift**2 > 0.5 * np.diag(f.cov) for c in f.undetermined}
        assert set(undet) <= {"reference_face_offset", "camera_roll[A]"}, set(undet)
        set_by = np.any(list(undet.values()), axis=0)
        assert [n for n, b in zip(E_NAMES, set_by, strict=True) if b] == ["E_xY", "E_yX"]
        z_lens.append(zs[~set_by])
    z = np.concatenate(z)
    z_lens = np.concatenate(z_lens)
    print(f"effects named: {named}; normalised errors of E: RMS "
          f"{np.sqrt(np.mean(z**2)):.2f}, max |z| {np.max(np.abs(z)):.2f} over {z.size}")
    assert not named
    assert np.max(np.abs(z)) < 3.5
    # u is never understated; since the lens belongs to the camera and an undetermined lens
    # is carried as a Type B term over its plausible range (align/lens.py), it is
    # conservative here (RMS 0.67 on these seeds: the error is the lens's actual value, not
    # a draw from its range) — bounded so that it stays useful.
    rms = np.sqrt(np.mean(z_lens**2))
    print(f"RMS over the angles the reference face does not set: {rms:.2f}")
    assert 0.5 < rms < 1 + 3.3 / np.sqrt(2 * z_lens.size)
    # The same sessions do show a real roll of camera A (30", u ~3"): "no roll" above is
    # not blindness.
    folder = tmp_path / "roll"
    write_session(folder, SessionSpec(seed=301, effects={"camera_roll_A": 30.0},
                                      undeclared=frozenset({"camera_roll_A"})))
    _camera_and_goniometer_only(folder)
    f = run_session(load_session(folder)).fusion
    assert [e.name for e in f.loop.effects] == ["camera_roll[A]"]
    e = f.loop.effects[0]
    assert abs(e.estimate / ARCSEC - 30.0) < TOL * e.u / ARCSEC


class _Linear:
    """A toy fusion stage: y = X e + Σ terms, σ 1″, the six angles e [rad] observed through X
    (the loop's contract only: residuals, χ², the terms' estimates, E's quantities)."""

    def __init__(self, X: np.ndarray, y: np.ndarray):
        self.X, self.y = X, y

    def fit(self, terms):
        from align.loop import StageFit

        A = np.column_stack([self.X, *[t.columns for t in terms]])
        p, *_ = np.linalg.lstsq(A, self.y, rcond=None)
        cov = np.linalg.inv(A.T @ A) * ARCSEC**2
        u = np.sqrt(np.diag(cov))
        r = self.y - A @ p
        return StageFit(r, np.full(len(r), ARCSEC), A.shape[1],
                        {"i": np.arange(len(r), dtype=float)}, "i",
                        {t.name: (float(p[6 + k]), float(u[6 + k]))
                         for k, t in enumerate(terms)},
                        {n: (float(p[k]), float(u[k])) for k, n in enumerate(E_NAMES)},
                        payload=cov[:6, :6])


@pytest.mark.parametrize("apart", [1.0, 100.0])
def test_an_alternative_the_loop_did_not_exclude_is_carried(apart):
    """Two candidates near-degenerate in the residuals (both explain the same signal, 15 σ)
    but moving E differently (a E_yZ, b E_zY, by 5″): the data are b's plus a part w only a
    fits, χ² ``apart``. The loop names a; beside it b runs away (±5″: no test). b in place
    of a, with a freed back at the loop's alpha: ``apart`` 1 — a's choice not established,
    b's E less a's carried (E_zY was 34 u off; now 1.0 u); 100 — established (w is a's
    signal, 10 σ), nothing carried. (Seed 18's camera roll and platform levelling, in toy
    form.)"""
    from align.fusion.plausible import not_excluded
    from align.loop import Candidate, Term, run_loop

    rng = np.random.default_rng(3)
    n = 60
    X = rng.normal(size=(n, 6))
    proj = np.eye(n) - X @ np.linalg.pinv(X)  # onto what X cannot fit: the residuals
    r = proj @ rng.normal(size=n)
    r *= 3.0 / np.linalg.norm(r)
    w = proj @ rng.normal(size=n)
    w -= r * (w @ r) / (r @ r)
    w *= np.sqrt(apart) / 5.0 / np.linalg.norm(w)  # 5 w: χ² `apart` between the models
    da, db = np.zeros(6), np.zeros(6)
    da[3], db[5] = 1.0, -1.0  # in E: a moves E_yZ, b E_zY
    ca, cb = r + X @ da, r + w + X @ db
    truth = rng.normal(size=6) * ARCSEC
    noise = rng.normal(size=n) - 5 * w  # the data favour a by `apart`
    y = X @ truth + (5 * cb + noise) * ARCSEC
    stage = _Linear(X, y)

    def cand(name, col):
        return Candidate(name, "rad", name, lambda fit: Term(name, "rad", col))

    cands = [cand("a", ca), cand("b", cb)]
    loop = run_loop(stage, cands)
    assert [t.name for t in loop.terms] == ["a"]
    cov = loop.after.payload
    carried = not_excluded(stage, cands, loop, cov, 1e-3)
    e = np.array([loop.after.quantities[k][0] for k in E_NAMES])
    z_before = (e - truth) / np.sqrt(np.diag(cov))
    if apart > 10:
        assert not carried
        return
    assert [(c.name, c.instead_of) for c in carried] == [("b", "a")]
    assert np.max(np.abs(z_before)) > 10, z_before
    cov = cov + sum(np.outer(c.shift, c.shift) for c in carried)
    z = (e - truth) / np.sqrt(np.diag(cov))
    assert np.all(np.abs(z) < TOL), z
