"""user6, an independent user: does axis-align give a confident wrong answer?

Every input is made by ``tests/align/user6_inputs.py`` (my own physics: a ring-laser counter
log, a groove integrated over each pixel through an OpenCV lens, a triad tumbled with
effects, session folders) and run through the CLI as a user runs it (``python3 -m align``).
A confident wrong answer is exit 0 / ``ok: true`` / no warning with a number more than 3 of
its stated u from my truth. Right behaviour passes; a defect is ``xfail(strict=True)`` with
the figures seen in its reason.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.align import user6_inputs as U
from tests.cli import run_cli

ROOT = Path(__file__).resolve().parents[2]
CHESS = ROOT.parent / "shared" / "data" / "real" / "opencv-chessboard"
FACES = ("--faces", "ref,y,x,z", "--latitude", "50.45")
# My generator's autocollimator has no latency (its pulse is the face's angle, with jitter):
# declared as its specification would say, on my table whose speed follows its angle.
NO_LATENCY = ("--latency-max-us", "0")
NO_LENS = ("--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")


def align(*args):
    """``align ARGS`` from the project's root, in this process (``tests.cli.run_cli``: the
    same exit status and streams as ``python3 -m align`` without ~1.3 s of imports a call)."""
    return tuple(run_cli(*args, cwd=ROOT))


def json_of(*args):
    rc, out, err = align(*args, "--json", "-", "-q")
    js = json.loads(out) if out.strip().startswith("{") else None
    return rc, js, err


def assert_one_line_refusal(rc, out, err, *needles):
    assert rc == 2, (rc, out, err)
    assert "Traceback" not in err + out, err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], (n, lines[0])


def gonio_z(js, g: U.Gonio) -> np.ndarray:
    err = (np.asarray(js["angles_deg"]) - g.truth_deg()) * 3600.0
    return err / np.asarray(js["angles_u_arcsec"])


def dropout_named(js) -> list:
    return [v["lines"] for k, v in js["exclusions"].items() if "drop-out" in k]


def need_chessboards():
    if not sorted(CHESS.glob("left*.jpg")):
        pytest.skip(f"real data folder {CHESS} is absent (it lives in ../shared/data/real)")


# ------------------------------------------------------------------------- goniometer

def test_my_gonio_log_clean_is_within_u():
    """My generator against the tool on a clean log: the basis of the drop-out checks. My
    table's speed follows its angle and I log one direction: without the autocollimator's
    latency bound declared the result is not ok and says what to give. Declared, the
    counters' part is what the ripple modelled over my unequal faces leaves (my counters are
    sound): u 0.773″ when it was the harmonic projection (1.3″ of my 1 % ripple over faces up
    to 356″ off 90°), ≤ 0.2″ now."""
    g = U.Gonio(seed=3)
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = U.write_gonio(Path(d) / "g.csv", g.rows())
        rc0, js0, err0 = json_of("gonio", p, *FACES)
        rc, js, err = json_of("gonio", p, *FACES, *NO_LATENCY)
    assert rc0 == 2 and not js0["ok"], err0
    assert "--latency-max-us" in err0 and "--reverse-log" in err0, err0
    assert rc == 0 and js["ok"], err
    assert np.all(np.abs(gonio_z(js, g)) < 3.5), gonio_z(js, g)
    assert max(js["angles_u_arcsec"]) < 0.2, js["angles_u_arcsec"]


@pytest.mark.parametrize("with_t", [True, False])
def test_dropout_across_the_reference_face_is_named_and_angles_within_u(tmp_path, with_t):
    """12 rows lost from 2 rows before a reference pulse: excluded and named (with times:
    by the row's duration; without: by the faces' sequence, 12 is not a multiple of 4 ...
    unless the phase is kept, which 12 rows keep: then the stitch is exact)."""
    g = U.Gonio(seed=4)
    rows = list(g.rows())
    refs = [i for i, r in enumerate(rows) if r[2] == 1]
    at = refs[40] - 2
    rows = rows[:at] + rows[at + 13:]   # 13 rows: the phase jumps by one face
    p = U.write_gonio(tmp_path / "g.csv", rows, with_t)
    rc, js, err = json_of("gonio", p, *FACES, *NO_LATENCY)
    assert rc == 0, err
    assert dropout_named(js) == [[at + 2]], js["exclusions"]   # line of the row after the gap
    assert np.all(np.abs(gonio_z(js, g)) < 3.5), gonio_z(js, g)


def _dropout_logs(tmp_path, with_t):
    """12 logs, one drop-out of 3-20 rows at a random place (head, across a reference face,
    tail), 0.5-2 rev/s: yields (seed, row of the gap, truth, result, clean rows)."""
    for seed in range(12):
        rng = np.random.default_rng(1000 + seed)
        g = U.Gonio(seed=seed, rev_per_s=float(rng.uniform(0.5, 2.0)))
        rows = list(g.rows())
        n = int(rng.integers(3, 21))
        at = int(rng.integers(0, len(rows) - n))
        p = U.write_gonio(tmp_path / f"g{seed}.csv", rows[:at] + rows[at + n:], with_t)
        rc, js, err = json_of("gonio", p, *FACES)
        assert rc in (0, 2) and js is not None, err
        yield seed, at, g, js, rows


@pytest.mark.slow
def test_dropouts_of_3_to_20_rows_with_times_named_and_within_u(tmp_path):
    """With times: each drop-out named at the line after the gap; normalised errors' RMS
    near 1, none beyond 4."""
    zs = []
    for seed, at, g, js, _ in _dropout_logs(tmp_path, True):
        zs.append(gonio_z(js, g))
        if at > 0:
            assert [at + 2] in dropout_named(js), (seed, at, js["exclusions"])
    zs = np.concatenate(zs)
    assert np.sqrt(np.mean(zs ** 2)) < 1.4 and np.abs(zs).max() < 4.0, np.round(zs, 2)


@pytest.mark.slow
def test_dropouts_without_times_move_angles_less_than_the_documented_bound(tmp_path):
    """Without times the Earth rate is neither removed nor bounded on my unsteady table, so
    compare with the drop-out-free twin (as the docs do): within 1 u (docs: < 0.3 u)."""
    moved = []
    for seed, _, g, js, rows in _dropout_logs(tmp_path, False):
        q = U.write_gonio(tmp_path / f"twin{seed}.csv", rows, False)
        _, twin, err = json_of("gonio", q, *FACES)
        moved.append(gonio_z(js, g) - gonio_z(twin, g))
    moved = np.concatenate(moved)
    assert np.abs(moved).max() < 1.0, np.round(moved, 2)


def test_duplicated_row_with_times_is_refused_in_one_line_naming_it(tmp_path):
    g = U.Gonio(seed=5)
    rows = list(g.rows())
    rows = rows[:201] + [rows[200]] + rows[201:]
    p = U.write_gonio(tmp_path / "g.csv", rows)
    rc, out, err = align("gonio", p, *FACES, "-q")
    assert_one_line_refusal(rc, out, err, "g.csv:203", "t")


def test_duplicated_row_without_times_is_excluded_not_stitched(tmp_path):
    """A row written twice adds one face interval's counts: the walk must not keep it."""
    g = U.Gonio(seed=5)
    rows = list(g.rows())
    rows = rows[:201] + [rows[200]] + rows[201:]
    p = U.write_gonio(tmp_path / "g.csv", rows, with_t=False)
    rc, js, err = json_of("gonio", p, *FACES)
    assert js is not None and "Traceback" not in err, err
    assert js["exclusions"], "the duplicated row left no trace"
    assert np.all(np.abs(gonio_z(js, g)) < 3.5), gonio_z(js, g)


