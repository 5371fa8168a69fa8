"""An independent user's checks of axis-align (a metrology engineer deciding on a platform).

Written from README.md, docs/ and the command's --help only; the data come from this user's
own generators (``user11_inputs``: numpy physics, nothing from ``synth`` or the pipeline).
The commands run in-process through ``align.cli.main`` (as ``python3 -m align ...``).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from align.cli import main
from tests.align import user11_inputs as ui

FACES = ["--faces", "ref,y,x,z", "--latitude", "50.45"]


def cli(*args: str) -> tuple[int, str, str]:
    """``align ARGS`` in-process: exit status, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in args])
        except SystemExit as e:  # argparse's own exits
            rc = e.code
    return rc, out.getvalue(), err.getvalue()


def run_session(folder: Path, *extra: str) -> tuple[int, dict, str]:
    out = folder.parent / f"{folder.name}.json"
    rc, _, err = cli("run", folder, "--json", out, "--force", "-q", *extra)
    return rc, json.loads(out.read_text()), err


def normalised_errors(d: dict, truth: ui.Truth) -> dict[str, float]:
    e = np.array(d["misalignment_arcsec"])
    u = np.array(d["misalignment_u_arcsec"])
    return {n: float((e[ui._IDX[n]] - truth.angle(n) / ui.ARCSEC) / u[ui._IDX[n]])
            for n in ui.E_NAMES}


def u_of(d: dict, name: str) -> float:
    return float(np.array(d["misalignment_u_arcsec"])[ui._IDX[name]])


