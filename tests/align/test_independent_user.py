"""An independent user's tests of the ``align`` command.

Written from README.md and ``align ... --help`` only, on inputs from this folder's own
generators (``user_inputs.py``: area-integrated grooves, counter logs of a turning table,
tumbles of a slightly misaligned triad) — not from ``synth``.  Tests that pass document
behaviour a user relies on; tests marked ``xfail(strict=True)`` expose a defect (their
reason says which) and start failing — to be un-xfailed — once it is fixed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.align import user_inputs as ui
from tests.cli import run_cli

ROOT = Path(__file__).resolve().parents[2]


# --------------------------------------------------------------------------- helpers


def cli(args, cwd: Path) -> tuple[int, str, str]:
    """Run ``align ARGS`` from ``cwd`` (in this process: ``tests.cli``); (exit status, stdout,
    stderr)."""
    return run_cli(*args, cwd=cwd)


def err_lines(err: str) -> list[str]:
    """Non-empty stderr lines, without progress lines ('  [session] stage')."""
    return [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("  [")]


def assert_one_line_refusal(rc: int, err: str, *names: str) -> str:
    """Exit 2, no traceback, one stderr line that names each of ``names``."""
    lines = err_lines(err)
    assert rc == 2, (rc, err)
    assert "Traceback" not in err, err
    assert len(lines) == 1, lines
    for n in names:
        assert n in lines[0], (n, lines[0])
    return lines[0]


PROVENANCE_KEYS = {"provenance", "tool", "tool_version", "created_utc", "command", "settings",
                   "inputs"}


def numbers(d, prefix=""):
    """All numbers of a JSON document by path, without its provenance."""
    out = {}
    if isinstance(d, dict):
        for k, v in d.items():
            if k not in PROVENANCE_KEYS:
                out.update(numbers(v, f"{prefix}/{k}"))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            out.update(numbers(v, f"{prefix}/{i}"))
    elif isinstance(d, (int, float)) and not isinstance(d, bool):
        out[prefix] = d
    return out


# --------------------------------------------------------------------------- fixtures

TUMBLE_HEADER = ["pose", "ux", "uy", "uz", "t"]
LOG_HEADER = ["count", "counter", "ref", "t"]
FACES_DEG = [0.0, 90.0 + 0.01, 180.0 - 0.004, 270.0 + 0.02]


@pytest.fixture(scope="module")
def triad():
    return ui.make_triad(3)


@pytest.fixture(scope="module")
def tumble(tmp_path_factory, triad):
    d = tmp_path_factory.mktemp("tumble")
    rows = ui.tumble_rows(triad, seed=3)
    ui.write_csv(d / "tumble.csv", TUMBLE_HEADER, rows)
    return d, rows


@pytest.fixture(scope="module")
def gonio_log(tmp_path_factory):
    d = tmp_path_factory.mktemp("gonio")
    rows, true = ui.counter_log(FACES_DEG, revs=100, seed=1)
    ui.write_csv(d / "log.csv", LOG_HEADER, rows)
    return d, rows, true


SESSION_TOML = """name = "user"
[calibration]
static = "tumble.csv"
[platform]
static = "platform.csv"
""" + ui.PLATFORM_POSES_TOML


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory):
    """A session of calibration + platform poses (determines all six angles)."""
    root = tmp_path_factory.mktemp("sessions")
    d = root / "base"
    d.mkdir()
    tri = ui.make_triad(3, mis_rad=3e-4)
    ui.write_csv(d / "tumble.csv", TUMBLE_HEADER, ui.tumble_rows(tri, seed=3))
    ui.write_csv(d / "platform.csv", TUMBLE_HEADER, ui.platform_rows(tri, seed=4))
    (d / "session.toml").write_text(SESSION_TOML)
    return d, tri


def copy_session(base: Path, name: str) -> Path:
    d = base.parent / name
    if d.exists():
        shutil.rmtree(d)
    shutil.copytree(base, d, symlinks=True)
    for f in d.glob("*.json"):
        f.unlink()
    return d


# =========================================================================== marks

def _mark_image(seed=5, angle=20.0, centre=(320.0, 240.0), length=300.0, snr=40.0,
                shape=(480, 640), **kw):
    return ui.render_mark(shape, angle, centre, length, seed=seed, snr=snr, **kw)


FLAT_LENS = ("--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")
"""These renders have no lens, and say so (an undeclared lens is carried in u: off-centre
and diagonal marks are then lens-limited, exit 2; see docs/camera.md)."""


def _marks(d: Path, files, *extra):
    out = d / "out.json"
    if out.exists():
        out.unlink()
    lens = () if any(x in extra for x in ("--lens", "--camera")) else FLAT_LENS
    rc, so, se = cli(["marks", *files, "--json", "out.json", "-q", *extra, *lens], d)
    doc = json.loads(out.read_text()) if out.exists() else None
    return rc, doc, se


def test_marks_same_image_as_png_tiff_8_and_16_bit_gives_the_same_numbers(tmp_path):
    """8-bit PNG, the same data ×257 as 16-bit PNG and uncompressed 16-bit TIFF, and 8-bit
    TIFF are one image: the measured line must be the same."""
    import cv2

    img, truth = _mark_image(angle=-33.3, centre=(300.2, 250.7))
    q8 = ui.quantise(img, 8)
    q16 = q8.astype(np.uint16) * 257
    cv2.imwrite(str(tmp_path / "a8.png"), q8)
    cv2.imwrite(str(tmp_path / "a16.png"), q16)
    cv2.imwrite(str(tmp_path / "a16.tif"), q16, [cv2.IMWRITE_TIFF_COMPRESSION, 1])
    cv2.imwrite(str(tmp_path / "a8.tif"), q8, [cv2.IMWRITE_TIFF_COMPRESSION, 1])
    files = ["a8.png", "a16.png", "a16.tif", "a8.tif"]
    rc, doc, se = _marks(tmp_path, files)
    assert rc == 0, se
    ms = doc["marks"]
    assert [m["image"] for m in ms] == files and all(m["found"] for m in ms)
    for key in ("angle_deg", "angle_u_arcsec", "offset_px", "offset_u_px"):
        vals = [m[key] for m in ms]
        np.testing.assert_allclose(vals, vals[0], rtol=1e-9, atol=1e-12, err_msg=key)
    err = ui.wrap_angle(ms[0]["angle_deg"] - truth.angle_deg) * 3600
    assert abs(err) < 4.5 * ms[0]["angle_u_arcsec"]


def test_marks_reads_lzw_tiff(tmp_path):
    import cv2

    img, truth = _mark_image()
    cv2.imwrite(str(tmp_path / "lzw.tif"), ui.quantise(img, 16))  # default: LZW
    rc, doc, se = _marks(tmp_path, ["lzw.tif"])
    assert rc == 0 and doc["marks"][0]["found"], se


def test_marks_multipage_tiff_is_not_misread(tmp_path):
    import tifffile

    img, truth = _mark_image()
    q = ui.quantise(img, 16)
    tifffile.imwrite(tmp_path / "stack.tif", np.stack([q, q]))
    rc, doc, se = _marks(tmp_path, ["stack.tif"])
    m = doc["marks"][0]
    if m["found"]:
        assert abs(ui.wrap_angle(m["angle_deg"] - truth.angle_deg)) * 3600 < 5 * m["angle_u_arcsec"]
    else:
        assert "480x2" not in m["error"] and "page" in m["error"].lower(), m["error"]


def _edge_scene(i: int, rng, shape=(480, 640)):
    """A mark hugging one edge (groove 6-12 px inside), near an axis or oblique."""
    h, w = shape
    side = i % 4
    near_axis = i % 3 != 2
    dev = rng.uniform(-0.9, 0.9) if near_axis else rng.uniform(-8, 8)
    dist = rng.uniform(6, 12)
    if side < 2:
        a = dev
        L = rng.uniform(150, 400)
        cx = rng.uniform(L / 2 + 10, w - 1 - L / 2 - 10)
        ext = abs(np.sin(np.radians(a))) * L / 2
        cy = dist + ext if side == 0 else h - 1 - dist - ext
    else:
        a = ui.wrap_angle(90 + dev)
        L = rng.uniform(150, 300)
        cy = rng.uniform(L / 2 + 10, h - 1 - L / 2 - 10)
        ext = abs(np.cos(np.radians(a))) * L / 2
        cx = dist + ext if side == 2 else w - 1 - dist - ext
    return a, (cx, cy), L


def _measure_scenes(tmp_path, scenes):
    """Write and measure (angle, centre, length, kw) scenes; per-image (truth, marks)."""
    import cv2

    files, truths = [], []
    for i, (a, c, L, kw) in enumerate(scenes):
        bits = kw.pop("bits", 16)
        shape = kw.pop("shape", (480, 640))
        img, tr = ui.render_mark(shape, a, c, L, **kw)
        f = f"s{i:03d}.png"
        cv2.imwrite(str(tmp_path / f), ui.quantise(img, bits))
        files.append(f)
        truths.append((tr, shape))
    rc, doc, se = _marks(tmp_path, files)
    by = {f: [] for f in files}
    for m in doc["marks"]:
        by[m["image"]].append(m)
    return rc, [(truths[i], by[f]) for i, f in enumerate(files)], se


def _check_found_once(results):
    z = []
    for (tr, shape), ms in results:
        found = [m for m in ms if m.get("found")]
        assert len(found) == 1, (tr, ms)
        m = found[0]
        h, w = shape
        # never the frame border: the offset is the true one, not +-half the frame
        assert abs(m["offset_px"] - tr.offset_px) < 1.0, (tr, m["offset_px"])
        z.append(ui.wrap_angle(m["angle_deg"] - tr.angle_deg) * 3600 / m["angle_u_arcsec"])
    return np.asarray(z)


def _hugging_scenes(n: int) -> list:
    """The first ``n`` of the edge-hugging scenes (scene i hugs side i % 4; 8- and 16-bit)."""
    rng = np.random.default_rng(11)
    scenes = []
    for i in range(n):
        a, c, L = _edge_scene(i, rng)
        scenes.append((a, c, L, dict(width_px=rng.uniform(2, 6), snr=rng.uniform(15, 60),
                                     seed=700 + i, bits=[8, 16][i % 2])))
    return scenes


# The default run: the first four scenes (each of the four edges once, 8- and 16-bit, one
# oblique); the slow run all eight (lead, issue 21: the default run's CPU).
@pytest.mark.parametrize("n", [4, pytest.param(8, marks=pytest.mark.slow)])
def test_marks_hugging_every_edge_are_found_and_the_border_never(tmp_path, n):
    scenes = _hugging_scenes(n)
    rc, results, se = _measure_scenes(tmp_path, scenes)
    assert rc == 0, se
    z = _check_found_once(results)
    assert np.all(np.abs(z) < 4.5), z


def test_marks_running_off_the_frame_and_beside_a_padded_border(tmp_path):
    """A mark cut by the frame edge is measured (its visible part); a black padded strip
    and a saturated strip along the border are not marks."""
    import cv2

    img1, t1 = _mark_image(seed=8, angle=10.0, centre=(600.0, 300.0), length=300)
    img2, t2 = _mark_image(seed=9, angle=-60.0, centre=(320.0, 20.0), length=400)
    img3, t3 = _mark_image(seed=10, angle=0.3, centre=(320.0, 240.0), length=300)
    q3 = ui.quantise(img3, 16)
    q3[:, :12] = 0
    q3[:8, :] = 65535
    for f, im in (("c1.png", ui.quantise(img1, 16)), ("c2.png", ui.quantise(img2, 16)),
                  ("pad.png", q3)):
        cv2.imwrite(str(tmp_path / f), im)
    rc, doc, se = _marks(tmp_path, ["c1.png", "c2.png", "pad.png"])
    assert rc == 0, se
    for tr, f in ((t1, "c1.png"), (t2, "c2.png"), (t3, "pad.png")):
        ms = [m for m in doc["marks"] if m["image"] == f]
        assert len(ms) == 1 and ms[0]["found"], ms
        assert abs(ms[0]["offset_px"] - tr.offset_px) < 1.0
        assert abs(ui.wrap_angle(ms[0]["angle_deg"] - tr.angle_deg)) * 3600 < 4.5 * ms[0][
            "angle_u_arcsec"]


def test_marks_two_marks_in_one_frame_both_measured_and_one_refuses(tmp_path):
    """A long near-horizontal mark and a short oblique one (150 px, the README's 'short mark
    beside a long strong one'): both found, each within its u.  --one refuses a frame with
    two comparable marks."""
    import cv2

    img, tr = ui.render_mark((1024, 1280), 0.2, (640.0, 300.0), 900, seed=22, snr=60,
                             extra_marks=[(45.0, (900.0, 750.0), 150)])
    cv2.imwrite(str(tmp_path / "two.png"), ui.quantise(img, 16))
    rc, doc, se = _marks(tmp_path, ["two.png"])
    assert rc == 0, se
    ms = sorted(doc["marks"], key=lambda m: m["length_px"], reverse=True)
    assert len(ms) == 2 and all(m["found"] for m in ms)
    for m, a in zip(ms, (0.2, 45.0), strict=True):
        assert abs(ui.wrap_angle(m["angle_deg"] - a)) * 3600 < 4.5 * m["angle_u_arcsec"], m
    # two marks of comparable strength (900 px and 500 px) where --one says one is expected
    img, tr = ui.render_mark((1024, 1280), 0.2, (640.0, 300.0), 900, seed=21, snr=60,
                             extra_marks=[(90.3, (300.0, 600.0), 500)])
    cv2.imwrite(str(tmp_path / "two2.png"), ui.quantise(img, 16))
    rc, doc, se = _marks(tmp_path, ["two2.png"], "--one")
    assert rc == 2 and doc["marks"][0]["found"] is False and "two" in doc["marks"][0]["error"]


def _random_scenes(n, seed, sizes=((480, 640),)):
    rng = np.random.default_rng(seed)
    scenes = []
    for i in range(n):
        h, w = sizes[i % len(sizes)]
        kind = i % 4
        a = [rng.uniform(-1, 1), 90 + rng.uniform(-1, 1), rng.uniform(-89, 89),
             rng.uniform(-1, 1)][kind]
        a = ui.wrap_angle(a)
        L = rng.uniform(100, min(h, w) * 0.8)
        ar = np.radians(a)
        hx, hy = abs(np.cos(ar)) * L / 2 + 8, abs(np.sin(ar)) * L / 2 + 8
        cx, cy = rng.uniform(hx, w - 1 - hx), rng.uniform(hy, h - 1 - hy)
        if rng.random() < 0.4:  # pushed against one edge
            side = rng.integers(4)
            cx = [hx, w - 1 - hx, cx, cx][side]
            cy = [cy, cy, hy, h - 1 - hy][side]
        scenes.append((a, (cx, cy), L, dict(
            width_px=rng.uniform(2, 7), blur_px=rng.uniform(0.8, 1.8),
            snr=rng.uniform(10, 80), seed=seed * 1000 + i, bits=[8, 16][rng.integers(2)],
            shape=(h, w))))
    return scenes


@pytest.mark.slow  # random scenes: the statistical sweeps of test_measure and test_scenes
def test_marks_random_small_scenes_truth_and_honest_u(tmp_path):
    rc, results, se = _measure_scenes(tmp_path, _random_scenes(10, seed=1))
    assert rc == 0, se
    z = _check_found_once(results)
    assert np.all(np.abs(z) < 4.5), z


@pytest.mark.slow
def test_marks_many_scenes_normalised_errors_and_no_false_flags(tmp_path):
    """90 marks 100 px ... 80 % of the short side, 0.3-5 MP, 8/16 bit, half within 1 deg
    of an axis, 40 % pushed against an edge: all found once, normalised angle error RMS in
    [0.8, 1.25], and at most 1 % flagged with a loop effect or unexplained structure."""
    sizes = ((480, 640), (1024, 1280), (2048, 2448))
    rc, results, se = _measure_scenes(tmp_path, _random_scenes(90, 3, sizes))
    assert rc == 0, se
    z = _check_found_once(results)
    assert 0.8 < np.sqrt(np.mean(z ** 2)) < 1.25, z
    flagged = [ms for _, ms in results if ms[0]["effects"] or ms[0]["unexplained_structure"]]
    assert len(flagged) <= 1, flagged


def test_marks_no_mark_and_broken_files_in_one_batch_lose_nothing(tmp_path):
    import cv2

    img, truth = _mark_image()
    cv2.imwrite(str(tmp_path / "ok.png"), ui.quantise(img, 8))
    cv2.imwrite(str(tmp_path / "uniform.png"), np.full((480, 640), 128, np.uint8))
    noise = np.random.default_rng(0).normal(128, 5, (480, 640))
    cv2.imwrite(str(tmp_path / "noise.png"), np.clip(noise, 0, 255).astype(np.uint8))
    (tmp_path / "text.png").write_text("hello")
    b = (tmp_path / "ok.png").read_bytes()
    (tmp_path / "trunc.png").write_bytes(b[: len(b) // 2])
    (tmp_path / "folder.png").mkdir()
    shutil.copy(tmp_path / "ok.png", tmp_path / "ok2.png")
    files = ["ok.png", "uniform.png", "noise.png", "text.png", "trunc.png", "folder.png",
             "missing.png", "ok2.png"]
    rc, doc, se = _marks(tmp_path, files)
    assert rc == 2 and "Traceback" not in se
    assert [m["image"] for m in doc["marks"]] == files
    found = {m["image"]: m["found"] for m in doc["marks"]}
    assert found == {f: f in ("ok.png", "ok2.png") for f in files}
    assert doc["ok"] is False
    for m in doc["marks"]:
        if not m["found"]:
            assert m["error"] and m["image"] in m["error"]


@pytest.mark.parametrize("flags, name", [
    (["--roi", "0,0,0,10"], "--roi"), (["--roi", "1,2,3"], "--roi"),
    (["--roi", "a,b,c,d"], "--roi"), (["--min-length", "0"], "--min-length"),
    (["--min-length", "-5"], "--min-length"), (["--max-marks", "0"], "--max-marks"),
    (["--alpha", "2"], "--alpha"), (["--camera", "missing.json"], "missing.json"),
    (["--camera", "ok.png"], "ok.png"), (["--plot", "ok.png"], "--plot"),
    (["--json", "ok.png"], "--json"),
])
def test_marks_bad_flags_refused_in_one_line(tmp_path, flags, name):
    import cv2

    img, _ = _mark_image()
    cv2.imwrite(str(tmp_path / "ok.png"), ui.quantise(img, 8))
    before = (tmp_path / "ok.png").read_bytes()
    rc, so, se = cli(["marks", "ok.png", *flags], tmp_path)
    assert_one_line_refusal(rc, se, name)
    assert (tmp_path / "ok.png").read_bytes() == before


def test_marks_existing_json_is_kept_and_force_replaces_only_outputs(tmp_path):
    import cv2

    img, _ = _mark_image()
    cv2.imwrite(str(tmp_path / "ok.png"), ui.quantise(img, 8))
    (tmp_path / "out.json").write_text("precious")
    rc, so, se = cli(["marks", "ok.png", "--json", "out.json"], tmp_path)
    assert_one_line_refusal(rc, se, "out.json")
    assert (tmp_path / "out.json").read_text() == "precious"
    rc, so, se = cli(["marks", "ok.png", "--json", "out.json", "--force", "-q", *FLAT_LENS],
                     tmp_path)
    assert rc == 0 and json.loads((tmp_path / "out.json").read_text())["marks"][0]["found"]


# =========================================================================== calibrate

def _cal_doc(d: Path, name: str, *extra):
    out = d / (name + ".out.json")
    if out.exists():
        out.unlink()
    rc, so, se = cli(["calibrate", name, "--json", out.name, "-q", *extra], d)
    return rc, (json.loads(out.read_text()) if out.exists() else None), se


CSV_VARIANTS = {
    "bom_crlf": dict(bom=True, eol="\r\n"),
    "semicolon": dict(sep=";"),
    "tab": dict(sep="\t"),
    "reordered": dict(order=[4, 2, 0, 3, 1]),
}


@pytest.fixture(scope="module")
def cal_plain(tumble):
    d, rows = tumble
    import contextlib
    import io

    from align.cli import main

    old = os.getcwd()
    os.chdir(d)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert main(["calibrate", "tumble.csv", "--json", "plain.json", "-q"]) == 0
    finally:
        os.chdir(old)
    return json.loads((d / "plain.json").read_text())


@pytest.mark.parametrize("variant", [*CSV_VARIANTS, "header_case_spaces", "unit_suffix"])
def test_calibrate_valid_variants_give_identical_numbers(tumble, cal_plain, variant):
    d, rows = tumble
    header = TUMBLE_HEADER
    kw = CSV_VARIANTS.get(variant, {})
    if variant == "header_case_spaces":
        header = [" Pose ", "UX", " Uy", "uZ ", "T"]
    if variant == "unit_suffix":
        header = ["pose", "ux [V]", "uy [V]", "uz [V]", "t [s]"]
    name = f"v_{variant}.csv"
    ui.write_csv(d / name, header, rows, **kw)
    rc, doc, se = _cal_doc(d, name)
    assert rc == 0, se
    assert numbers(doc) == numbers(cal_plain)


def test_calibrate_against_the_generators_truth(triad, cal_plain):
    k = np.array(cal_plain["scale_factors_v_per_g"])
    ku = np.array(cal_plain["scale_factors_u_v_per_g"])
    b = np.array(cal_plain["bias_g"])
    bu = np.array(cal_plain["bias_u_g"])
    assert np.all(np.abs((k - triad.k) / ku) < 4.5)
    # the bias is defined before the non-orthogonality: compare within its u plus the
    # frame term |beta| * |b| (< 1 µg here)
    assert np.all(np.abs(b - triad.bias_g) < 4.5 * bu + 1e-6)
    assert cal_plain["ok"] is True and cal_plain["noise_known"] is True


def test_calibrate_same_tumble_in_m_per_s2_scales_exactly(tumble, cal_plain):
    d, rows = tumble
    g0 = 9.80665
    ui.write_csv(d / "ms2.csv", ["pose", "ux [m/s2]", "uy [m/s2]", "uz [m/s2]", "t"],
                 [[r[0], r[1] * g0, r[2] * g0, r[3] * g0, r[4]] for r in rows])
    rc, doc, se = _cal_doc(d, "ms2.csv")
    assert rc == 0, se
    assert doc["output_unit"] != cal_plain["output_unit"]
    assert "m/s" in doc["scale_factor_unit"]
    np.testing.assert_allclose(doc["scale_factors_v_per_g"],
                               np.array(cal_plain["scale_factors_v_per_g"]) * g0, rtol=1e-9)
    np.testing.assert_allclose(doc["bias_g"], cal_plain["bias_g"], rtol=1e-7)
    np.testing.assert_allclose(doc["beta_rad"], cal_plain["beta_rad"], rtol=1e-7)
    rc, so, se = cli(["calibrate", "ms2.csv", "--units", "g"], d)
    assert_one_line_refusal(rc, se, "ms2.csv", "--units")


def _continuous_recording(tri, seed=5, fs=100.0):
    """t,ux,uy,uz: 6 s static per pose, 1.5 s smooth turns with vibration between."""
    rng = np.random.default_rng(seed)
    dirs = [np.array(v, float) for v in
            [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]]
    rr = np.random.default_rng(3)
    while len(dirs) < 18:
        v = rr.normal(size=3)
        dirs.append(v / np.linalg.norm(v))

    def slerp(a, b, s):
        om = np.arccos(np.clip(a @ b, -1, 1))
        return a if om < 1e-6 else (np.sin((1 - s) * om) * a + np.sin(s * om) * b) / np.sin(om)

    out, t = [], 0.0
    for i, f in enumerate(dirs):
        for _ in range(int(6 * fs)):
            out.append([round(t, 3), *(ui.read_triad(tri, f)[0] + rng.normal(0, 2e-5, 3))])
            t += 1 / fs
        if i + 1 == len(dirs):
            break
        g = dirs[i + 1]
        legs = [(f, g)]
        if f @ g < -0.99:  # opposite: turn through a perpendicular direction
            mid = np.cross(f, [0.3, 0.5, 0.8])
            mid /= np.linalg.norm(mid)
            legs = [(f, mid), (mid, g)]
        for a, b in legs:
            n = int(1.5 * fs)
            for k in range(n):
                v = slerp(a, b, 0.5 - 0.5 * np.cos(np.pi * k / n))
                out.append([round(t, 3), *(ui.read_triad(tri, v)[0] + rng.normal(0, 3e-3, 3))])
                t += 1 / fs
    return [[r[0], *(round(float(x), 9) for x in r[1:])] for r in out]


def test_calibrate_continuous_recording_finds_every_pose(tumble, triad):
    d, _ = tumble
    ui.write_csv(d / "cont.csv", ["t", "ux", "uy", "uz"], _continuous_recording(triad))
    rc, doc, se = _cal_doc(d, "cont.csv")
    assert rc == 0, se
    assert len(doc["poses"]) == 18
    k, ku = np.array(doc["scale_factors_v_per_g"]), np.array(doc["scale_factors_u_v_per_g"])
    b, bu = np.array(doc["bias_g"]), np.array(doc["bias_u_g"])
    assert np.all(np.abs(k - triad.k) < 4.5 * ku)
    assert np.all(np.abs(b - triad.bias_g) < 4.5 * bu + 1e-6)


@pytest.mark.slow
def test_calibrate_uncertainty_is_honest_over_seeds(tmp_path):
    zk = []
    for s in range(12):
        tri = ui.make_triad(100 + s)
        ui.write_csv(tmp_path / f"t{s}.csv", TUMBLE_HEADER, ui.tumble_rows(tri, seed=s))
        rc, doc, se = _cal_doc(tmp_path, f"t{s}.csv")
        assert rc == 0, se
        zk += list((np.array(doc["scale_factors_v_per_g"]) - tri.k)
                   / np.array(doc["scale_factors_u_v_per_g"]))
    rms = np.sqrt(np.mean(np.square(zk)))
    assert 0.7 < rms < 1.35, zk


def _bad_tumbles(rows: list[list]) -> dict[str, tuple[bytes, str]]:
    """name -> (file bytes, text the one-line message must contain)."""
    h = ",".join(TUMBLE_HEADER)
    lines = [",".join(map(str, r)) for r in rows]

    def with_cell(i, col, val):
        r = lines[i].split(",")
        r[col] = val
        return ",".join(r)

    def text(ls):
        return ("\n".join(ls) + "\n").encode()

    return {
        "empty": (b"", "empty"),
        "header_only": (text([h]), "no rows"),
        "blank_label": (text([h, *lines[:60], with_cell(60, 0, ""), *lines[61:]]), ":62:"),
        "nan": (text([h, *lines[:70], with_cell(70, 2, "nan"), *lines[71:]]), ":72:"),
        "inf": (text([h, *lines[:70], with_cell(70, 2, "inf"), *lines[71:]]), ":72:"),
        "word": (text([h, *lines[:70], with_cell(70, 2, "abc"), *lines[71:]]), ":72:"),
        "truncated": (text([h, *lines[:70], ",".join(lines[70].split(",")[:3]),
                            *lines[71:]]), ":72:"),
        "extra_field": (text([h, *lines[:70], lines[70] + ",5", *lines[71:]]), ":72:"),
        "time_backwards": (text([h, *lines[:70], lines[71], lines[70], *lines[72:]]), ":73:"),
        "rows_doubled": (text([h] + [ln for ln in lines for _ in (0, 1)]), ":3:"),
        "file_doubled": (text([h, *lines, *lines]), f":{len(lines) + 2}:"),
        "missing_uz": (text(["pose,ux,uy,t"] + [",".join(ln.split(",")[i] for i in (0, 1, 2, 4))
                                                for ln in lines]), "uz"),
        "duplicate_header": (text(["pose,ux,ux,uz,t", *lines]), "ux"),
        "no_header": (text(lines), "header"),
        "latin1": (("pose,ux,uy,uz,t\n" + "\n".join(lines[:5]) + "\nPö,1,2,3,999\n")
                   .encode("latin-1"), "UTF-8"),
        "binary": (bytes(range(256)) * 10, "UTF-8"),
        "decimal_comma": (text(["pose;ux;uy;uz;t"] + [ln.replace(",", ";").replace(".", ",")
                                                      for ln in lines]), "decimal comma"),
        "one_pose": (text([h, *lines[:50]]), "poses"),
    }


BAD_TUMBLE_NAMES = list(_bad_tumbles([["P", 1.0, 0.0, 0.0, 0.0]] * 100))


@pytest.mark.parametrize("case", BAD_TUMBLE_NAMES)
def test_calibrate_malformed_static_file_refused_in_one_line(tumble, case):
    d, rows = tumble
    data, must = _bad_tumbles(rows)[case]
    name = f"bad_{case}.csv"
    (d / name).write_bytes(data)
    rc, doc, se = _cal_doc(d, name)
    line = assert_one_line_refusal(rc, se, must)
    assert doc is None
    if case not in ("one_pose",):
        assert name in line, line


def test_calibrate_folder_and_missing_file(tumble):
    d, _ = tumble
    (d / "folder.csv").mkdir(exist_ok=True)
    rc, so, se = cli(["calibrate", "folder.csv"], d)
    assert_one_line_refusal(rc, se, "folder.csv", "folder")
    rc, so, se = cli(["calibrate", "nothere.csv"], d)
    assert_one_line_refusal(rc, se, "nothere.csv")


def test_calibrate_folder_message_reads_well(tumble):
    d, _ = tumble
    (d / "folder.csv").mkdir(exist_ok=True)
    rc, so, se = cli(["calibrate", "folder.csv"], d)
    assert "file file" not in se


def test_calibrate_huge_value_one_line_with_line_number(tumble):
    d, rows = tumble
    lines = [",".join(map(str, r)) for r in rows]
    r = lines[70].split(",")
    r[2] = "1e308"
    lines[70] = ",".join(r)
    (d / "huge.csv").write_text("\n".join([",".join(TUMBLE_HEADER), *lines]) + "\n")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # an overflow would surface as rc 1
        rc, so, se = cli(["calibrate", "huge.csv"], d)
    assert_one_line_refusal(rc, se, "huge.csv:72")


def test_table_messages_show_plain_numbers(tumble):
    d, rows = tumble
    lines = [",".join(map(str, r)) for r in rows]
    (d / "back.csv").write_text("\n".join([",".join(TUMBLE_HEADER), *lines[:70], lines[71],
                                           lines[70], *lines[72:]]) + "\n")
    rc, so, se = cli(["calibrate", "back.csv"], d)
    assert rc == 2 and "np.float64" not in se, se


@pytest.mark.parametrize("flags, name", [
    (["--rate", "0"], "--rate"), (["--rate", "nan"], "--rate"),
    (["--rate", "100"], "--rate"),  # the file has its own time column
    (["--alpha", "5"], "--alpha"), (["--alpha", "nan"], "--alpha"),
    (["--window", "0"], "--window"), (["--threshold", "inf"], "--threshold"),
    (["--min-static", "-2"], "--min-static"), (["--margin", "nan"], "--margin"),
    (["--scale-sign", "x"], "--scale-sign"), (["--scale-sign=-,-"], "--scale-sign"),
    (["--columns", "ux"], "--columns"), (["--columns", "ux=foo"], "ux=foo"),
    (["--columns", "bogus=ux"], "bogus"), (["--columns", "ux=uy"], "uy"),
    (["--units", "furlong"], "--units"), (["--check", "tumble.csv"], "tumble.csv"),
    (["--json", "tumble.csv"], "--json"), (["--plot", "tumble.csv"], "--plot"),
])
def test_calibrate_bad_flags_refused_in_one_line(tumble, flags, name):
    d, _ = tumble
    before = (d / "tumble.csv").read_bytes()
    rc, so, se = cli(["calibrate", "tumble.csv", *flags], d)
    assert_one_line_refusal(rc, se, name)
    assert (d / "tumble.csv").read_bytes() == before


@pytest.mark.parametrize("cmd", ["calibrate", "gonio"])
def test_quiet_with_json_to_stdout_leaves_stderr_to_warnings(tumble, gonio_log, cmd):
    if cmd == "calibrate":
        d, args = tumble[0], ["calibrate", "tumble.csv"]
    else:
        d, args = gonio_log[0], ["gonio", "log.csv", "--faces", "ref,y,x,z"]
    rc, so, se = cli([*args, "--json", "-", "-q"], d)
    assert rc == 0 and json.loads(so)
    noise = [ln for ln in err_lines(se) if not ln.startswith("WARNING")]
    assert noise == [], noise


def test_calibrate_scale_sign_three_signs_as_documented(tumble):
    d, _ = tumble
    rc, doc, se = _cal_doc(d, "tumble.csv", "--scale-sign", "-,-,-")
    assert rc == 0, se
    assert doc["scale_sign"] == [-1.0, -1.0, -1.0]


def test_calibrate_one_stray_sample_does_not_silently_change_the_result(tmp_path, triad):
    rows = ui.tumble_rows(triad, seed=3, samples=20, poses=14)
    ui.write_csv(tmp_path / "clean.csv", TUMBLE_HEADER, rows)
    ui.write_csv(tmp_path / "stray.csv", TUMBLE_HEADER, [*rows, ["PX", *rows[5][1:4], 9999.0]])
    rc, clean, se = _cal_doc(tmp_path, "clean.csv")
    assert rc == 0 and clean["noise_known"] is True, se
    rc, doc, se = _cal_doc(tmp_path, "stray.csv")
    if rc == 2:  # refused, naming the pose: fine
        assert "PX" in se
        return
    assert doc["noise_known"] is True
    b0, bu0 = np.array(clean["bias_g"]), np.array(clean["bias_u_g"])
    assert np.all(np.abs(np.array(doc["bias_g"]) - b0) < bu0)
    assert np.all(np.array(doc["bias_u_g"]) < 1.5 * bu0)


# =========================================================================== gonio

@pytest.fixture(scope="module")
def gonio_plain(gonio_log):
    d, rows, true = gonio_log
    import contextlib
    import io

    from align.cli import main

    old = os.getcwd()
    os.chdir(d)
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            assert main(["gonio", "log.csv", "--faces", "ref,y,x,z", "--json", "plain.json",
                         "-q"]) == 0
    finally:
        os.chdir(old)
    return json.loads((d / "plain.json").read_text())


def _gonio_doc(d: Path, name: str, *extra, faces="ref,y,x,z"):
    out = d / (name + ".out.json")
    if out.exists():
        out.unlink()
    rc, so, se = cli(["gonio", name, "--faces", faces, "--json", out.name, "-q", *extra], d)
    return rc, (json.loads(out.read_text()) if out.exists() else None), se


@pytest.mark.parametrize("variant", [*CSV_VARIANTS, "header_case_spaces", "unit_suffix",
                                     "no_time"])
def test_gonio_valid_variants_give_identical_angles(gonio_log, gonio_plain, variant):
    d, rows, _ = gonio_log
    header, kw = LOG_HEADER, dict(CSV_VARIANTS.get(variant, {}))
    if "order" in kw:
        kw["order"] = [3, 1, 2, 0]
    if variant == "header_case_spaces":
        header = ["COUNT", " Counter ", "REF", "T"]
    if variant == "unit_suffix":
        header = ["count", "counter", "ref", "t [s]"]
    if variant == "no_time":
        header, rows = LOG_HEADER[:3], [r[:3] for r in rows]
    name = f"v_{variant}.csv"
    ui.write_csv(d / name, header, rows, **kw)
    rc, doc, se = _gonio_doc(d, name)
    # without times the Earth rate's share on a table that may not be steady is not in u:
    # the same angles, but not ok (exit 2; docs/commands/gonio.md)
    assert rc == (2 if variant == "no_time" else 0), se
    assert doc["ok"] is (variant != "no_time")
    assert doc["angles_deg"] == gonio_plain["angles_deg"]
    if variant == "no_time":
        # With times the pass also accumulates each angle's Earth-rate sensitivity beside the
        # angle (zeros without), which changes the rounding of the shared sums: the same u to
        # 1e-9, not to the bit. Everything derived from the same columns stays bit-identical.
        assert np.allclose(doc["angles_u_arcsec"], gonio_plain["angles_u_arcsec"],
                           rtol=1e-9, atol=0)
    else:
        assert doc["angles_u_arcsec"] == gonio_plain["angles_u_arcsec"]


def test_gonio_against_the_generators_truth(gonio_log, gonio_plain):
    _, _, true = gonio_log
    err = (np.array(gonio_plain["angles_deg"]) - np.array(true)) * 3600
    u = np.array(gonio_plain["angles_u_arcsec"])
    assert np.all(np.abs(err) < 4.5 * u), (err, u)
    assert gonio_plain["faces"] == ["ref", "y", "x", "z"]


@pytest.mark.slow
def test_gonio_uncertainty_is_honest_with_jitter(tmp_path):
    rng = np.random.default_rng(0)
    z = []
    for s in range(30):
        dev = rng.normal(0, 0.01, 3)
        faces = [0.0, 90 + dev[0], 180 + dev[1], 270 + dev[2]]
        rows, true = ui.counter_log(faces, revs=100, seed=100 + s, jitter_s=2e-6,
                                    phase0=rng.uniform())
        ui.write_csv(tmp_path / f"g{s}.csv", LOG_HEADER, rows)
        rc, doc, se = _gonio_doc(tmp_path, f"g{s}.csv")
        assert rc == 0, se
        z += list((np.array(doc["angles_deg"]) - true) * 3600 / np.array(doc["angles_u_arcsec"]))
    assert 0.8 < np.sqrt(np.mean(np.square(z))) < 1.15, z


def test_gonio_lost_row_excludes_one_revolution_and_says_where(gonio_log, gonio_plain):
    d, rows, true = gonio_log
    ui.write_csv(d / "lost.csv", LOG_HEADER, rows[:50] + rows[51:])
    rc, doc, se = _gonio_doc(d, "lost.csv")
    assert rc == 0, se
    assert doc["revolutions_used"] == gonio_plain["revolutions_used"] - 1
    assert any("missing" in w for w in doc["warnings"])
    err = (np.array(doc["angles_deg"]) - np.array(true)) * 3600
    assert np.all(np.abs(err) < 4.5 * np.array(doc["angles_u_arcsec"]))


def test_gonio_clean_log_has_no_warning(gonio_log, gonio_plain):
    assert gonio_plain["warnings"] == []


@pytest.mark.parametrize("where", ["middle", "end"])
def test_gonio_comment_lines_anywhere_are_ignored(gonio_log, gonio_plain, where):
    d, rows, _ = gonio_log
    h = ",".join(LOG_HEADER)
    lines = [",".join(map(str, r)) for r in rows]
    body = ([h, *lines[:100], "# table paused", *lines[100:]] if where == "middle"
            else [h, *lines, "# end of log"])
    (d / f"comment_{where}.csv").write_text("\n".join(["# logger 1.2", *body]) + "\n")
    rc, doc, se = _gonio_doc(d, f"comment_{where}.csv")
    assert rc == 0, se
    assert doc["angles_deg"] == gonio_plain["angles_deg"]


def test_gonio_comment_and_blank_lines_at_the_top_and_blank_lines_inside(gonio_log, gonio_plain):
    d, rows, _ = gonio_log
    lines = [",".join(map(str, r)) for r in rows]
    text = "\n".join(["# logger 1.2", "", ",".join(LOG_HEADER), *lines[:100], "", *lines[100:],
                      "", ""]) + "\n"
    (d / "blanks.csv").write_text(text)
    rc, doc, se = _gonio_doc(d, "blanks.csv")
    assert rc == 0, se
    assert doc["angles_deg"] == gonio_plain["angles_deg"]


def test_gonio_reverse_log_mean_of_both_directions_against_truth(gonio_log):
    """The same faces logged with the table turning clockwise (faces pass ref, z, x, y)."""
    d, _, true = gonio_log
    cw_positions = [0.0] + [360.0 - f for f in FACES_DEG[:0:-1]]
    rows, _ = ui.counter_log(cw_positions, revs=100, seed=2)
    ui.write_csv(d / "cw.csv", LOG_HEADER, rows)
    rc, doc, se = _gonio_doc(d, "log.csv", "--reverse-log", "cw.csv")
    assert rc == 0, se
    err = (np.array(doc["angles_deg"]) - np.array(true)) * 3600
    assert np.all(np.abs(err) < 4.5 * np.array(doc["angles_u_arcsec"])), err
    assert any(e["name"] == "direction_dependent" for e in doc["effects"])
    rc, cw, se = _gonio_doc(d, "cw.csv", "--direction", "cw", faces="ref,z,x,y")
    assert rc == 0, se
    # ref->z, z->x, x->y, y->ref clockwise are the ccw angles in reverse order
    np.testing.assert_allclose(cw["angles_deg"], true[::-1], atol=4.5 * max(
        cw["angles_u_arcsec"]) / 3600)


@pytest.mark.parametrize("flags, words", [(["--latitude", "50"], ("earth", "latitude")),
                                          (["--steady-table"], ("steady",))])
def test_gonio_flag_that_cannot_be_honoured_is_a_warning(gonio_log, flags, words):
    d, rows, _ = gonio_log
    ui.write_csv(d / "notime.csv", LOG_HEADER[:3], [r[:3] for r in rows])
    rc, doc, se = _gonio_doc(d, "notime.csv", *flags)
    assert doc["notes"], "the tool knows it did not do it"
    # The angles are still measured (exit 0); what was not done is a warning in the JSON.
    assert rc == 0, se
    assert any(k in w.lower() for w in doc["warnings"] for k in words), doc["warnings"]


def _bad_logs(rows):
    h = ",".join(LOG_HEADER)
    lines = [",".join(map(str, r)) for r in rows]

    def cell(i, col, val):
        r = lines[i].split(",")
        r[col] = val
        return "\n".join([h, *lines[:i], ",".join(r), *lines[i + 1:]]) + "\n"

    return {
        "empty": ("", "empty"),
        "header_only": (h + "\n", "no rows"),
        "negative_count": (cell(50, 0, "-5"), ":52:"),
        "fractional_count": (cell(50, 0, "191000.5"), ":52:"),
        "blank_count": (cell(50, 0, ""), ":52:"),
        "counter_3": (cell(50, 1, "3"), ":52:"),
        "ref_2": (cell(50, 2, "2"), ":52:"),
        "ref_word": (cell(50, 2, "yes"), ":52:"),
        "time_nan": (cell(50, 3, "nan"), ":52:"),
        "time_backwards": (cell(50, 3, "0.5"), ":52:"),
        "no_reference": ("\n".join([h] + [",".join(ln.split(",")[:2] + ["0"]
                                                   + ln.split(",")[3:]) for ln in lines]) + "\n",
                         "reference"),
        "rows_doubled": ("\n".join([h] + [ln for ln in lines for _ in (0, 1)]) + "\n", ":3:"),
        "truncated": ("\n".join([h, *lines[:50], ",".join(lines[50].split(",")[:2]),
                                  *lines[51:]]) + "\n", ":52:"),
        "no_ref_column": ("\n".join(["count,counter,t"] + [
            ",".join(ln.split(",")[i] for i in (0, 1, 3)) for ln in lines]) + "\n", "ref"),
    }


def test_gonio_double_trigger_gives_the_clean_logs_angles_and_u(gonio_log, gonio_plain):
    """A double trigger 1 ms after a reference face (an extra pulse: the counts of the next
    interval split, every later counter flipped) is resolved exactly: the same angles AND the
    same u as the clean log, listed with its line. (Found by the lead on data of this file's
    generator: the repaired revolution entered the statistics after the chunk's clean ones,
    and u moved by up to 35 %.)"""
    d, rows, _ = gonio_log
    i = next(k for k in range(40, len(rows)) if rows[k][2] == 1)
    c, ctr, ref, t = rows[i]
    nxt = rows[i + 1]
    k = int(nxt[0] * 1e-3 / (nxt[3] - t))
    extra = [k, 2 if ctr == 1 else 1, 0, t + 1e-3]
    flip = [[r[0], 2 if r[1] == 1 else 1, r[2], r[3]] for r in [[nxt[0] - k, *nxt[1:]],
                                                                  *rows[i + 2:]]]
    ui.write_csv(d / "dbl.csv", LOG_HEADER, [*rows[:i + 1], extra, *flip])
    rc, doc, se = _gonio_doc(d, "dbl.csv")
    assert rc == 0 and "spurious" in se, se
    assert doc["angles_deg"] == gonio_plain["angles_deg"]
    assert np.allclose(doc["angles_u_arcsec"], gonio_plain["angles_u_arcsec"], rtol=1e-12)


def test_gonio_zero_count_is_a_listed_fault_not_a_silent_change(gonio_log, gonio_plain):
    """A count of 0 is what two pulses within one ring-laser period give (a double trigger),
    so it is a fault to resolve, not a malformed file: listed with a warning, and the angles
    stay within their uncertainty of the clean log's."""
    d, rows, _ = gonio_log
    lines = [",".join(map(str, r)) for r in rows]
    r = lines[50].split(",")
    r[0] = "0"
    (d / "zero.csv").write_text("\n".join([",".join(LOG_HEADER), *lines[:50], ",".join(r),
                                           *lines[51:]]) + "\n")
    rc, doc, se = _gonio_doc(d, "zero.csv")
    assert rc == 0 and "WARNING" in se and doc["warnings"], se
    err = np.subtract(doc["angles_deg"], gonio_plain["angles_deg"]) * 3600
    assert np.all(np.abs(err) < 4 * np.asarray(doc["angles_u_arcsec"])), err


@pytest.mark.parametrize("case", list(_bad_logs([[1, 1, 1, 0.0]] * 60)))
def test_gonio_malformed_log_refused_in_one_line(gonio_log, case):
    d, rows, _ = gonio_log
    text, must = _bad_logs(rows)[case]
    name = f"bad_{case}.csv"
    (d / name).write_text(text)
    rc, doc, se = _gonio_doc(d, name)
    line = assert_one_line_refusal(rc, se, must)
    assert name in line and doc is None


def test_gonio_log_shorter_than_a_revolution(gonio_log):
    d, rows, _ = gonio_log
    ui.write_csv(d / "short3.csv", LOG_HEADER, rows[:3])
    rc, doc, se = _gonio_doc(d, "short3.csv")
    assert_one_line_refusal(rc, se, "short3.csv")


def test_gonio_log_of_a_few_revolutions(gonio_log):
    d, rows, _ = gonio_log
    ui.write_csv(d / "short9.csv", LOG_HEADER, rows[:9])
    rc, so, se = cli(["gonio", "short9.csv", "--faces", "ref,y,x,z"], d)
    line = assert_one_line_refusal(rc, se, "short9.csv")
    assert "zero-size" not in line


@pytest.mark.parametrize("faces", ["ref,y,x", "ref,y,x,z,w"])
def test_gonio_wrong_number_of_faces(gonio_log, faces):
    d, _, _ = gonio_log
    rc, doc, se = _gonio_doc(d, "log.csv", faces=faces)
    assert_one_line_refusal(rc, se, "--faces")


def test_gonio_nominal_far_from_the_measured_angles_is_flagged(gonio_log):
    d, _, _ = gonio_log
    # x and y 90 deg apart as their axes are (a plan with them 80 deg apart is refused: the
    # face-plan rule session.toml follows too), the reference and z 5 deg off what was measured
    rc, doc, se = _gonio_doc(d, "log.csv", "--nominal", "95,90,85,90")
    # The measured angles stand (exit 0); the nominal that disagrees is a warning.
    assert rc == 0, se
    assert any("nominal" in w for w in doc["warnings"]), doc["warnings"]


def test_gonio_nominal_with_x_and_y_not_perpendicular_is_refused(gonio_log):
    d, _, _ = gonio_log
    rc, so, se = cli(["gonio", "log.csv", "--faces", "ref,y,x,z", "--nominal", "100,80,90,90"], d)
    assert_one_line_refusal(rc, se, "--nominal")


@pytest.mark.parametrize("flags, name", [
    (["--faces", "ref,y,y,z"], "--faces"), (["--faces", "ref,,x,z"], "--faces"),
    (["--nominal", "90,90,90"], "--nominal"), (["--nominal", "90,90,90,100"], "--nominal"),
    (["--nominal", "90,90,180,0"], "--nominal"), (["--nominal", "90,90,nan,90"], "--nominal"),
    (["--latitude", "1000"], "--latitude"), (["--latitude", "nan"], "--latitude"),
    (["--reverse-log", "log.csv"], "--reverse-log"),
    (["--reverse-log", "copy.csv"], "--reverse-log"), (["--alpha", "1"], "--alpha"),
    (["--direction", "up"], "--direction"), (["--columns", "count=foo"], "count=foo"),
    (["--json", "log.csv"], "--json"), (["--plot", "log.csv"], "--plot"),
    (["--json", "o.json", "--plot", "o.json"], "--plot"),
])
def test_gonio_bad_flags_refused_in_one_line(gonio_log, flags, name):
    d, _, _ = gonio_log
    shutil.copy(d / "log.csv", d / "copy.csv")
    before = (d / "log.csv").read_bytes()
    args = ["gonio", "log.csv", *([] if flags[0] == "--faces" else ["--faces", "ref,y,x,z"]),
            *flags]
    rc, so, se = cli(args, d)
    assert_one_line_refusal(rc, se, name)
    assert (d / "log.csv").read_bytes() == before
    assert not (d / "o.json").exists()


def test_gonio_json_to_stdout_and_closed_pipe(gonio_log):
    d, _, _ = gonio_log
    rc, so, se = cli(["gonio", "log.csv", "--faces", "ref,y,x,z", "--json", "-", "-q"], d)
    assert rc == 0 and json.loads(so)["format"] == "axis-align/gonio"
    out = d / "piped.json"
    if out.exists():
        out.unlink()
    # ``| head -1`` (in this process; the shell's own pipe: tests/align/test_bad_inputs.py)
    rc, so, se = run_cli("gonio", "log.csv", "--faces", "ref,y,x,z", "--json", "piped.json",
                         cwd=d, stdout_lines=1)
    assert "Traceback" not in se and "BrokenPipe" not in se
    assert so.count("\n") == 1
    assert json.loads(out.read_text())["angles_deg"]


@pytest.mark.slow
def test_gonio_two_concurrent_runs_on_one_output_one_wins_one_refuses(gonio_log):
    d, _, _ = gonio_log
    out = d / "race.json"
    if out.exists():
        out.unlink()
    shutil.copy(d / "log.csv", d / "copy_for_race.csv")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    procs = [subprocess.Popen([sys.executable, "-m", "align", "gonio", name, "--faces",
                               "ref,y,x,z", "--json", "race.json", "-q"], cwd=d, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for name in ("log.csv", "copy_for_race.csv")]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    assert sorted(rc for rc, _ in results) == [0, 2], results
    loser = next(err for rc, err in results if rc == 2)
    assert "race.json" in loser and "Traceback" not in loser
    assert json.loads(out.read_text())["format"] == "axis-align/gonio"


def test_ascii_console_gets_ascii_symbols(gonio_log):
    d, _, _ = gonio_log
    # An ASCII console (in this process; PYTHONIOENCODING=ascii in a fresh one:
    # tests/align/test_bad_inputs.py)
    rc, out, se = run_cli("gonio", "log.csv", "--faces", "ref,y,x,z", cwd=d,
                          encoding="ascii")  # decoded as ASCII: raises on anything else
    assert rc == 0, se
    assert "+/-" in out and '"' in out


# =========================================================================== tilt / apply

@pytest.fixture(scope="module")
def readings(tumble, triad, cal_plain):
    d, _ = tumble
    rows, f = ui.readings_rows(triad)
    ui.write_csv(d / "read.csv", ["t", "ux", "uy", "uz"], rows)
    return d, rows, f


def _tilt_csv(d, name, cal="plain.json", *extra):
    out = d / (name + ".tilt.csv")
    if out.exists():
        out.unlink()
    rc, so, se = cli(["tilt", name, "--calibration", cal, "--out", out.name, "-q", *extra], d)
    return rc, (out.read_text() if out.exists() else None), se


def test_tilt_variants_identical_and_roll_pitch_near_truth(readings):
    d, rows, f = readings
    rc, plain, se = _tilt_csv(d, "read.csv")
    assert rc == 0, se
    ui.write_csv(d / "read_v.csv", ["T ", "Ux", "uy", "UZ"], rows, order=[0, 3, 2, 1],
                 sep=";", bom=True, eol="\r\n")
    rc, variant, se = _tilt_csv(d, "read_v.csv")
    assert rc == 0 and variant == plain
    out = np.loadtxt(plain.splitlines()[1:], delimiter=",")
    roll = np.degrees(np.arctan2(f[:, 1], f[:, 2]))
    pitch = np.degrees(np.arctan2(-f[:, 0], np.hypot(f[:, 1], f[:, 2])))
    # the triad's own frame differs from the generator's by its misalignment (< 3e-4 rad)
    assert np.abs(out[:, 1] - roll).max() < np.degrees(1e-3)
    assert np.abs(out[:, 2] - pitch).max() < np.degrees(1e-3)


def test_tilt_readings_without_time_get_no_invented_time(readings):
    d, rows, _ = readings
    ui.write_csv(d / "read_nt.csv", ["ux", "uy", "uz"], [r[1:] for r in rows])
    rc, out, se = _tilt_csv(d, "read_nt.csv")
    assert rc == 0, se
    lines = out.splitlines()
    assert lines[0] == "t,roll_deg,pitch_deg" and len(lines) == len(rows) + 1
    t = [ln.split(",")[0] for ln in lines[1:]]
    assert set(t) == {""}, t[:3]  # blank on every row: no time is made up


@pytest.mark.parametrize("bad_k", [float("nan"), 0.0])
def test_tilt_refuses_a_calibration_with_invalid_scale(readings, bad_k):
    d, _, _ = readings
    doc = json.loads((d / "plain.json").read_text())
    doc["model"]["k_v_per_g"][0] = bad_k
    (d / "badk.json").write_text(json.dumps(doc))
    rc, out, se = _tilt_csv(d, "read.csv", "badk.json")
    assert_one_line_refusal(rc, se, "badk.json")


def test_tilt_flags_readings_far_from_one_g(readings):
    d, _, _ = readings
    (d / "zero.csv").write_text("t,ux,uy,uz\n0,0,0,0\n0.1,0,0,0\n")
    rc, out, se = _tilt_csv(d, "zero.csv")
    # Roll and pitch are still written (the other readings of a longer file are tilts);
    # the readings that are not 1 g are named in a warning, exit 0.
    assert rc == 0, se
    assert "WARNING: 2 of 2 readings have |a| more than 0.1 g from 1 g" in se, se


@pytest.mark.parametrize("args, name", [
    (["hdr.csv", "--calibration", "plain.json"], "hdr.csv"),
    (["trunc.csv", "--calibration", "plain.json"], "trunc.csv:2"),
    (["read.csv", "--calibration", "notjson.json"], "notjson.json"),
    (["read.csv", "--calibration", "tumble.csv"], "tumble.csv"),
    (["read.csv", "--calibration", "missing.json"], "missing.json"),
    (["read.csv", "--calibration", "plain.json", "--units", "g"], "g"),
    (["read.csv", "--calibration", "plain.json", "--mu", "-1"], "--mu"),
    (["read.csv", "--calibration", "plain.json", "--out", "read.csv"], "--out"),
    (["read.csv", "--calibration", "plain.json", "--out", "plain.json"], "--out"),
    (["read.csv", "--calibration", "read.csv"], "read.csv"),
])
def test_tilt_bad_inputs_refused_in_one_line(readings, args, name):
    d, _, _ = readings
    (d / "hdr.csv").write_text("t,ux,uy,uz\n")
    (d / "trunc.csv").write_text("t,ux,uy,uz\n0,1,2\n")
    (d / "notjson.json").write_text("{not json")
    before = {f: (d / f).read_bytes() for f in ("read.csv", "plain.json")}
    rc, so, se = cli(["tilt", *args], d)
    assert_one_line_refusal(rc, se, name)
    assert before == {f: (d / f).read_bytes() for f in before}


# =========================================================================== run / apply

@pytest.fixture(scope="module")
def session_result(session_dir):
    d, tri = session_dir
    rc, so, se = cli(["run", d.name, "--json", "base.json", "--calibration",
                           "base_cal.json", "-q"], d.parent)
    assert rc == 0, se
    return json.loads((d.parent / "base.json").read_text()), d.parent / "base_cal.json"


def test_run_misalignment_against_the_generators_truth(session_dir, session_result):
    _, tri = session_dir
    doc, _ = session_result
    E = np.array(doc["misalignment_rad"])
    U = np.array(doc["misalignment_u_rad"])
    off = ~np.eye(3, dtype=bool)
    z = (E - tri.axes)[off] / U[off]
    assert doc["ok"] is True and doc["fused"] is True and not doc["errors"]
    assert np.all(np.abs(z) < 4.5), z


def test_run_bom_crlf_session_files_give_the_same_matrix(session_dir, session_result):
    d, _ = session_dir
    doc, _ = session_result
    s = copy_session(d, "bom")
    for f in ("session.toml", "platform.csv", "tumble.csv"):
        p = s / f
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes().replace(b"\n", b"\r\n"))
    rc, so, se = cli(["run", "bom", "--json", "bom.json", "-q"], s.parent)
    assert rc == 0, se
    other = json.loads((s.parent / "bom.json").read_text())
    assert other["misalignment_rad"] == doc["misalignment_rad"]
    assert other["misalignment_u_rad"] == doc["misalignment_u_rad"]


@pytest.mark.parametrize("variant", ["semicolon_reordered_caps", "tab_no_time"])
def test_run_platform_file_variants_give_the_same_matrix(session_dir, session_result,
                                                         variant):
    d, tri = session_dir
    doc, _ = session_result
    s = copy_session(d, f"pv_{variant}")
    rows = ui.platform_rows(tri, seed=4)
    if variant == "semicolon_reordered_caps":
        ui.write_csv(s / "platform.csv", ["POSE", "Ux", " uy ", "UZ", "T"], rows,
                     sep=";", order=[4, 3, 1, 0, 2])
    else:
        ui.write_csv(s / "platform.csv", ["pose", "ux", "uy", "uz"], [r[:4] for r in rows],
                     sep="\t")
    rc, so, se = cli(["run", s.name, "--json", f"pv_{variant}.json", "-q"], s.parent)
    assert rc == 0, se
    other = json.loads((s.parent / f"pv_{variant}.json").read_text())
    if variant == "tab_no_time":  # the time only serves drift terms; none is found here
        np.testing.assert_allclose(other["misalignment_rad"], doc["misalignment_rad"],
                                   atol=1e-9)
    else:
        assert other["misalignment_rad"] == doc["misalignment_rad"]


SESSION_FAULTS = {
    # name: (edit of session.toml text, text the one line must contain)
    "dotdot": (lambda t: t.replace('static = "platform.csv"', 'static = "../outside.csv"'),
               "outside the session folder"),
    "absolute": (lambda t: t.replace('static = "platform.csv"', 'static = "/etc/passwd"'),
                 "outside the session folder"),
    "symlink": (lambda t: t.replace('static = "platform.csv"', 'static = "link.csv"'),
                "outside the session folder"),
    "missing_file": (lambda t: t.replace('static = "platform.csv"', 'static = "nope.csv"'),
                     "nope.csv"),
    "unknown_key": (lambda t: t.replace("[platform]", "[platform]\nstatik = 1"), "statik"),
    "unknown_section": (lambda t: t + '\n[platfrom]\nstatic = "x"\n', "platfrom"),
    "bad_toml": (lambda t: t + "\n[[[\n", "TOML"),
    "bad_up": (lambda t: t.replace('up = "-Y"', 'up = "-Q"'), "Ydn"),
    "table_nan": (lambda t: t.replace("table_deg = 90.0", "table_deg = nan"), "L090"),
    "table_huge": (lambda t: t.replace("table_deg = 90.0", "table_deg = 1e9"), "L090"),
    "latitude": (lambda t: "latitude_deg = 1000\n" + t, "latitude_deg"),
    "tilt_huge": (lambda t: t.replace('static = "platform.csv"',
                                      'static = "platform.csv"\ntable_tilt_arcsec = [1e308, 0]'),
                  "table_tilt_arcsec"),
    "same_file_twice": (lambda t: t.replace('static = "platform.csv"', 'static = "tumble.csv"'),
                        "tumble.csv"),
    "scale_sign": (lambda t: t.replace('static = "tumble.csv"',
                                       'static = "tumble.csv"\nscale_sign = "x"'), "scale_sign"),
    "units": (lambda t: t.replace('static = "tumble.csv"',
                                  'static = "tumble.csv"\nunits = "furlong"'), "units"),
    "rate": (lambda t: t.replace('static = "tumble.csv"',
                                 'static = "tumble.csv"\nrate_hz = -1'), "rate_hz"),
    "empty": (lambda t: "", "session.toml"),
    "no_calibration_for_platform": (
        lambda t: t.replace('[calibration]\nstatic = "tumble.csv"\n', ""), "[calibration]"),
}


@pytest.mark.parametrize("case", list(SESSION_FAULTS))
def test_run_session_faults_refused_in_one_line_naming_the_key(session_dir, case):
    d, _ = session_dir
    s = copy_session(d, f"f_{case}")
    (s.parent / "outside.csv").write_bytes((s / "platform.csv").read_bytes())
    if not (s / "link.csv").exists():
        os.symlink("/etc/hostname", s / "link.csv")
    edit, must = SESSION_FAULTS[case]
    (s / "session.toml").write_text(edit((s / "session.toml").read_text()))
    rc, so, se = cli(["run", s.name, "--json", f"{case}.json"], s.parent)
    line = assert_one_line_refusal(rc, se, must)
    assert "session.toml" in line
    assert "root:" not in se + so  # nothing of /etc/passwd is echoed


def test_run_allow_outside_lifts_confinement_but_never_echoes_contents(session_dir,
                                                                       session_result):
    d, _ = session_dir
    doc, _ = session_result
    s = copy_session(d, "outside_ok")
    shutil.copy(s / "platform.csv", s.parent / "outside_ok_platform.csv")
    t = (s / "session.toml").read_text()
    (s / "session.toml").write_text(
        t.replace('static = "platform.csv"', 'static = "../outside_ok_platform.csv"'))
    rc, so, se = cli(["run", s.name, "--allow-outside", "--json", "oo.json", "-q"], s.parent)
    assert rc == 0, se
    assert json.loads((s.parent / "oo.json").read_text())["misalignment_rad"] == doc[
        "misalignment_rad"]
    (s / "session.toml").write_text(t.replace('static = "platform.csv"', 'static = "/etc/passwd"'))
    rc, so, se = cli(["run", s.name, "--allow-outside", "--json", "op.json", "-q"], s.parent)
    assert rc == 2
    written = (s.parent / "op.json").read_text()
    assert "root:" not in se + so + written and "/etc/passwd" in se


def test_run_failed_stage_exit_2_result_written_ok_false(session_dir):
    d, _ = session_dir
    s = copy_session(d, "broken_stage")
    p = s / "platform.csv"
    p.write_text(p.read_text() + "Ydn,abc,1,2,9999\n")
    rc, so, se = cli(["run", s.name, "--json", "broken.json", "-q"], s.parent)
    assert rc == 2 and "Traceback" not in se
    doc = json.loads((s.parent / "broken.json").read_text())
    assert doc["ok"] is False
    assert any("platform.csv:" in e["message"] and "abc" in e["message"]
               for e in doc["errors"]), doc["errors"]


def test_run_undeclared_pose_label_fails_the_stage_naming_it(session_dir):
    d, _ = session_dir
    s = copy_session(d, "undeclared")
    t = (s / "session.toml").read_text()
    (s / "session.toml").write_text(t.replace('Ydn = { up = "-Y" }', ""))
    rc, so, se = cli(["run", s.name, "--json", "und.json", "-q"], s.parent)
    assert rc == 2
    doc = json.loads((s.parent / "und.json").read_text())
    assert doc["ok"] is False and any("Ydn" in e["message"] for e in doc["errors"])


def test_run_declared_pose_absent_from_the_data_fails_the_stage_naming_it(session_dir):
    """The mirror case (noticed by the independent user, fixed after): an attitude declared in
    [platform.poses] whose pose is not in the platform file is a typo or a lost pose."""
    d, _ = session_dir
    s = copy_session(d, "absent")
    t = (s / "session.toml").read_text()
    assert 'Ydn = { up = "-Y" }' in t
    (s / "session.toml").write_text(t.replace('Ydn = { up = "-Y" }',
                                              'Ydn = { up = "-Y" }\nZdn = { up = "-Z" }'))
    rc, so, se = cli(["run", s.name, "--json", "abs.json", "-q"], s.parent)
    assert rc == 2
    doc = json.loads((s.parent / "abs.json").read_text())
    assert doc["ok"] is False and any("Zdn" in e["message"] for e in doc["errors"])


@pytest.mark.parametrize("flags", [["--json", "{s}/tumble.csv"], ["--report", "{s}/session.toml"],
                                   ["--calibration", "{s}/platform.csv"],
                                   ["--json", "x.out", "--report", "x.out"]])
def test_run_never_writes_over_inputs_even_with_force(session_dir, flags):
    d, _ = session_dir
    s = copy_session(d, "outs")
    before = {p.name: p.read_bytes() for p in s.iterdir()}
    args = [f.format(s=s.name) for f in flags]
    rc, so, se = cli(["run", s.name, *args, "--force"], s.parent)
    assert_one_line_refusal(rc, se, args[-2])
    assert before == {p.name: p.read_bytes() for p in s.iterdir()}


@pytest.mark.slow  # the demo, the report page and test_fusion find an undeclared roll too
def test_run_cameras_find_an_undeclared_roll_and_e_stays_true(tmp_path):
    """Cameras (two, each with its reversal view) + tumble + platform poses, camera A rolled
    by 30 arcsec and nobody told: the fusion loop names camera A's roll within its u, and E
    stays within 4.5 u of the generator's axes.  Without the platform poses nothing fixes
    the azimuths: the run says which angles are undetermined, exit 2."""
    tri = ui.make_triad(7, mis_rad=3e-4)
    d = tmp_path / "cams"
    toml = ui.image_session(d, tri, seed=7, roll_a_arcsec=30.0)
    rc, so, se = cli(["run", "cams", "--json", "cams.json", "-q"], tmp_path)
    assert rc == 0, se
    doc = json.loads((tmp_path / "cams.json").read_text())
    E, U = np.array(doc["misalignment_rad"]), np.array(doc["misalignment_u_rad"])
    off = ~np.eye(3, dtype=bool)
    assert np.all(np.abs((E - tri.axes)[off] / U[off]) < 4.5)
    rolls = [e for e in doc["effects"] if "camera_roll" in e["name"]]
    assert len(rolls) == 1 and "A" in rolls[0]["name"], doc["effects"]
    est = np.degrees(rolls[0]["estimate"]) * 3600
    u = np.degrees(rolls[0]["u"]) * 3600
    assert abs(est - 30.0) < 4.5 * u, (est, u)
    (d / "session.toml").write_text(toml.split("[platform]")[0])
    rc, so, se = cli(["run", "cams", "--json", "cams2.json", "-q"], tmp_path)
    assert rc == 2
    doc = json.loads((tmp_path / "cams2.json").read_text())
    assert doc["ok"] is False and doc["fused"] is False
    assert any("E_xY" in e["message"] and "E_yX" in e["message"] for e in doc["errors"])


def test_run_folder_with_spaces_and_umlauts_report_and_provenance(session_dir):
    """A session folder named like a real one; a failed stage is at the top of the report,
    and the JSON's provenance carries the true SHA-256 of every input."""
    import hashlib

    d, _ = session_dir
    s = copy_session(d, "Prüfung März 1")
    p = s / "platform.csv"
    p.write_text(p.read_text() + "Ydn,abc,1,2,9999\n")
    rc, so, se = cli(["run", s.name, "--json", "pm.json", "--report", "pm.html", "-q"], s.parent)
    assert rc == 2 and "Traceback" not in se
    doc = json.loads((s.parent / "pm.json").read_text())
    listed = doc["inputs"] if "inputs" in doc else doc["provenance"]["inputs"]
    inputs = {Path(i["path"]).name: i["sha256"] for i in listed}
    assert set(inputs) >= {"session.toml", "tumble.csv", "platform.csv"}
    for name, sha in inputs.items():
        assert sha == hashlib.sha256((s / name).read_bytes()).hexdigest()
    html = (s.parent / "pm.html").read_text(encoding="utf-8")
    body = html[html.find("<body"):]
    assert 0 <= body.find("platform.csv:") < body.find("<table"), "failure not at the top"


def test_run_image_without_a_mark_fails_its_stage_but_fuses_the_rest(tmp_path):
    tri = ui.make_triad(8, mis_rad=3e-4)
    d = tmp_path / "noimg"
    ui.image_session(d, tri, seed=8)
    noise = np.random.default_rng(0).normal(30000, 300, (480, 640))
    ui.write_image(d / "x_A.png", np.clip(noise, 0, 65535).astype(np.uint16))
    rc, so, se = cli(["run", "noimg", "--json", "noimg.json", "-q"], tmp_path)
    assert rc == 2
    doc = json.loads((tmp_path / "noimg.json").read_text())
    assert doc["ok"] is False and doc["fused"] is True
    assert any("x_A.png" in e["message"] and "no mark" in e["message"] for e in doc["errors"])
    E, U = np.array(doc["misalignment_rad"]), np.array(doc["misalignment_u_rad"])
    off = ~np.eye(3, dtype=bool)
    assert np.all(np.abs((E - tri.axes)[off] / U[off]) < 4.5)


@pytest.mark.slow
def test_run_batch_of_clean_camera_sessions_honest_u_and_no_false_effects(tmp_path):
    """Ten clean sessions (cameras + reversals + tumble + platform) as one batch into
    folders: every session ok, no fusion effect added, normalised E errors RMS 0.75-1.35
    (measured 1.14 over 60 angles)."""
    names, tris = [], {}
    for k in range(10):
        tri = ui.make_triad(200 + k, mis_rad=3e-4)
        ui.image_session(tmp_path / f"s{k}", tri, seed=200 + k)
        names.append(f"s{k}")
        tris[f"s{k}"] = tri
    rc, so, se = cli(["run", *names, "--json", "out", "--jobs", "2", "-q"], tmp_path)
    assert rc == 0, se
    z = []
    off = ~np.eye(3, dtype=bool)
    for n in names:
        doc = json.loads((tmp_path / "out" / f"{n}.json").read_text())
        assert doc["ok"] is True and doc["effects"] == [], (n, doc["effects"])
        E, U = np.array(doc["misalignment_rad"]), np.array(doc["misalignment_u_rad"])
        z += list((E - tris[n].axes)[off] / U[off])
    assert 0.75 < np.sqrt(np.mean(np.square(z))) < 1.35, z


def test_apply_variants_identical_and_near_truth(session_dir, session_result):
    d, _ = session_dir
    _, cal = session_result
    tri = ui.make_triad(3, mis_rad=3e-4)
    rows, f = ui.readings_rows(tri, n=40, seed=9)
    w = d.parent / "apply"
    w.mkdir(exist_ok=True)
    shutil.copy(cal, w / "cal.json")
    ui.write_csv(w / "r.csv", ["t", "ux", "uy", "uz"], rows)
    ui.write_csv(w / "rv.csv", ["Time", "Acc_X ", "acc_y", "ACC_Z"], rows, order=[0, 3, 2, 1],
                 sep=";", bom=True, eol="\r\n")
    outs = []
    for name in ("r.csv", "rv.csv"):
        o = w / f"o_{name}"
        if o.exists():
            o.unlink()
        rc, so, se = cli(["apply", "cal.json", name, "--out", o.name, "--tilt", "-q"], w)
        assert rc == 0, se
        outs.append(o.read_text())
    assert outs[0] == outs[1]
    a = np.loadtxt(outs[0].splitlines()[1:], delimiter=",")[:, 1:4]
    # 20 µg noise per axis and reading; the calibration adds < 5 µg
    assert np.abs(a - f).max() < 5 * 2.2e-5


@pytest.mark.parametrize("case", ["newer_version", "calibration_not_platform", "out_is_input",
                                  "out_exists", "header_only"])
def test_apply_bad_inputs_refused_in_one_line(session_dir, session_result, tumble, case):
    d, _ = session_dir
    _, cal = session_result
    w = d.parent / "apply_bad"
    w.mkdir(exist_ok=True)
    doc = json.loads(cal.read_text())
    (w / "cal.json").write_text(json.dumps(doc))
    doc["format_version"] = 99
    (w / "cal99.json").write_text(json.dumps(doc))
    shutil.copy(tumble[0] / "plain.json", w / "triad.json")
    ui.write_csv(w / "r.csv", ["t", "ux", "uy", "uz"], [[0.0, 0.0, 0.0, 1.0]])
    (w / "hdr.csv").write_text("t,ux,uy,uz\n")
    (w / "exists.csv").write_text("keep me")
    args, must = {
        "newer_version": (["cal99.json", "r.csv", "--out", "o.csv"], "99"),
        "calibration_not_platform": (["triad.json", "r.csv", "--out", "o.csv"], "triad.json"),
        "out_is_input": (["cal.json", "r.csv", "--out", "r.csv"], "--out"),
        "out_exists": (["cal.json", "r.csv", "--out", "exists.csv"], "exists.csv"),
        "header_only": (["cal.json", "hdr.csv", "--out", "o.csv"], "hdr.csv"),
    }[case]
    rc, so, se = cli(["apply", *args], w)
    assert_one_line_refusal(rc, se, must)
    assert (w / "exists.csv").read_text() == "keep me"
    assert not (w / "o.csv").exists()


def test_demo_force_never_replaces_the_users_own_folder(tmp_path):
    d = tmp_path / "mine"
    (d / "session").mkdir(parents=True)
    (d / "notes.txt").write_text("mine")
    (d / "session" / "important.csv").write_text("my data")
    rc, so, se = cli(["demo", "--out", "mine", "-q"], tmp_path)
    assert_one_line_refusal(rc, se, "mine")
    rc, so, se = cli(["demo", "--out", "mine", "--force", "-q"], tmp_path)
    assert_one_line_refusal(rc, se, "session")
    assert (d / "notes.txt").read_text() == "mine"
    assert (d / "session" / "important.csv").read_text() == "my data"
    assert sorted(p.name for p in d.rglob("*")) == ["important.csv", "notes.txt", "session"]


def test_every_command_has_version_and_help_without_traceback(tmp_path):
    rc, so, se = cli(["--version"], tmp_path)
    assert rc == 0 and re.search(r"\d+\.\d+", so + se)
    for cmd in ("marks", "calibrate", "gonio", "tilt", "apply", "run"):
        rc, so, se = cli([cmd, "--help"], tmp_path)
        assert rc == 0 and "usage" in so and "Traceback" not in se