@pytest.mark.parametrize("jump_s", [0.5, 3600.0])
def test_clock_jump_forward_is_named_and_angles_within_u(tmp_path, jump_s):
    """The logger's clock jumps forward (NTP step) with no row lost: the revolution it
    falls in is excluded as a drop-out (its duration is not its counts'), and nothing
    carries the jump into the Earth-rate correction."""
    g = U.Gonio(seed=6)
    rows = [list(r) for r in g.rows()]
    for r in rows[150:]:
        r[3] += jump_s
    p = U.write_gonio(tmp_path / "g.csv", rows)
    rc, js, err = json_of("gonio", p, *FACES, *NO_LATENCY)
    assert rc == 0, err
    assert dropout_named(js) == [[152]], js["exclusions"]
    assert np.all(np.abs(gonio_z(js, g)) < 3.5), gonio_z(js, g)


def test_clock_jump_backward_is_refused_in_one_line(tmp_path):
    g = U.Gonio(seed=6)
    rows = [list(r) for r in g.rows()]
    for r in rows[150:]:
        r[3] -= 2.0
    p = U.write_gonio(tmp_path / "g.csv", rows)
    rc, out, err = align("gonio", p, *FACES, "-q")
    assert_one_line_refusal(rc, out, err, "g.csv:152", "t")


# ------------------------------------------------------------------------- camera stage

def test_my_lens_map_is_exact_to_a_thousandth_of_a_pixel():
    """My renderer's interpolated inverse of the real chessboard lens, pushed back through
    cv2.projectPoints, lands within 1e-3 px of where it started, all over the frame."""
    need_chessboards()
    lens = U.chessboard_lens()
    f = U.ideal_map(lens, 640, 480)
    rng = np.random.default_rng(0)
    px = rng.uniform([0, 0], [639, 479], size=(20000, 2))
    back = lens.distort(f(px))
    assert np.abs(back - px).max() < 1e-3