def refusal_problems(rc: int, err: str, fname: str) -> list[str]:
    """How a run departs from a refusal as the docs promise (exit 2, one line naming the
    file, no traceback): [] when it is one."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    return ([f"{fname}: exit {rc}, not 2"] * (rc != 2)
            + [f"{fname}: a traceback"] * ("Traceback" in err)
            + [f"{fname}: not one line naming it: {err!r}"]
            * (len(lines) != 1 or fname not in (lines or [""])[0]))


# ---------------------------------------------------------------- (1) a session from scratch

def _tolerance_for(truth: ui.Truth, name: str, outside_by: float) -> str:
    """A tolerance on one angle whose upper/lower limit sits ``outside_by`` ″ inside the
    truth (negative: the truth is inside the zone by that much)."""
    v = truth.angle(name) / ui.ARCSEC
    lim = abs(v) - outside_by
    return f"\n[tolerance]\n{name} = {lim:.4f}\ndecision = \"guarded\"\nk = 2.0\n"


def test_own_session_E_u_budget_and_verdict(tmp_path):
    """One seed: every angle within 4 u of the truth, ok, budget adds to u², and a platform
    whose E_zX is 4 u (from the user's expected u of ~0.6″: 2.4″) outside its tolerance is
    not passed."""
    truth = ui.make_truth(3)
    folder = ui.write_session(tmp_path / "unit3", truth, 3,
                              tolerance=_tolerance_for(truth, "E_zX", 2.4))
    rc, d, err = run_session(folder)
    assert rc == 0 and d["ok"] is True, err
    z = normalised_errors(d, truth)
    assert max(abs(v) for v in z.values()) < 4.0, z
    for name, b in d["budget"]["angles"].items():
        total = sum(c["u2_arcsec2"] for c in b["contributions"])
        assert abs(total / b["u_arcsec"] ** 2 - 1) < 0.01, (name, total, b["u_arcsec"])
        assert abs(b["u_arcsec"] / u_of(d, name) - 1) < 0.01, name
    assert 2.4 > 3 * u_of(d, "E_zX"), "the case must be decidable at k = 2"
    assert d["disposition"]["verdict"] == "FAIL", d["disposition"]["reason"]
    # the angle's line agrees with the documented rule (docs/decision.md)
    (a,) = [a for a in d["disposition"]["angles"] if a["name"] == "E_zX"]
    v, u, lo, hi = a["value_arcsec"], a["u_arcsec"], a["lower_arcsec"], a["upper_arcsec"]
    assert abs(a["margin_arcsec"] - min(v - lo, hi - v)) < 1e-9
    assert abs(a["guard_arcsec"] - 2 * u) < 1e-9
    p = norm.cdf((hi - v) / u) - norm.cdf((lo - v) / u)
    assert abs(a["p_conform"] - p) < 1e-6, (a["p_conform"], p)


@pytest.mark.slow
def test_own_sessions_over_seeds_E_within_u(tmp_path):
    """12 seeds × 6 angles: normalised errors' RMS near 1, none beyond 4, all ok."""
    zs = []
    for seed in range(20, 32):
        truth = ui.make_truth(seed)
        rc, d, err = run_session(ui.write_session(tmp_path / f"s{seed}", truth, seed))
        assert rc == 0 and d["ok"], (seed, err)
        zs += list(normalised_errors(d, truth).values())
    zs = np.array(zs)
    rms = float(np.sqrt(np.mean(zs ** 2)))
    assert 0.7 < rms < 1.35 and np.max(np.abs(zs)) < 4.0, (rms, np.round(zs, 2))


@pytest.mark.slow
def test_own_sessions_clockwise_table_and_tilted_table_axis(tmp_path):
    """A clockwise table (faces named as they pass: ref, z, x, y) and, separately, a table
    axis tilted 20″/−10″ under the levelled poses (undeclared): E within 4 u, ok; the tilt
    found within 4 u of mine and said."""
    for seed in (80, 81):
        truth = ui.make_truth(seed)
        folder = ui.write_session(tmp_path / f"cw{seed}", truth, seed)
        ui.write_gonio(folder / "gonio.csv", truth, seed, direction="cw")
        toml = (folder / "session.toml").read_text()
        toml = toml.replace('faces = ["ref", "y", "x", "z"]', 'faces = ["ref", "z", "x", "y"]')
        (folder / "session.toml").write_text(toml.replace('"ccw"', '"cw"'))
        rc, d, err = run_session(folder)
        assert rc == 0 and d["ok"], (seed, err)
        z = normalised_errors(d, truth)
        assert max(abs(v) for v in z.values()) < 4.0, (seed, "cw", z)

        folder = ui.write_session(tmp_path / f"tilt{seed}", truth, seed,
                                  table_tilt_arcsec=(20.0, -10.0))
        rc, d, err = run_session(folder)
        assert rc == 0 and d["ok"], (seed, err)
        z = normalised_errors(d, truth)
        assert max(abs(v) for v in z.values()) < 4.0, (seed, "tilt", z)
        (tilt,) = [e for e in d["effects"] if e["name"] == "platform_tilt"]
        for c, want in zip(tilt["components"], (20.0, -10.0), strict=True):
            assert abs(c["estimate"] / ui.ARCSEC - want) < 4 * c["u"] / ui.ARCSEC, tilt
        assert any("tilt of the table axis" in w for w in d["warnings"]), d["warnings"]


@pytest.mark.slow
def test_own_session_from_a_continuous_tumble_recording(tmp_path):
    """The tumble as a 100 Hz recording (t,ux,uy,uz; 14 holds of 4 s, hand-turned 2 s
    moves with 2 mg of shake): 14 static intervals found, E within 4 u, ok."""
    for seed in (90, 91):
        truth = ui.make_truth(seed)
        folder = ui.write_session(tmp_path / f"rec{seed}", truth, seed)
        ui.write_tumble_recording(folder / "tumble.csv", truth, seed)
        rc, d, err = run_session(folder)
        assert rc == 0 and d["ok"], (seed, err)
        assert len(d["stages"]["calibration"]["poses"]) == 14
        z = normalised_errors(d, truth)
        assert max(abs(v) for v in z.values()) < 4.0, (seed, z)


@pytest.mark.slow
def test_drifting_bias_in_the_tumble_is_never_a_confident_wrong_answer(tmp_path):
    """A warm-up drift of 2-3 µg/s per axis over the 80 s recording (160-240 µg): either
    every angle within 4 u of my truth, or the result not ok (exit 2) with the reason."""
    for seed in (90, 91, 92):
        truth = ui.make_truth(seed)
        truth.extra["drift"] = (2e-6, -3e-6, 2.5e-6)
        folder = ui.write_session(tmp_path / f"drift{seed}", truth, seed)
        ui.write_tumble_recording(folder / "tumble.csv", truth, seed)
        rc, d, err = run_session(folder)
        z = normalised_errors(d, truth)
        if d["ok"]:
            assert rc == 0 and max(abs(v) for v in z.values()) < 4.0, (seed, z)
        else:
            assert rc == 2 and "NOT OK" in err, (seed, rc, err)


# ---------------------------------------------------------------- (2) decisions

@pytest.mark.slow
def test_budget_model_predicts_u_without_the_goniometer(tmp_path):
    """The budget's linearisation (groups A, C) gives the stated u, and with the goniometer's
    group left out it gives the u a run without [goniometer] states (within 2 %)."""
    truth = ui.make_truth(8)
    folder = ui.write_session(tmp_path / "full", truth, 8)
    rc, d, err = run_session(folder)
    assert rc == 0, err
    model = d["budget"]["model"]

    # the candidates' columns are held at zero (docs: held, ranged, others): not estimated
    zero = {i for key in ("held", "ranged", "others") for h in model.get(key, ())
            for i in h["index"]}
    est = [i for i in range(len(model["parameters"])) if i not in zero]

    def u_pred(groups: list[dict]) -> np.ndarray:
        info = sum(np.array(g["A"]).T @ np.linalg.solve(np.array(g["C"]), np.array(g["A"]))
                   for g in groups)[np.ix_(est, est)]
        return np.sqrt(np.diag(np.linalg.inv(info)))[:6] / ui.ARCSEC * model["inflation"]

    names = model["parameters"][:6]
    stated = np.array([u_of(d, n) for n in names])
    np.testing.assert_allclose(u_pred(model["groups"]), stated, rtol=0.01)
    toml = (folder / "session.toml").read_text()
    a, b = toml.index("[goniometer]"), toml.index("[platform]")
    (folder / "session.toml").write_text(toml[:a] + toml[b:])
    rc, d2, err = run_session(folder)
    assert rc == 0 and d2["ok"], err
    without = u_pred([g for g in model["groups"] if g["kind"] != "gonio"])
    np.testing.assert_allclose(without, [u_of(d2, n) for n in names], rtol=0.02)
    assert without[names.index("E_xY")] > 3 * stated[names.index("E_xY")]


@pytest.mark.slow
@pytest.mark.parametrize("outside_u, allowed", [(-3.0, {"PASS", "INCONCLUSIVE"}),
                                                (+3.0, {"FAIL", "INCONCLUSIVE"}),
                                                (-5.0, {"PASS"}), (+5.0, {"FAIL"})])
def test_verdict_just_inside_and_outside_over_seeds(tmp_path, outside_u, allowed):
    """A platform whose true E_zX is 3 u inside (outside) its tolerance is never FAILed
    (PASSed) under the guarded rule with k = 2; 5 u inside (outside): PASS (FAIL) on every
    seed bar chance (a 3 u error: 1 seed in ~700). u is the user's own 0.6″ figure of this
    set-up; the run's stated u is checked to be within 30 % of it."""
    wrong = []
    for seed in range(40, 48):
        truth = ui.make_truth(seed)
        tol = _tolerance_for(truth, "E_zX", outside_u * 0.6)
        rc, d, err = run_session(ui.write_session(tmp_path / f"s{seed}", truth, seed,
                                                  tolerance=tol))
        assert rc == 0, err
        assert 0.42 < u_of(d, "E_zX") < 0.78, u_of(d, "E_zX")
        if d["disposition"]["verdict"] not in allowed:
            wrong.append((seed, d["disposition"]["verdict"], d["disposition"]["reason"]))
    assert not wrong, wrong


@pytest.mark.slow
def test_p_conform_all_is_the_joint_normal_over_the_box(tmp_path):
    """Three angles toleranced near their values (simple rule): each p_conform is
    Phi((U-v)/u) - Phi((L-v)/u) and p_conform_all the 6x6 covariance's normal over the box
    (scipy's multivariate_normal.cdf), as docs/decision.md says."""
    from scipy.stats import multivariate_normal

    truth = ui.make_truth(9)
    folder = ui.write_session(tmp_path / "unit9", truth, 9)
    rc, d, err = run_session(folder)
    assert rc == 0, err
    e = np.array(d["misalignment_arcsec"])
    lines = ["\n[tolerance]\ndecision = \"simple\"\n"]
    for name, f in (("E_xZ", 0.5), ("E_yZ", -0.3), ("E_zX", 1.0)):
        v = e[ui._IDX[name]]
        lines.append(f"{name} = [{v - 50:.4f}, {v + f * u_of(d, name):.4f}]\n")
    with open(folder / "session.toml", "a") as fh:
        fh.write("".join(lines))
    rc, d, err = run_session(folder)
    assert rc == 0, err
    disp = d["disposition"]
    judged = [a for a in disp["angles"] if a["lower_arcsec"] is not None]
    assert [a["name"] for a in judged] == ["E_xZ", "E_yZ", "E_zX"], judged
    ix = [d["angle_names"].index(a["name"]) for a in judged]
    cov = np.array(d["covariance_rad2"])[np.ix_(ix, ix)] / ui.ARCSEC ** 2
    v = np.array([a["value_arcsec"] for a in judged])
    lo = np.array([a["lower_arcsec"] for a in judged])
    hi = np.array([a["upper_arcsec"] for a in judged])
    for a, m, s_ in zip(judged, v, np.sqrt(np.diag(cov)), strict=True):
        assert abs(a["p_conform"] - (norm.cdf((a["upper_arcsec"] - m) / s_)
                                     - norm.cdf((a["lower_arcsec"] - m) / s_))) < 1e-4, a
    p_all = multivariate_normal(mean=v, cov=cov).cdf(hi, lower_limit=lo)
    assert abs(disp["p_conform_all"] - p_all) < 2e-3, (disp["p_conform_all"], p_all)
    assert disp["verdict"] == "FAIL" and disp["worst"] == "E_yZ", disp["reason"]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "a carried not-excluded term's fate after a measurement is a draw: seed 51's session "
    "carries 'platform_level not excluded (+3.6 +- 1.4\")' (2.85\" of E_xZ's 2.91\"); the plan "
    "now predicts it (align plan: the target E_xZ, a second tumble 2.66 +- 1.30\", the term "
    "still carried at p 0.73, 'no measurement improves E_xZ by more than the noise of its "
    "prediction') and the tumble realised drops it: 0.488\" (-82 %, z -1.7 against the "
    "stated noise; the user's tolerance 15 %); the advice is the best of the three (static "
    "1.99\", gonio 2.90\"); seed 50 (nothing carried) within it. Decided (code17): the plan "
    "states the spread of that draw (the +- 1.30\" holds the carried term's two branches) "
    "and advises nothing within it; a fixed 15 % on one draw is not what it states: the "
    "realised z -1.7 is inside its stated noise"))
