"""The declared non-linearity bound (align/calibration/nonlinearity.py): one rule for the flag
and the session keys, the candidate refused beyond the bound, the term carried in u where the
poses do not fit it — its size the propagated uniform term, checked against refits of
rendered K3 — and user 8's cubic tumbles covered once the datasheet's bound is declared.

The truth is rendered by user 8's independent generator (``tests/align/user8_inputs.py``:
u = k (a + K3 a³) + o + white noise of 0.3 mg a sample, 200 samples a pose)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from align.calibration import calibrate, poses_from_samples
from align.calibration.effects import K3, NONLIN
from align.calibration.nonlinearity import BOUND, FLAG, UG, UNEXCLUDED, bound_ug, parse_flag
from align.cli import main
from align.errors import InputError
from align.session.decisions import alarm_limit

from . import user8_inputs as ui

CUBE26 = ui.cube26()
CUBE14 = CUBE26[np.count_nonzero(CUBE26, axis=1) != 2]  # the 6 faces and 8 corners
FACES = CUBE26[np.count_nonzero(CUBE26, axis=1) == 1]
FACE_LABELS = [("+" if f.sum() > 0 else "-") + "xyz"[int(np.argmax(np.abs(f)))] for f in FACES]
K3_TRUE = 1e-4  # 100 µg/g³ (user 8's case)
Z_MAX = 3.0


def _rows(tr: ui.Triad, ups: np.ndarray, seed: int, labels=None) -> list[tuple]:
    return ui.tumble_rows(tr, ups, seed, labels=labels)


def _poses(rows: list[tuple], labels: bool = False):
    lab = np.array([r[0] for r in rows])
    names = list(dict.fromkeys(lab))
    pose = np.array([names.index(x) for x in lab])
    u = np.array([r[1:4] for r in rows])
    t = np.array([r[4] for r in rows])
    return poses_from_samples(pose, u, t, names if labels else None)


def _cli(tmp_path: Path, rows: list[tuple], capsys, *extra: str) -> tuple[int, dict]:
    p = ui.write_tumble(rows, tmp_path / "tumble.csv")
    rc = main(["calibrate", str(p), "--units", "g", "--json", "-", "-q", "--force", *extra])
    out = capsys.readouterr().out
    return rc, json.loads(out[out.find("{"):])


def _zk(js: dict, tr: ui.Triad) -> np.ndarray:
    """k against the linear coefficient of u = k (a + K3 a³) in its u."""
    return ((np.array(js["scale_factors_v_per_g"]) - np.array(tr.k))
            / np.array(js["scale_factors_u_v_per_g"]))


# ---------------------------------------------------------------- the rule


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), 3e3, "100", True, None])
def test_the_rule_refuses_what_is_no_bound(bad):
    with pytest.raises(InputError, match=r"^here = "):
        bound_ug(bad, K3, "here")


def test_the_flag_reads_micro_g_and_an_empty_part_declares_nothing():
    assert parse_flag("50,100") == pytest.approx((50 * UG, 100 * UG))
    assert parse_flag(",100") == (None, pytest.approx(100 * UG))
    assert parse_flag("0, ") == (0.0, None)


@pytest.mark.parametrize("bad", ["100", "1,2,3", ",", "abc,5", "-1,5", "5,3000"])
def test_bad_flag_is_refused_in_one_line_naming_it(tmp_path, capsys, bad):
    rows = _rows(ui.Triad(), CUBE14, 0)
    p = ui.write_tumble(rows, tmp_path / "t.csv")
    assert main(["calibrate", str(p), "--units", "g", f"{FLAG}={bad}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and FLAG in err[0], err


def test_bad_session_key_is_refused_naming_it(tmp_path):
    from align.session.config import load_session

    (tmp_path / "t.csv").write_text("pose,ux,uy,uz\n")
    toml = tmp_path / "session.toml"
    toml.write_text('[calibration]\nstatic = "t.csv"\nk3_bound_ug_per_g3 = -5\n')
    with pytest.raises(InputError, match=r"\[calibration\] k3_bound_ug_per_g3 = -5"):
        load_session(tmp_path)
    toml.write_text('[calibration]\nstatic = "t.csv"\nk2_bound_ug_per_g2 = "big"\n')
    with pytest.raises(InputError, match=r"\[calibration\] k2_bound_ug_per_g2 = 'big'"):
        load_session(tmp_path)
    toml.write_text('[calibration]\nstatic = "t.csv"\nk3_bound_ug_per_g3 = 100\n')
    assert load_session(tmp_path).calibration.nonlinearity_bound == (
        None, pytest.approx(100 * UG))


# ---------------------------------------------------------------- the term


def test_six_faces_carry_k3_as_the_chord():
    """On six faces k is the 1 g chord k (1 + K3) (x³ = x at ±1 g): the term on k is the
    bound's uniform u, b k / sqrt 3 exactly; nothing declared: u unchanged, and the result
    says K3 is not separable and names the flag."""
    tr = ui.Triad()
    poses = _poses(_rows(tr, FACES, 1, FACE_LABELS), labels=True)
    plain = calibrate(poses)
    assert plain.widening is None and not plain.nonlinearity["k3_separable"]
    assert FLAG in plain.nonlinearity["statement"]
    assert "k is the 1 g chord k (1 + K3)" in plain.nonlinearity["statement"]
    b = 100 * UG
    cal = calibrate(poses, nonlinearity_bound=(None, b))
    p = cal.widening.to_dict()["parameters"]
    for ax, k in zip("xyz", np.abs(tr.k), strict=True):
        assert p[f"k_{ax}"][BOUND] == pytest.approx(b * k / np.sqrt(3), rel=1e-3)
        assert p[f"k_{ax}"]["u"] ** 2 == pytest.approx(
            plain.model.u_of(f"k_{ax}") ** 2 + p[f"k_{ax}"][BOUND] ** 2, rel=1e-9)
    assert cal.ok and cal.nonlinearity["carried"] == [K3]


def test_clean_26_poses_widen_only_by_the_propagated_term():
    """Clean cube poses, K3 declared at 100 µg/g³: no effect added, every u² grows by the
    term's u² alone (the declaration replaces the undeclared K3 term), and the term is the
    uniform ±b through each k's sensitivity to K3 — the sensitivity checked against refits of
    the same tumble rendered with K3 = 30 µg/g³ on one axis at a time (same noise: the shift
    is the fit's response alone)."""
    seed, b, d = 3, 100 * UG, 30 * UG
    tr = ui.Triad()
    plain = calibrate(_poses(_rows(tr, CUBE26, seed)))
    cal = calibrate(_poses(_rows(tr, CUBE26, seed)), nonlinearity_bound=(None, b))
    assert tuple(plain.widening.to_dict()["terms"]) == (UNEXCLUDED,)
    assert cal.loop.effects == () and cal.ok
    assert tuple(cal.widening.to_dict()["terms"]) == (BOUND,)
    p = cal.widening.to_dict()["parameters"]
    for name in p:
        u0 = p[name]["u_noise"]
        assert p[name]["u"] ** 2 == pytest.approx(u0 ** 2 + p[name][BOUND] ** 2, rel=1e-9)
    S = np.zeros((3, 3))  # d k_i / d K3_a
    for a in range(3):
        k3 = np.zeros(3)
        k3[a] = d
        moved = calibrate(_poses(_rows(ui.Triad(k3=tuple(k3)), CUBE26, seed)))
        assert moved.loop.effects == ()
        S[:, a] = (moved.model.k - plain.model.k) / d
    for i, ax in enumerate("xyz"):
        assert p[f"k_{ax}"][BOUND] == pytest.approx(
            b * np.linalg.norm(S[i]) / np.sqrt(3), rel=0.02)


def test_a_candidate_beyond_the_declared_bound_is_refused():
    """K3 = 600 µg/g³ rendered, 100 declared: the loop's K3 is refused naming the declared
    bound (undeclared the same data add it), and the result does not pass as clean."""
    tr = ui.Triad(k3=(6e-4, -6e-4, 6e-4))
    poses = _poses(_rows(tr, CUBE26, 0))
    assert K3 in [e.name for e in calibrate(poses).loop.effects]
    cal = calibrate(poses, nonlinearity_bound=(None, 100 * UG))
    why = [r.reason for r in cal.loop.refused if r.name == K3]
    assert why and "declared bound" in why[0], cal.loop.refused
    assert K3 not in [e.name for e in cal.loop.effects]
    assert cal.widening is not None and BOUND in cal.widening.to_dict()["terms"]


def test_k2_bound_is_carried_through_its_own_sensitivity():
    """K2 is even: on the six faces (x² = 1) it is a bias shift b_a of the axis's faces, not
    a scale factor: the term sits on the biases; on k only through the offset inside x
    (2 K2 b, b = 4 mg here: under 2 % of k's noise u)."""
    tr = ui.Triad()
    poses = _poses(_rows(tr, FACES, 2, FACE_LABELS), labels=True)
    cal = calibrate(poses, nonlinearity_bound=(50 * UG, None))
    p = cal.widening.to_dict()["parameters"]
    for ax in "xyz":
        assert p[f"bias_{ax}"][BOUND] == pytest.approx(50 * UG / np.sqrt(3), rel=0.05)
        assert p[f"k_{ax}"][BOUND] < 0.02 * p[f"k_{ax}"]["u"]
    assert cal.nonlinearity["carried"] == [NONLIN]


# ---------------------------------------------------------------- user 8's cubic tumbles


def test_user8_cubic_is_covered_with_the_bound_declared(tmp_path, capsys):
    """User 8's seed 2 on 26 poses: K3 = ±100 µg/g³, no K3 the poses can test (undeclared:
    carried by ``k3_not_excluded``, below); with the bound declared at the true |K3| every k
    within 3 u, the declared term named in the JSON (it replaces the undeclared one)."""
    tr = ui.Triad(k3=(K3_TRUE, -K3_TRUE, K3_TRUE))
    rc, js = _cli(tmp_path, _rows(tr, CUBE26, 2), capsys, FLAG, ",100")
    assert np.all(np.abs(_zk(js, tr)) <= Z_MAX), _zk(js, tr)
    assert BOUND in js["u_widening"]["terms"] and js["nonlinearity"]["carried"] == [K3]
    assert UNEXCLUDED not in js["u_widening"]["terms"]
    assert any(BOUND in w or "non-linearity declared" in w for w in js["warnings"])


# ------------------------------------------------- nothing declared: K3 the poses do not exclude


def _k3(k: float) -> ui.Triad:
    return ui.Triad(k3=(k, -k, k))


def test_undeclared_k3_the_poses_miss_is_carried(tmp_path, capsys):
    """User 8's seed 2, nothing declared: K3 = ±100 µg/g³ leaves a χ² drop of ~6 (no test
    sees it) and moved k by 7.4-9.1 u with exit 0, ok, no warning (the strict xfail of
    test_independent_user8, before). Now the free-K3 fit is averaged over: every k within
    3 u, ok, the term in u_widening per parameter and in the nonlinearity record, which
    names the flag that replaces it."""
    tr = _k3(K3_TRUE)
    rc, js = _cli(tmp_path, _rows(tr, CUBE26, 2), capsys)
    z = _zk(js, tr)
    assert np.all(np.abs(z) <= Z_MAX), z
    assert rc == 0 and js["ok"] and js["effects"] == []
    assert tuple(js["u_widening"]["terms"]) == (UNEXCLUDED,)
    for ax in "xyz":
        par = js["u_widening"]["parameters"][f"scale_factor_{ax}"]
        assert par[UNEXCLUDED] > par["u_noise"]  # the rule: it moves k by more than 1 u
    nl = js["nonlinearity"]
    assert nl["carried"] == [K3] and UNEXCLUDED in nl["statement"] and FLAG in nl["statement"]


def test_paper14_says_k_is_neither_the_chord_nor_the_linear_coefficient():
    """The paper's 14 poses (faces and corners) cannot measure K3 (skipped): u unchanged,
    and the statement does not call k the chord (at a corner x³ = x/3: with K3 = 100 µg/g³
    k sat up to 4.1 u from the chord and 11.5 u from the linear coefficient over 24 runs,
    benchmarks/calibration_k3.py) but says it lies between them, naming the flag."""
    cal = calibrate(_poses(_rows(ui.Triad(), CUBE14, 4)))
    said = cal.nonlinearity["statement"]
    assert cal.widening is None and not cal.nonlinearity["k3_separable"]
    assert "between the linear coefficient and the 1 g chord" in said and FLAG in said, said


def test_clean_26_poses_carry_it_as_a_statement_not_a_warning(tmp_path, capsys):
    """Clean 26 cube poses: the poses bound K3 no better than ~±100 µg/g³ whatever the data
    (a design's property): u of k carries it (×1-10 of its noise u: still a measurement), the
    line under the table says so, and no warning is raised (on every clean tumble it would be
    a false alarm); biases barely move (the term is k's)."""
    rc, js = _cli(tmp_path, _rows(ui.Triad(), CUBE26, 1000), capsys)
    assert rc == 0 and js["ok"] and js["warnings"] == [] and js["effects"] == []
    par = js["u_widening"]["parameters"]
    assert all(1.0 < par[f"scale_factor_{ax}"]["factor"] < 10.0 for ax in "xyz")
    assert all(par[f"bias_{ax}"]["factor"] < 1.1 for ax in "xyz")
    assert js["nonlinearity"]["carried"] == [K3]


@pytest.mark.slow
def test_undeclared_k3_sweep_is_covered_or_flagged(tmp_path, capsys):
    """Nothing declared, 26 cube poses, K3 = ±30, ±100, ±300 µg/g³ (both sign patterns),
    seeds 0-7 each: every k within 3 u of the linear coefficient, or the result flagged
    (a warning or not ok). Before: K3 100 left k up to 9.3 u off unflagged (5 of 12 seeds);
    measured after: max 2.9 u (K3 300 is added by the loop)."""
    bad = []
    for k3 in (30 * UG, 100 * UG, 300 * UG):
        for sign in (1, -1):
            for s in range(8):
                tr = _k3(sign * k3)
                rc, js = _cli(tmp_path, _rows(tr, CUBE26, s), capsys)
                z = _zk(js, tr)
                flagged = rc != 0 or not js["ok"] or bool(js["warnings"])
                if not flagged and np.any(np.abs(z) > Z_MAX):
                    bad.append(f"K3 {sign * k3 / UG:+.0f} seed {s}: k {np.round(z, 2)}")
    assert bad == []


@pytest.mark.slow
def test_clean_26_poses_false_warnings_over_seeds(tmp_path, capsys):
    """120 clean 26-pose tumbles (seeds 2000-2119): a warning or not ok at most as often as
    a true 1 % rate allows (alarm_limit: false-fail probability < 1e-3); the K3 term on each
    (a statement); every k and bias within 3.5 u."""
    n, alarms, bad = 120, 0, []
    for s in range(2000, 2000 + n):
        tr = ui.Triad()
        rc, js = _cli(tmp_path, _rows(tr, CUBE26, s), capsys)
        alarms += rc != 0 or not js["ok"] or bool(js["warnings"])
        zb = ((np.array(js["bias_g"]) - np.array(tr.o) / np.array(tr.k))
              / np.array(js["bias_u_g"]))
        if np.any(np.abs(_zk(js, tr)) > 3.5) or np.any(np.abs(zb) > 3.5):
            bad.append(s)
    assert alarms <= alarm_limit(n), alarms
    assert bad == []


@pytest.mark.slow
@pytest.mark.parametrize("ups", ["cube26", "cube14"])
def test_user8_cubic_over_seeds(tmp_path, capsys, ups):
    """K3 = ±100 µg/g³ declared at its true size, seeds 0-11: every k within 3 u of the
    linear coefficient (measured: 26 poses max 2.9, 14 poses max 2.4)."""
    bad = []
    for s in range(12):
        tr = ui.Triad(k3=(K3_TRUE, -K3_TRUE, K3_TRUE))
        rc, js = _cli(tmp_path, _rows(tr, CUBE26 if ups == "cube26" else CUBE14, s), capsys,
                      FLAG, ",100")
        z = _zk(js, tr)
        bad += [f"seed {s}: k {np.round(z, 2)}"] if np.any(np.abs(z) > Z_MAX) else []
    assert bad == []


@pytest.mark.slow
def test_clean_with_a_bound_adds_no_effect_over_seeds():
    """Clean 26-pose tumbles with K2, K3 declared (50 µg/g², 100 µg/g³), seeds 100-129: no
    effect added, ok, every k and bias within 3 u."""
    bad = []
    for s in range(100, 130):
        tr = ui.Triad()
        cal = calibrate(_poses(_rows(tr, CUBE26, s)), nonlinearity_bound=(50 * UG, 100 * UG))
        m = cal.model
        zk = (m.sensitivity() - np.array(tr.k)) / m.sensitivity_u()
        zb = (m.bias - np.array(tr.o) / np.array(tr.k)) / m.u_per_axis("bias")
        if cal.loop.effects or not cal.ok or np.any(np.abs(zk) > 3) or np.any(np.abs(zb) > 3):
            bad.append((s, [e.name for e in cal.loop.effects], cal.ok, zk, zb))
    assert bad == []


def test_a_session_key_reaches_the_calibration(tmp_path):
    """``[calibration] k3_bound_ug_per_g3`` in session.toml: the session's calibration
    carries the declared K3 (synth's session; the calibration and platform poses alone)."""
    from dataclasses import replace

    from align.session import load_session, run_session
    from synth.session import SessionSpec
    from tests.conftest import imageless_session

    folder = imageless_session(tmp_path, SessionSpec(seed=11))  # its images are not read
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace("[calibration]\n",
                                             "[calibration]\nk3_bound_ug_per_g3 = 100\n", 1))
    s = load_session(folder)
    cal = run_session(replace(s, images=(), goniometer=None)).calibration
    assert cal.nonlinearity["k3_bound_ug_per_g3"] == pytest.approx(100.0)
    assert cal.nonlinearity["carried"] == [K3]
    assert BOUND in cal.widening.to_dict()["terms"]