@pytest.mark.slow
def test_camera_u_matches_the_jackknife_over_real_views():
    """The stated u of each intrinsic against the delete-one jackknife over the 7 views
    (6 dof: a ratio beyond 2.2 has p < 1e-3 for an honest u). Was: stated u(cx) 0.72 px
    against a jackknife 2.37 px (3.3x); holds on main since the camera model's jackknife u."""
    need_chessboards()
    files = sorted(map(str, CHESS.glob("left*.jpg")))

    def cal(fs):
        rc, js, err = json_of("camera", *fs)
        assert rc == 0, err
        K, D = js["camera_matrix"], js["dist_coeffs"]
        return np.array([K[0][0], K[1][1], K[0][2], K[1][2], *D[:4]]), js["u"]

    _, u = cal(files)
    subs = np.array([cal(files[:i] + files[i + 1:])[0] for i in range(len(files))])
    n = len(files)
    jk = np.sqrt((n - 1) / n * ((subs - subs.mean(0)) ** 2).sum(0))
    names = ["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]
    ratio = {k: jk[i] / u[k] for i, k in enumerate(names)}
    assert max(ratio.values()) < 2.2, ratio


@pytest.mark.slow
def test_marks_through_the_real_lens_with_its_model_within_u(tmp_path):
    """(Was: -239, -216, -280 arcsec at u 56, 32, 63, exit 0;
    holds on main.) Both calibrations estimate one real lens; allowing my own as much error as the
    tool's (a factor sqrt 2), an ok angle stays within 3 sqrt(2) u of my truth."""
    need_chessboards()
    cam = tmp_path / "cam.json"
    rc, _, err = align("camera", *sorted(CHESS.glob("left*.jpg")), "--json", cam, "-q")
    assert rc == 0, err
    lens = U.chessboard_lens()
    bad = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        x, y, a = 320 + rng.uniform(-40, 40), rng.uniform(60, 110), rng.uniform(-0.3, 0.3)
        sc = U.Scene(width=640, height=480, lens=lens, marks=(U.Mark(x, y, a, 300),),
                     seed=seed, bits=12)
        p = U.write_image(tmp_path / f"m{seed}.png", U.render(sc))
        rc, js, err = json_of("marks", p, "--camera", cam)
        (m,) = js["marks"]
        z = U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"]
        if js["ok"] and abs(z) > 3 * np.sqrt(2):
            bad.append((seed, round(z, 2), rc))
    assert not bad, bad


@pytest.mark.slow
def test_real_lens_without_a_model_is_lens_limited_not_wrong(tmp_path):
    """No model, default lens ranges: an off-centre mark is either within 3 u or NOT OK."""
    need_chessboards()
    lens = U.chessboard_lens()
    for seed in range(3):
        rng = np.random.default_rng(seed)
        x, y, a = 320 + rng.uniform(-40, 40), rng.uniform(60, 110), rng.uniform(-0.3, 0.3)
        sc = U.Scene(width=640, height=480, lens=lens, marks=(U.Mark(x, y, a, 300),),
                     seed=seed, bits=12)
        p = U.write_image(tmp_path / f"m{seed}.png", U.render(sc))
        rc, js, err = json_of("marks", p)
        (m,) = js["marks"]
        z = U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"]
        assert abs(z) < 3 or (rc == 2 and not js["ok"] and "NOT OK" in err), (seed, z, rc)


# ------------------------------------------------------------------------- calibration

def cal_json(path, *flags):
    return json_of("calibrate", path, *flags)


def k_z(js, k_true) -> np.ndarray:
    k = np.asarray(js["scale_factors_v_per_g"])
    return (k - k_true) / np.asarray(js["scale_factors_u_v_per_g"])


def triad(seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    return U.Triad(U.s_from_E(U.E_arcsec(*rng.uniform(-300, 300, 6)))), rng


def test_my_clean_tumble_gives_k_within_u(tmp_path):
    tri, rng = triad(1)
    p = U.write_tumble(tmp_path / "t.csv", U.tumble_rows(tri, U.cube14(), rng))
    rc, js, err = cal_json(p)
    assert rc == 0 and js["ok"], err
    assert np.all(np.abs(k_z(js, tri.k)) < 3), k_z(js, tri.k)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 2])
def test_scale_warmup_without_temperature_column_k_at_the_mean_time_within_u(tmp_path, seed):
    """The scale factor warms up by 450 ppm (tau 60 s) over a 14-pose tumble, no temperature
    column: k is reported at the mean pose time; it must be within 3 u of my k there."""
    tri, rng = triad(seed)

    def sf(t):
        return 1 + 450e-6 * (1 - np.exp(-t / 60.0))

    rows = U.tumble_rows(tri, U.cube14(), rng, scale_of_t=sf)
    t_ref = np.mean([r[1] for r in rows])
    p = U.write_tumble(tmp_path / "t.csv", rows)
    rc, js, err = cal_json(p)
    assert js is not None, err
    z = k_z(js, tri.k * sf(np.array([t_ref]))[0])
    assert np.all(np.abs(z) < 3) or not js["ok"], z


@pytest.mark.slow
def test_scale_cycling_with_temperature_without_a_temp_column_is_covered_or_not_ok(tmp_path):
    bad = []
    for seed in range(3):
        tri, rng = triad(seed)
        ph = rng.uniform(0, 2 * np.pi)

        def sf(t, ph=ph):
            return 1 + 100e-6 * np.sin(2 * np.pi * t / 900.0 + ph)

        rows = U.tumble_rows(tri, U.cube14(), rng, n=1200, scale_of_t=sf, t_gap=30.0)
        ts = np.array([r[1] for r in rows])
        p = U.write_tumble(tmp_path / f"t{seed}.csv", rows)
        rc, js, err = cal_json(p)
        assert js is not None, err
        z_ref = k_z(js, tri.k * sf(np.array([ts.mean()]))[0])
        z_avg = k_z(js, tri.k * sf(ts).mean())
        covered = np.all(np.minimum(np.abs(z_ref), np.abs(z_avg)) < 3)
        if not covered and js["ok"]:
            bad.append((seed, np.round(z_ref, 1), np.round(z_avg, 1), rc))
    assert not bad, bad