def test_plan_advice_lowers_u_most(tmp_path):
    """The advised measurement, done (with my own generator), lowers the critical angle's u
    as predicted (within 15 %) and more than the other measurements I can do."""
    for seed in (50, 51):
        truth = ui.make_truth(seed)
        base = ui.write_session(tmp_path / f"b{seed}", truth, seed)
        rc, d, err = run_session(base)
        assert rc == 0, err
        rc, out, err = cli("plan", tmp_path / f"b{seed}.json", "--json",
                           tmp_path / f"p{seed}.json")
        assert rc == 0, err
        plan = json.loads((tmp_path / f"p{seed}.json").read_text())
        target = plan["target"]
        done = {"static": {"static_samples": 80}, "tumble": {"tumble_repeats": 2},
                "gonio": {"gonio_kw": {"revolutions": 120}}}
        obtained = {}
        for kind, kw in done.items():
            rc, dk, err = run_session(ui.write_session(tmp_path / f"{kind}{seed}", truth,
                                                       seed, **kw))
            assert rc == 0, err
            obtained[kind] = u_of(dk, target)
        best = plan["options"][0]
        assert best["kind"] in obtained, best
        assert abs(obtained[best["kind"]] / best["u_after_arcsec"] - 1) < 0.15, (
            best, obtained)
        assert obtained[best["kind"]] <= min(obtained.values()) * 1.05, (best, obtained)


# ---------------------------------------------------------------- (3) files as users have them

def _gonio_variants(base: str) -> dict[str, bytes]:
    lines = base.splitlines()
    body = "\n".join(lines[1:]) + "\n"
    quoted = "".join(",".join(f'"{c}"' for c in ln.split(",")) + "\n" for ln in lines[1:])
    return {
        "crlf.csv": base.replace("\n", "\r\n").encode(),
        "bom.csv": b"\xef\xbb\xbf" + base.encode(),
        "semicolon.csv": base.replace(",", ";").encode(),
        "tab.csv": base.replace(",", "\t").encode(),
        "units_in_comments.csv": ("# ring laser RL-7, counts are laser periods\n# t in s\n"
                                  "count,counter,ref,t [s]\n" + body).encode(),
        "trailing_empty_line.csv": (base + "\n").encode(),
        "excel_quoted.csv": ('"count","counter","ref","t"\n' + quoted).encode(),
        "t_in_ms.csv": ("count,counter,ref,t [ms]\n" + "".join(
            ",".join(ln.split(",")[:3] + [f"{float(ln.split(',')[3]) * 1e3:.3f}"]) + "\n"
            for ln in lines[1:])).encode(),
    }


def _gonio_reference(tmp_path: Path) -> tuple[str, dict]:
    """My counter log of seed 5 (30 revolutions) and its angles, checked against my truth."""
    truth = ui.make_truth(5)
    ui.write_gonio(tmp_path / "base.csv", truth, 5, revolutions=30)
    rc, _, err = cli("gonio", tmp_path / "base.csv", *FACES, "--json", tmp_path / "b.json")
    assert rc == 0, err
    ref = json.loads((tmp_path / "b.json").read_text())
    z = (np.array(ref["angles_deg"]) - np.rad2deg(ui.gonio_truth_angles(truth))) * 3600
    assert np.all(np.abs(z) < 4 * np.array(ref["angles_u_arcsec"])), z
    return (tmp_path / "base.csv").read_text(), ref