def test_one_clipped_pose_in_per_pose_means_is_covered_or_flagged(tmp_path):
    """Per-pose means, the +z pose clipped by 1 mg on uz (was k_z 4.4 u off, silent; since
    main 592bdc3: structure named, u widened x1.9, 2.3 u)."""
    tri, rng = triad(0)
    rows = U.tumble_rows(tri, U.cube14(), rng, clip=(2, tri.k[2] * 0.999 + tri.b[2]))
    p = tmp_path / "means.csv"
    p.write_text("pose,ux,uy,uz\n" + "".join(
        f"{r[0]},{r[1]:.9e},{r[2]:.9e},{r[3]:.9e}\n" for r in U.pose_means(rows)))
    rc, js, err = cal_json(p)
    assert js is not None, err
    z = k_z(js, tri.k)
    assert np.all(np.abs(z) < 3) or not js["ok"] or any("clip" in w for w in js["warnings"]), z


def test_analogue_saturation_with_adc_noise_after_it_is_covered(tmp_path):
    """The amplifier saturates 1 mg below the +z face's reading; the ADC adds its noise
    after it, so no value piles up at a rail: the samples' residual shows it, and u covers
    it (or the result is not ok)."""
    tri, rng = triad(0)
    rows = U.tumble_rows(tri, U.cube14(), rng, clip=(2, tri.k[2] * 0.999 + tri.b[2]))
    p = U.write_tumble(tmp_path / "t.csv", rows)
    rc, js, err = cal_json(p)
    assert js is not None, err
    z = k_z(js, tri.k)
    assert np.all(np.abs(z) < 3) or not js["ok"], z
    assert js["unexplained_structure"] or not js["ok"]


def test_a_pose_with_a_vibration_is_refused_naming_the_pose_and_its_lines(tmp_path):
    tri, rng = triad(0)
    rows = U.tumble_rows(tri, U.cube14(), rng, vib=(5, 0.05, 7.3))
    p = U.write_tumble(tmp_path / "t.csv", rows)
    rc, out, err = align("calibrate", p, "-q")
    assert_one_line_refusal(rc, out, err, "t.csv", "pose 5", "lines 1002-1201")


def test_pose_blocks_written_out_of_time_order_are_refused_naming_the_line(tmp_path):
    tri, rng = triad(0)
    rows = U.tumble_rows(tri, U.cube14(), rng)
    blocks = [rows[i * 200:(i + 1) * 200] for i in range(14)]
    blocks[3], blocks[7] = blocks[7], blocks[3]
    p = U.write_tumble(tmp_path / "t.csv", sum(blocks, []))
    rc, out, err = align("calibrate", p, "-q")
    assert_one_line_refusal(rc, out, err, "t.csv:802", "t:")


def test_labels_of_two_faces_swapped_are_refused(tmp_path):
    """+x and +y labels exchanged: the labels do not name the triad's axes."""
    tri, rng = triad(0)
    labels = ["+y", "-x", "+x", "-y", "+z", "-z"] + [f"c{i}" for i in range(8)]
    p = U.write_tumble(tmp_path / "t.csv", U.tumble_rows(tri, U.cube14(), rng, labels=labels))
    rc, out, err = align("calibrate", p, "-q")
    assert_one_line_refusal(rc, out, err, "labelled faces", "--scale-sign")


@pytest.mark.slow
@pytest.mark.parametrize("with_t", [True, False])
def test_continuous_recording_with_turns_and_shake_k_within_u(tmp_path, with_t):
    """A hand tumble recorded at 50 Hz (8 s poses, 3 s turns with 0.02 g of shake), with
    and without a time column (--rate 50): 14 poses found, k within 3 u over 3 seeds."""
    zs = []
    for seed in range(3):
        tri, rng = triad(seed)
        rec = U.recording(tri, U.cube14(), rng)
        p = U.write_recording(tmp_path / f"r{seed}.csv", rec, with_t)
        rc, js, err = cal_json(p, *(() if with_t else ("--rate", "50")))
        assert rc == 0 and js["ok"], err
        assert len(js["poses"]) == 14
        zs.append(k_z(js, tri.k))
    assert np.all(np.abs(zs) < 3), np.round(zs, 2)


# ------------------------------------------------------------------------- scenes

def marks_of(js) -> list:
    return [m for m in js["marks"] if m.get("found", True)]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_stage_micrometer_with_numerals_and_dust_family_within_u(tmp_path, seed):
    """11 graduations at a 40 px pitch, every 5th long and numbered, 25 specks of dust:
    every graduation found, each and the family's mean within 3 u, pitch within 0.05 px."""
    a = 90 + np.random.default_rng(seed).uniform(-0.4, 0.4)
    sc = U.micrometer(a, seed=seed)
    p = U.write_image(tmp_path / "scale.png", U.render(sc))
    rc, js, err = json_of("marks", p, *NO_LENS)
    ms = marks_of(js)
    assert len(ms) == 11, err
    z = [U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"] for m in ms]
    assert np.all(np.abs(z) < 3.5), z
    fam = ms[0]["family"]
    assert fam["lines"] == 11
    assert abs(U.wrap_deg(fam["angle_deg"] - a) * 3600) < 3 * fam["angle_u_arcsec"]
    assert abs(fam["pitch_px"] - 40.0) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 4])
def test_dial_of_12_graduations_each_within_u(tmp_path, seed):
    sc, truth = U.dial(seed=seed, turn_deg=np.random.default_rng(seed).uniform(0, 30))
    p = U.write_image(tmp_path / "dial.png", U.render(sc))
    rc, js, err = json_of("marks", p, *NO_LENS)
    ms = marks_of(js)
    assert len(ms) == 12, err
    z = []
    for m in ms:
        t = min(truth, key=lambda t, m=m: abs(U.wrap_deg(m["angle_deg"] - t)))
        z.append(U.wrap_deg(m["angle_deg"] - t) * 3600 / m["angle_u_arcsec"])
    assert np.all(np.abs(z) < 3.5) and np.sqrt(np.mean(np.square(z))) < 1.6, np.round(z, 2)


@pytest.mark.slow
def test_clean_vertical_mark_raises_no_stripe_warning(tmp_path):
    """A clean vertical 250 px mark, no stripes rendered: no stripe warning. Was: 'column
    stripes ... removed' in 6 of 6 seeds (p 2e-7..6e-4); holds on main since."""
    found = []
    for seed in range(2):
        rng = np.random.default_rng(seed)
        a = 90 + rng.uniform(-0.3, 0.3)
        sc = U.Scene(480, 360, (U.Mark(239.5 + rng.uniform(-6, 6), 179.5, a, 250.0, 4.5),),
                     seed=seed, bits=12)
        p = U.write_image(tmp_path / f"v{seed}.png", U.render(sc))
        rc, js, err = json_of("marks", p, *NO_LENS)
        # A removed stripe pattern is a note, not a warning: both count as a false finding.
        notes = [n for m in js["marks"] for n in m.get("notes", [])]
        found += [w for w in js["warnings"] + notes if "stripes" in w]
    assert not found, found


def test_vertical_mark_angle_within_u_in_a_12_bit_tiff(tmp_path):
    """12-bit data in a 16-bit TIFF, vignetting 25 %: the angle within 3 u."""
    a = 89.83
    sc = U.Scene(480, 360, (U.Mark(241.0, 180.2, a, 250.0, 4.5),), seed=7, bits=12)
    p = U.write_image(tmp_path / "v.tif", U.render(sc))
    rc, js, err = json_of("marks", p, *NO_LENS)
    assert rc == 0, err
    (m,) = marks_of(js)
    assert abs(U.wrap_deg(m["angle_deg"] - a) * 3600) < 3 * m["angle_u_arcsec"]


@pytest.mark.slow
def test_tangential_lens_beyond_the_default_range_is_lens_limited_not_wrong(tmp_path):
    """|p| x R/f = 0.003 (three times the default range), mark in the top quarter, no model:
    within 3 u or NOT OK (exit 2)."""
    for seed in range(2):
        rng = np.random.default_rng(seed)
        lens = U.Lens(530, 530, 319.5 + rng.uniform(-8, 8), 239.5 + rng.uniform(-8, 8),
                      (-0.12, 0.02, 0.004, -0.003, 0.0))
        a = rng.uniform(-0.3, 0.3)
        sc = U.Scene(640, 480, (U.Mark(320 + rng.uniform(-30, 30), rng.uniform(70, 110), a,
                                       320),), lens=lens, seed=seed, bits=12)
        p = U.write_image(tmp_path / f"t{seed}.png", U.render(sc))
        rc, js, err = json_of("marks", p)
        (m,) = marks_of(js)
        z = U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"]
        assert abs(z) < 3 or (rc == 2 and not js["ok"]), (seed, z, rc)


# ------------------------------------------------------------------------- sessions

CHESS_LIKE = U.Lens(420, 420, 244.5, 175.5, (-0.25, 0.05, 0.0, 0.0, 0.0))
SESSIONS = {
    "clean": U.SessionSpec(seed=0),
    "level": U.SessionSpec(seed=0, level_arcsec=(24.0, -18.0)),      # 30" out of level
    "creep": U.SessionSpec(seed=0, creep_y_arcsec=30.0),
    "lens_zero": U.SessionSpec(seed=0, lens_A=CHESS_LIKE, off_centre_A=110.0),
    "lens_none": U.SessionSpec(seed=0, lens_A=CHESS_LIKE, off_centre_A=110.0,
                               lens_A_keys="none"),
    "level_plain": U.SessionSpec(seed=0, level_arcsec=(24.0, -18.0), images=False),
    "chess_model": U.SessionSpec(seed=0, off_centre_A=110.0, model_A="camA.json"),
}
_RUNS: dict = {}