def _angle_problems(tmp_path: Path, name: str, data: bytes, ref: dict) -> list[str]:
    """The file ``data`` saved as ``name`` against the reference log's angles and u (bit
    for bit; a ms -> s conversion may move the last bit): what differs, one line each."""
    (tmp_path / name).write_bytes(data)
    rc, _, err = cli("gonio", tmp_path / name, *FACES, "--json", tmp_path / f"{name}.json")
    if rc != 0:
        return [f"{name}: exit {rc}: {err}"]
    d = json.loads((tmp_path / f"{name}.json").read_text())
    rtol = 1e-12 if name == "t_in_ms.csv" else 0.0
    return [f"{name}: {key} {d[key]} != {ref[key]}" for key in ("angles_deg", "angles_u_arcsec")
            if not np.allclose(d[key], ref[key], rtol=rtol, atol=0)]


def _bad_gonio(base: str) -> dict[str, str]:
    lines = base.splitlines()
    return {"twice_with_header.csv": base + base,
            "twice_no_header.csv": base + "\n".join(lines[1:]) + "\n",
            "decimal_comma.csv": "count;counter;ref;t\n" + "".join(
                ";".join(ln.split(",")[:3] + [ln.split(",")[3].replace(".", ",")]) + "\n"
                for ln in lines[1:])}