@pytest.fixture(scope="module")
def session_run(tmp_path_factory):
    """Write and run one of SESSIONS once per module: (rc, result JSON, stderr, truth)."""
    def run(name):
        if name not in _RUNS:
            folder = tmp_path_factory.mktemp("u6sess") / name
            spec = SESSIONS[name]
            if spec.model_A:   # the tool's model of the real lens; images through mine
                need_chessboards()
                folder.mkdir(parents=True)
                rc, _, err = align("camera", *sorted(CHESS.glob("left*.jpg")), "--json",
                                   folder / spec.model_A, "-q")
                assert rc == 0, err
                spec = U.SessionSpec(**{**spec.__dict__, "lens_A": U.chessboard_lens()})
            truth = U.write_session(folder, spec)
            rc, js, err = json_of("run", folder)
            assert js is not None, err
            _RUNS[name] = (rc, js, err, truth)
        return _RUNS[name]
    return run


def e_z(js, E_true) -> np.ndarray:
    E, uE = np.asarray(js["misalignment_rad"]), np.asarray(js["misalignment_u_rad"])
    off = ~np.eye(3, dtype=bool)
    return (E - E_true)[off] / uE[off]


@pytest.mark.slow
def test_session_clean_E_within_u(session_run):
    rc, js, err, truth = session_run("clean")
    assert rc == 0 and js["ok"], err
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])


@pytest.mark.slow
def test_session_platform_30_arcsec_out_of_level_is_found_and_E_within_u(session_run):
    rc, js, err, truth = session_run("level")
    names = [e["name"] for e in js["effects"]]
    sd = js["source_disagreement"] or {}
    assert "platform_level" in names or sd.get("source") == "platform static", (names, sd)
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])


@pytest.mark.slow
def test_session_creep_names_the_sources_and_u_covers_the_images_truth(session_run):
    """The triad turned 30" about Y after the images: the static poses and the camera
    images are named in E_xZ, E_zX, and u covers E as the images saw it."""
    rc, js, err, truth = session_run("creep")
    sd = js["source_disagreement"]
    assert sd is not None, js["warnings"]
    named = {sd["source"], *(sd.get("also") or []), *sd["others"]}
    assert "platform static" in named and any("camera" in n for n in named), sd
    assert set(sd["angles"]) >= {"E_xZ", "E_zX"}, sd
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])


@pytest.mark.slow
def test_session_creep_exit_status_says_the_instruments_disagree(session_run):
    """A 30 arcsec creep (was: chi2 141/21, exit 0, ok true; main d6da705: exit 2)."""
    rc, js, err, truth = session_run("creep")
    assert rc == 2 and not js["ok"], (rc, js["ok"])


@pytest.mark.slow
def test_session_lens_declared_absent_but_present_names_camera_A_and_E_within_u(session_run):
    """Camera A has a k1 = -0.25 lens, session.toml declares lens_* = 0 and its marks sit
    110 px off-centre: the bows are named on camera A's images and E stays within u."""
    rc, js, err, truth = session_run("lens_zero")
    assert any("x_A.png" in w and "bent" in w for w in js["warnings"]), js["warnings"]
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])


@pytest.mark.slow
def test_session_with_lens_limited_marks_is_not_ok(session_run):
    """Four lens-limited marks (was: exit 0, ok true; main d6da705: exit 2)."""
    rc, js, err, truth = session_run("lens_none")
    assert any("lens-limited" in w for w in js["warnings"]), js["warnings"]
    assert rc == 2 and not js["ok"], (rc, js["ok"])


# ------------------------------------------------------------------------- bad input

def _gonio_file(tmp_path, edit):
    rows = [list(r) for r in U.Gonio(seed=1, revolutions=12).rows()]
    p = U.write_gonio(tmp_path / "g.csv", rows)
    lines = p.read_text().splitlines()
    edit(lines)
    p.write_text("\n".join(lines) + "\n")
    return p


def _tumble_file(tmp_path, edit):
    tri, rng = triad(1)
    p = U.write_tumble(tmp_path / "t.csv", U.tumble_rows(tri, U.cube14(), rng, n=20))
    lines = p.read_text().splitlines()
    edit(lines)
    p.write_text("\n".join(lines) + "\n")
    return p


def _set(i, col, value):
    def edit(lines):
        cells = lines[i - 1].split(",")
        cells[col] = value
        lines[i - 1] = ",".join(cells)
    return edit


BAD_TABLES = [
    ("gonio", _set(20, 0, "191127.5"), ("g.csv:20", "count")),
    ("gonio", _set(30, 1, "3"), ("g.csv:30", "counter")),
    ("calibrate", _set(150, 4, "nan"), ("t.csv:150", "uz")),
    ("calibrate", _set(77, 1, ""), ("t.csv:77", "t")),
]


@pytest.mark.parametrize("cmd, edit, needles", BAD_TABLES)
def test_bad_cell_is_one_line_naming_file_line_and_column(tmp_path, cmd, edit, needles):
    if cmd == "gonio":
        rc, out, err = align("gonio", _gonio_file(tmp_path, edit), *FACES, "-q")
    else:
        rc, out, err = align("calibrate", _tumble_file(tmp_path, edit), "-q")
    assert_one_line_refusal(rc, out, err, *needles)