def test_counter_log_as_users_save_it(tmp_path):
    """Default twin of the slow test below: one file with every saving quirk at once
    (BOM, CRLF, ';', units in comments, Excel quotes, a trailing empty line) gives the same
    angles and u bit for bit; the log written twice into itself is refused in one line."""
    base, ref = _gonio_reference(tmp_path)
    lines = base.splitlines()
    quirky = ("# ring laser RL-7, counts are laser periods\n# t in s\n"
              '"count";"counter";"ref";"t [s]"\n' + "".join(
                  ";".join(f'"{c}"' for c in ln.split(",")) + "\n" for ln in lines[1:])
              + "\n").replace("\n", "\r\n")
    assert _angle_problems(tmp_path, "quirky.csv", b"\xef\xbb\xbf" + quirky.encode(),
                           ref) == []
    (tmp_path / "twice.csv").write_text(_bad_gonio(base)["twice_with_header.csv"])
    rc, _, err = cli("gonio", tmp_path / "twice.csv", *FACES, "-q")
    assert refusal_problems(rc, err, "twice.csv") == []


@pytest.mark.slow
def test_counter_log_as_users_save_it_each_way(tmp_path):
    """The same counter log saved eight ways gives the same angles and u, bit for bit; the
    log written twice into itself (with or without a second header) and a decimal-comma
    file are refused in one line naming the file and the line."""
    base, ref = _gonio_reference(tmp_path)
    bad = []
    for name, data in _gonio_variants(base).items():
        bad += _angle_problems(tmp_path, name, data, ref)
    for name, text in _bad_gonio(base).items():
        (tmp_path / name).write_text(text)
        rc, _, err = cli("gonio", tmp_path / name, *FACES, "-q")
        bad += refusal_problems(rc, err, name)
    assert bad == []


@pytest.mark.xfail(strict=True, reason=(
    "align gonio on a 120-row count,counter,ref log (no t column) followed by the same 120 "
    "rows again: was exit 0, ok, u shrunk 0.136 -> 0.088″ (x->z); now exit 2, not ok (no t "
    "column) but not refused: an untimed copy is refused only from 32 revolutions (a steady "
    "table's counts repeat count for count over ~30 revolutions by chance, docs/formats.md), "
    "this one has 30; with --steady-table it would be ok at the shrunk u (lead, stop 29)"))
def test_counter_log_without_times_written_twice_is_refused(tmp_path):
    truth = ui.make_truth(5)
    rows = ui.gonio_rows(truth, 5, revolutions=30)
    text = "".join(f"{c},{k},{r}\n" for c, k, r, _ in rows)
    (tmp_path / "twice.csv").write_text("count,counter,ref\n" + text + text)
    rc, _, err = cli("gonio", tmp_path / "twice.csv", "--faces", "ref,y,x,z", "-q")
    assert refusal_problems(rc, err, "twice.csv") == []


@pytest.mark.slow
def test_pose_files_as_users_save_them(tmp_path):
    """The tumble saved six ways calibrates to the same numbers; written twice into itself
    (with / without a second header) it is refused in one line."""
    truth = ui.make_truth(6)
    ui.write_tumble(tmp_path / "tb.csv", truth, 6, samples=10)
    base = (tmp_path / "tb.csv").read_text()
    lines = base.splitlines()
    body = "\n".join(lines[1:]) + "\n"
    variants = {
        "trailing_empty_line.csv": (base + "\n").encode(),
        "crlf.csv": base.replace("\n", "\r\n").encode(),
        "semicolon_bom_crlf.csv": b"\xef\xbb\xbf" + base.replace(",", ";").replace(
            "\n", "\r\n").encode(),
        "units.csv": ("# 24-bit ADC\npose,ux [counts],uy [counts],uz [counts]\n"
                      + body).encode(),
        "excel.csv": ('"pose","ux","uy","uz"\n' + "".join(
            ",".join(f'"{c}"' for c in ln.split(",")) + "\n" for ln in lines[1:])).encode(),
    }
    rc, _, err = cli("calibrate", tmp_path / "tb.csv", "--units", "counts", "--json",
                     tmp_path / "tb.json", "-q")
    assert rc == 0, err
    ref = json.loads((tmp_path / "tb.json").read_text())
    keys = ("scale_factors_counts_per_g", "beta_rad", "bias_g", "beta_u_rad")
    for name, data in variants.items():
        (tmp_path / name).write_bytes(data)
        rc, _, err = cli("calibrate", tmp_path / name, "--units", "counts", "--json",
                         tmp_path / f"{name}.json", "-q")
        assert rc == 0, (name, err)
        d = json.loads((tmp_path / f"{name}.json").read_text())
        assert all(d[k] == ref[k] for k in keys), name
    bad = []
    for name, text in {"twice_hdr.csv": base + base, "twice.csv": base + body}.items():
        (tmp_path / name).write_text(text)
        rc, _, err = cli("calibrate", tmp_path / name, "--units", "counts", "-q")
        bad += refusal_problems(rc, err, name)
    assert bad == []


# ---------------------------------------------------------------- (1b) with camera images

BOARD = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / (
    "opencv-chessboard")


def _board() -> Path:
    if not BOARD.is_dir():
        pytest.skip(f"real data folder {BOARD} is absent (it lives in ../shared/data/real)")
    return BOARD


def _camera_model(tmp_path: Path) -> tuple[dict, Path]:
    """My own lens (cv2.calibrateCamera) and the tool's model from the same photographs."""
    board = _board()
    lens = ui.calibrate_lens(board)
    model = tmp_path / "camera.json"
    rc, _, err = cli("camera", *sorted(board.glob("left*.jpg")), "--pattern", "9x6",
                     "--json", model, "-q")
    assert rc == 0, err
    return lens, model


def _mark_truth_deg(truth: ui.Truth, housing: str, view: str) -> float:
    """The mark's direction atan2(s.up, s.right) as a line, wrapped to (-90, 90] [deg]."""
    _, right, up = ui.VIEWS[view]
    s = truth.axes()["xyz".index(housing)]
    a = np.degrees(np.arctan2(s @ ui._AXIS[up], s @ ui._AXIS[right]))
    return float((a + 90) % 180 - 90)


@pytest.mark.slow
def test_own_session_with_my_camera_images(tmp_path):
    """Two seeds, eight mark images each (my groove through my lens, marks near the
    principal point), the camera model made with `align camera` from the real chessboard
    photographs: ok, every mark angle and every E within 4 u of my truth."""
    lens, model = _camera_model(tmp_path)
    for seed in (3, 4):
        truth = ui.make_truth(seed)
        folder = ui.write_session(tmp_path / f"cam{seed}", truth, seed)
        toml = ui.write_images(folder, truth, seed, lens, model, centre_px=(340.0, 236.0))
        with open(folder / "session.toml", "a") as fh:
            fh.write("\n" + toml)
        rc, d, err = run_session(folder)
        assert rc == 0 and d["ok"], (seed, err)
        assert "camera" in d["sources"], d["sources"]
        for m in d["stages"]["marks"]:
            want = _mark_truth_deg(truth, m["housing"], m["view"])
            got = (m["angle_deg"] - want + 90) % 180 - 90
            assert abs(got * 3600) < 4 * m["angle_u_arcsec"], (seed, m["image"], got * 3600,
                                                               m["angle_u_arcsec"])
        z = normalised_errors(d, truth)
        assert max(abs(v) for v in z.values()) < 4.0, (seed, z)


@pytest.mark.slow
def test_lens_limited_with_a_model_says_what_to_do(tmp_path):
    """With a camera model given, a lens-limited mark is refused (right) but its advice must
    not be to give the camera model the user gave: it should say the model's own u is the
    limit (more or better chessboard views, or a mark nearer the centre)."""
    import cv2

    lens, model = _camera_model(tmp_path)
    img = ui.render_mark(lens, np.array([1.0, 100 * ui.ARCSEC]), (430.0, 300.0), 1)
    cv2.imwrite(str(tmp_path / "off.png"), img)
    rc, _, err = cli("marks", tmp_path / "off.png", "--camera", model, "--json",
                     tmp_path / "off.json")
    assert rc == 2 and "lens-limited" in err, err
    assert "give it with --camera" not in err, err