@pytest.mark.parametrize("flags, needle", [
    (("--faces", "ref,y,x"), "--faces"),
    (("--faces", "ref,y,x,z", "--nominal", "90,90,90,80"), "--nominal"),
])
def test_gonio_flag_contradicting_the_log_is_one_line_naming_the_flag(tmp_path, flags, needle):
    p = U.write_gonio(tmp_path / "g.csv", U.Gonio(seed=1, revolutions=12).rows())
    rc, out, err = align("gonio", p, *flags, "-q")
    assert_one_line_refusal(rc, out, err, needle)


@pytest.mark.parametrize("flags, needle", [
    (("--roi", "10,10,-5,100"), "--roi"),
    (("--lens", "k1=abc"), "--lens"),
    (("--lens", "k9=0.1"), "--lens"),
])
def test_marks_bad_flag_is_one_line_naming_it(tmp_path, flags, needle):
    p = U.write_image(tmp_path / "m.png", np.full((120, 160), 2000, np.uint16))
    rc, out, err = align("marks", p, *flags, "-q")
    assert_one_line_refusal(rc, out, err, needle)


def test_roi_outside_the_image_names_the_image_and_the_region(tmp_path):
    sc = U.Scene(480, 360, (U.Mark(240, 180, 0.1, 200),), ss=2)
    p = U.write_image(tmp_path / "m.png", U.render(sc))
    rc, out, err = align("marks", p, "--roi", "400,0,200,100", "-q")
    assert_one_line_refusal(rc, out, err, "m.png", "400,0,200,100", "480x360")


def test_truncated_image_is_one_line_naming_it(tmp_path):
    sc = U.Scene(160, 120, (U.Mark(80, 60, 0.1, 100),), ss=2)
    p = U.write_image(tmp_path / "m.png", U.render(sc))
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    rc, out, err = align("marks", p, "-q")
    assert_one_line_refusal(rc, out, err, "m.png", "truncated")


@pytest.mark.slow
def test_clean_near_horizontal_marks_u_is_honest_over_30_seeds(tmp_path):
    """My groove is a ground scribe's rounded V (not the tool's flat-bottomed model): its
    centres are unbiased by symmetry, so an honest u gives RMS z near 1 (30 z: above 1.41
    has p < 1e-3) and no |z| beyond 3.7 (p ~ 0.006 for the largest of 30)."""
    zs = []
    for seed in range(100, 130):
        rng = np.random.default_rng(seed)
        a = rng.uniform(-0.3, 0.3)
        sc = U.Scene(640, 480, (U.Mark(320 + rng.uniform(-20, 20), 240 + rng.uniform(-20, 20),
                                       a, 300),), seed=seed, bits=16, vignetting=0.0, ss=8)
        p = U.write_image(tmp_path / f"c{seed}.png", U.render(sc))
        rc, js, err = json_of("marks", p, *NO_LENS)
        (m,) = marks_of(js)
        zs.append(U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"])
    zs = np.asarray(zs)
    assert np.sqrt(np.mean(zs ** 2)) < 1.41 and np.abs(zs).max() < 3.7, np.round(zs, 2)


# ------------------------------------------------------------------------- exposure, edges

def _edge_mark(seed: int) -> tuple[U.Scene, float]:
    """The frame-edge scene of ``seed``: a horizontal 300 px mark 6 px from the bottom edge
    (row 473 of 480), within 0.3 deg of the pixel rows, vignetting 35 %, 12-bit."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.3, 0.3)
    return U.Scene(640, 480, (U.Mark(320 + rng.uniform(-20, 20), 473, a, 300),), seed=seed,
                   bits=12, vignetting=0.35), a


def _edge_z(tmp_path, seeds, render, silent_only: bool, noise_free: bool = False,
            flags: tuple = ()) -> np.ndarray:
    zs = []
    for seed in seeds:
        sc, a = _edge_mark(seed)
        if noise_free:
            sc.full_well_e, sc.read_e, sc.bits = 1e9, 0.0, 16
        p = U.write_image(tmp_path / f"e{seed}.png", render(sc))
        rc, js, err = json_of("marks", p, *NO_LENS, *flags)
        (m,) = marks_of(js)
        if not silent_only or (js["ok"] and not js["warnings"]):
            zs.append(U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"])
    return np.asarray(zs)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "a horizontal 300 px mark 6 px from the bottom edge, vignetting 35 %, 12-bit, clean: over "
    "16 seeds RMS z 1.61, max 3.15, all ok and silent. The cause is my renderer's order, not "
    "the edge nor the vignetting: it blurs the pixel grid AFTER the pixels (a digital filter), "
    "and the sharp groove's pixel-phase detail moves the centres of a mark crossing < ~1.5 "
    "phase cycles (noise-free seeds 0, 8: +9.0, -9.3 arcsec). The same marks at the frame's "
    "centre without vignetting: RMS z 1.66 (max 3.06); the same scene blurred BEFORE the "
    "pixels (optics): 0.82 (2.16), the test below. The images cannot tell the orders apart: "
    "the best test at 1 % false alarms detects blur-after with power <= 0.70-0.82 on these "
    "marks, <= 0.02 below 0.15 cycles (benchmarks/grid_phase.py --what oracle cause). The tool "
    "assumes blur before the pixels unless told --blur-after-pixels (docs/camera.md; the "
    "test below): open, the lead's call"))
def test_mark_near_the_frame_edge_under_vignetting_within_u_over_seeds(tmp_path):
    zs = _edge_z(tmp_path, range(16), U.render, silent_only=True)
    # 16 honest z: RMS beyond 1.5 has p < 0.01 (chi2 16 dof), |z| > 3.3 p < 0.02
    assert np.sqrt(np.mean(zs ** 2)) < 1.5 and np.abs(zs).max() < 3.3, np.round(zs, 2)


@pytest.mark.slow
def test_mark_near_the_frame_edge_under_vignetting_blurred_by_optics_within_u_over_seeds(
        tmp_path):
    """The xfail's 16 scenes with the blur before the pixels, as a lens blurs: the frame's
    edge (the band cut 6 px below the centre) and 35 % vignetting leave the angle within u
    (measured: RMS z 0.82, max 2.16; every mark counted, flagged or not)."""
    zs = _edge_z(tmp_path, range(16), U.render_optics_first, silent_only=False)
    assert len(zs) == 16
    assert np.sqrt(np.mean(zs ** 2)) < 1.5 and np.abs(zs).max() < 3.3, np.round(zs, 2)


@pytest.mark.slow
def test_mark_near_the_frame_edge_declared_blurred_after_the_pixels_within_u_over_seeds(
        tmp_path):
    """The xfail's 16 images as rendered (blurred after the pixels), the filter declared
    (``--blur-after-pixels``): the grid_phase term covers them, still silent (measured: RMS
    z 1.61 -> 1.21, max 3.15 -> 2.27)."""
    zs = _edge_z(tmp_path, range(16), U.render, silent_only=True,
                 flags=("--blur-after-pixels",))
    assert len(zs) == 16
    assert np.sqrt(np.mean(zs ** 2)) < 1.5 and np.abs(zs).max() < 3.3, np.round(zs, 2)


def test_mark_near_the_frame_edge_declared_blurred_after_the_pixels_noise_free(tmp_path):
    """The slow test's short twin: seed 8 noise-free as rendered, -9.3" at u 1.5" (z -6.4)
    undeclared; declared, the grid_phase term covers it (measured: u 7.0", z -1.3)."""
    zs = _edge_z(tmp_path, (8,), U.render, silent_only=False, noise_free=True,
                 flags=("--blur-after-pixels",))
    assert len(zs) == 1 and np.abs(zs).max() < 3.0, np.round(zs, 2)


def test_mark_near_the_frame_edge_blurred_by_optics_noise_free_is_unbiased(tmp_path):
    """The slow test's short twin: seed 8 noise-free, so any bias the edge or the vignetting
    put on the angle stands alone against u's Type B floor: measured -0.01" at 0.47".
    Blurred after the pixels instead, it is -9.3" at 1.5" (z -6.4)."""
    zs = _edge_z(tmp_path, (8,), U.render_optics_first, silent_only=False, noise_free=True)
    assert len(zs) == 1 and np.abs(zs).max() < 3.0, np.round(zs, 2)


def test_over_exposed_frame_is_measured_or_the_clipping_is_named(tmp_path):
    a = 0.12
    sc = U.Scene(640, 480, (U.Mark(322.0, 238.0, a, 300),), seed=0, bits=12, level=1.15,
                 vignetting=0.35)
    p = U.write_image(tmp_path / "over.png", U.render(sc))
    rc, js, err = json_of("marks", p, *NO_LENS)
    ms = marks_of(js)
    if ms:
        m = ms[0]
        assert abs(U.wrap_deg(m["angle_deg"] - a) * 3600) < 3 * m["angle_u_arcsec"]
    else:
        assert rc == 2 and any(w in err for w in ("clip", "saturat", "4095")), err


@pytest.mark.slow
def test_session_imageless_platform_out_of_level_is_found_and_E_within_u(session_run):
    """Tumble and platform poses only: the ellipsoid and the gimbal poses see E_xZ, E_yZ
    without the levelled poses, so a 30" levelling error is separable and found."""
    rc, js, err, truth = session_run("level_plain")
    assert "platform_level" in [e["name"] for e in js["effects"]], js["effects"]
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])


@pytest.mark.slow
def test_session_four_images_through_the_real_lens_test_its_model(session_run):
    """Camera A's four images rendered through my calibration of the real chessboard lens,
    the session given the tool's own model of it: the marks' bows disagree with the model
    (named: 'the lens differs from its calibration'), and E stays within u."""
    rc, js, err, truth = session_run("chess_model")
    assert any("differs from its calibration" in w for w in js["warnings"]), js["warnings"]
    assert np.all(np.abs(e_z(js, truth["E"])) < 3), e_z(js, truth["E"])
