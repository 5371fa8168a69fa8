"""The contract, third round (issue 22), end to end through the CLI: write errors, an
unreachable scheduler, decompression bombs and bad camera models (class 7); valid images and
tables that were refused (class 8); orientation and units declared in files (class 3).

Each case: exit status 2 and one line naming the file / flag / key, never a traceback; or
the valid variant read to the same numbers as the plain file.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from align.cli import main
from axisbase.units import ARCSEC
from tests.conftest import imageless_session, mark_image
from tests.imaging.bad_images import png_bomb

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A seeded synthetic session without images (~1 s to run)."""
    from synth.session import SessionSpec

    return imageless_session(tmp_path_factory.mktemp("round3"), SessionSpec(seed=22))


def _one_line(stderr: str, *needles: str) -> str:
    assert "Traceback" not in stderr, stderr
    lines = [ln for ln in stderr.splitlines() if ln.startswith("align")]
    assert len(lines) == 1, stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def _cli(argv: list[str], stdout=subprocess.PIPE,
         timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "align", *argv], stdout=stdout,
                          stderr=subprocess.PIPE, text=True, env=ENV, timeout=timeout)


# ----------------------------------------------------------------------------- class 7

def _commands(session: Path, lot: Path, image: Path) -> dict[str, list[str]]:
    return {
        "gonio": ["gonio", str(session / "gonio.csv"), "--faces", "ref,y,x,z"],
        "calibrate": ["calibrate", str(session / "tumble.csv"), "--scale-sign", "-"],
        "run": ["run", str(session)],
        "lot": ["lot", str(lot)],
        "marks": ["marks", str(image)],
    }


@pytest.fixture(scope="module")
def lot_and_image(session, tmp_path_factory):
    root = tmp_path_factory.mktemp("lot")
    (root / "lot").mkdir()
    assert main(["run", str(session), "--json", str(root / "lot" / "a.json"), "-q"]) == 0
    import cv2

    cv2.imwrite(str(root / "mark.png"), mark_image(3.0, seed=5, with_crlb=False).image)
    return root / "lot", root / "mark.png"


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full on this system")
@pytest.mark.parametrize("cmd", ["gonio", "calibrate", "run", "lot", "marks"])
@pytest.mark.parametrize("json_out", [True, False], ids=["json-", "text"])
def test_full_disk_on_stdout_is_one_line_exit_2(session, lot_and_image, capsys, monkeypatch,
                                                cmd, json_out):
    """``> /dev/full`` (ENOSPC): the JSON or the result text cannot be written — one line
    naming standard output, exit 2 (before: a traceback, exit 1)."""
    argv = _commands(session, *lot_and_image)[cmd] + (["--json", "-"] if json_out else [])
    with open("/dev/full", "w") as full:
        monkeypatch.setattr(sys, "stdout", full)
        status = main(argv)
    assert status == 2
    _one_line(capsys.readouterr().err, "standard output", "No space left on device")


def test_a_full_disk_shell_redirect_end_to_end(session):
    """The same through a real process (what the user types: ``align gonio ... > /dev/full``)."""
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full on this system")
    with open("/dev/full", "w") as full:
        r = _cli(_commands(session, Path("."), Path("."))["gonio"], stdout=full)
    assert r.returncode == 2, r.stderr
    _one_line(r.stderr, "standard output", "No space left on device")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full on this system")
def test_full_disk_as_the_json_file_is_one_line_with_the_path(session, capsys):
    assert main(["calibrate", str(session / "tumble.csv"), "--scale-sign", "-",
                 "--json", "/dev/full", "-q"]) == 2
    cap = capsys.readouterr()
    _one_line(cap.err, "/dev/full", "No space left on device")


@pytest.mark.parametrize("errno_name", ["ENOSPC", "EACCES", "EIO"])
def test_a_refused_file_write_is_one_line_with_the_path(session, tmp_path, capsys,
                                                        monkeypatch, errno_name):
    """The disk fills (or permission goes, or the device fails) while the result is being
    written: one line with the path, exit 2, nothing left behind (before: a traceback)."""
    import errno

    def refuse(fd):
        raise OSError(getattr(errno, errno_name), os.strerror(getattr(errno, errno_name)))

    monkeypatch.setattr(os, "fsync", refuse)
    out = tmp_path / "g.json"
    assert main(["gonio", str(session / "gonio.csv"), "--faces", "ref,y,x,z", "--json",
                 str(out), "-q"]) == 2
    _one_line(capsys.readouterr().err, str(out), os.strerror(getattr(errno, errno_name)))
    assert list(tmp_path.iterdir()) == []


class _GonePipe:
    """A standard output whose reader has left (every write: EPIPE)."""

    encoding = "utf-8"

    def write(self, text):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        raise BrokenPipeError(32, "Broken pipe")

    @property
    def buffer(self):
        return self

    def fileno(self):
        raise OSError("no file descriptor")


def test_json_into_a_closed_pipe_is_one_line(session, capsys, monkeypatch):
    """``--json - | head -c 1`` with a JSON larger than the pipe: the JSON is incomplete —
    one line, exit 2 (a closed pipe for the text messages stays quiet)."""
    monkeypatch.setattr(sys, "stdout", _GonePipe())
    status = main(_commands(session, Path("."), Path("."))["calibrate"] + ["--json", "-"])
    assert status == 2
    _one_line(capsys.readouterr().err, "standard output", "closed the pipe")


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "nonsense", "http://127.0.0.1:8786",
                                     "tcp://127.0.0.1:notaport"])
def test_unreachable_scheduler_fails_fast_once(session, tmp_path, capsys, address):
    """Before: the right error after 20 s, then 40 s more and a traceback from the client's
    finaliser. Now: one line within a few seconds, nothing computed."""
    t0 = time.monotonic()
    other = tmp_path / "s2"
    import shutil

    shutil.copytree(session, other)
    status = main(["run", str(session), str(other), "--json", str(tmp_path / "out"),
                   "--scheduler", address, "-q"])
    dt = time.monotonic() - t0
    assert status == 2
    _one_line(capsys.readouterr().err, "--scheduler", address)
    assert dt < 5.0, dt
    assert not any((tmp_path / "out").glob("*.json"))


def test_decompression_bomb_refused_from_its_header(tmp_path, capsys):
    """A 390 kB PNG declaring 20000 x 20000 px: refused at once, by name (before: minutes at
    5 GB). Raising the budget is the user's decision (--max-pixels)."""
    bomb = png_bomb(tmp_path / "bomb.png")
    assert bomb.stat().st_size < 700_000
    t0 = time.monotonic()
    status = main(["marks", str(bomb), "--json", str(tmp_path / "m.json")])
    assert time.monotonic() - t0 < 3.0
    assert status == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "20000x20000 px" in err and "--max-pixels" in err
    doc = json.loads((tmp_path / "m.json").read_text())
    assert doc["marks"][0]["found"] is False and "pixel budget" in doc["marks"][0]["error"]


def test_pixel_budget_is_settable(tmp_path, capsys):
    import cv2

    p = tmp_path / "m.png"
    cv2.imwrite(str(p), mark_image(3.0, seed=6, with_crlb=False).image)
    assert main(["marks", str(p), "--max-pixels", "1000", "-q"]) == 2
    assert "pixel budget of 0.001 MP" in capsys.readouterr().err
    assert os.environ.get("ALIGN_MAX_PIXELS") is None  # the flag did not outlive the call
    assert main(["marks", str(p), "-q"]) == 0


_CAM = {"camera_matrix": [[1000, 0, 400], [0, 1000, 300], [0, 0, 1]],
        "dist_coeffs": [0, 0, 0, 0, 0], "image_size": [800, 600],
        "format": "axis-align/camera", "format_version": 3}


@pytest.mark.parametrize("key,value,needle", [
    ("camera_matrix", [[0, 0, 400], [0, 0, 300], [0, 0, 1]], "focal lengths"),
    ("camera_matrix", [[-1000, 0, 400], [0, 1000, 300], [0, 0, 1]], "focal lengths"),
    ("camera_matrix", [[1000, 0, 400], [0, 1000, None], [0, 0, 1]], "non-finite"),
    ("camera_matrix", [1000, 1000, 400], "shape"),
    ("camera_matrix", [[1000, 0, 4000], [0, 1000, 300], [0, 0, 1]], "principal point"),
    ("camera_matrix", [[1000, 0, 400], [0, 1000, 300], [0, 0, 0]], "camera_matrix"),
    ("dist_coeffs", [0, 0, 0], "dist_coeffs"),
    ("dist_coeffs", "none", "dist_coeffs"),
    ("image_size", [800], "image_size"),
    ("image_size", [800.5, 600], "image_size"),
    ("image_size", [0, 600], "image_size"),
])
def test_camera_model_validated_like_any_input(tmp_path, capsys, key, value, needle):
    """Before: focal length 0 was an 'internal error', exit 1; others passed silently."""
    import cv2

    img = tmp_path / "m.png"
    cv2.imwrite(str(img), mark_image(3.0, seed=7, size=(800, 600), with_crlb=False).image)
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({**_CAM, key: value}))
    assert main(["marks", str(img), "--camera", str(cam), "-q"]) == 2
    line = _one_line(capsys.readouterr().err, str(cam), needle)
    assert key in line


def test_a_sound_camera_model_is_accepted(tmp_path):
    import cv2

    img = tmp_path / "m.png"
    cv2.imwrite(str(img), mark_image(3.0, seed=7, size=(800, 600), with_crlb=False).image)
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps(_CAM))
    assert main(["marks", str(img), "--camera", str(cam), "-q"]) == 0


# ----------------------------------------------------------------------------- class 8, 3

@pytest.fixture(scope="module")
def mark16(tmp_path_factory):
    """A 16-bit mark image at +3° (seeded) and its angle read from a plain PNG."""
    import cv2

    root = tmp_path_factory.mktemp("images")
    img = mark_image(3.0, seed=8, with_crlb=False).image
    assert img.dtype == np.uint16
    cv2.imwrite(str(root / "plain.png"), img)
    return root, img, _angles(root / "plain.png")


def _angles(path: Path, *extra: str) -> tuple[list[float], list[float], dict]:
    out = path.with_suffix(".json")
    out.unlink(missing_ok=True)
    assert main(["marks", str(path), "--json", str(out), "-q", *extra]) == 0
    doc = json.loads(out.read_text())
    marks = [m for m in doc["marks"] if m["found"]]
    return [m["angle_deg"] for m in marks], [m["angle_u_deg"] for m in marks], doc


def test_planar_rgb_tiff_is_one_colour_image(mark16):
    """Before: 'image is only 480x3 px'. Three equal planes: the gray image is the plain one."""
    import tifffile

    root, img, (a0, _, _) = mark16
    p = root / "planar.tif"
    tifffile.imwrite(p, np.stack([img] * 3), planarconfig="separate", photometric="rgb")
    a, _, _ = _angles(p)
    assert a == pytest.approx(a0, abs=1e-9)


def test_signed_16_bit_tiff_is_offset_and_said(mark16):
    """Before: 'no mark found' (negative DN). Offset by +32768: the same angle, and the
    JSON says what was done."""
    import tifffile

    root, img, (a0, _, _) = mark16
    p = root / "signed.tif"
    tifffile.imwrite(p, (img.astype(np.int32) - 32768).astype(np.int16))
    a, _, doc = _angles(p)
    assert a == pytest.approx(a0, abs=1e-9)
    assert any("offset by +32768" in n for n in doc["marks"][0]["notes"])
    assert any("offset by +32768" in w for w in doc["warnings"])


@pytest.mark.parametrize("code,stored", [
    (6, lambda a: np.rot90(a, 1)),       # shown turned 90° clockwise
    (8, lambda a: np.rot90(a, -1)),      # shown turned 90° counter-clockwise
    (3, lambda a: a[::-1, ::-1]),        # turned 180°
    (2, lambda a: a[:, ::-1]),           # mirrored left-right
    (4, lambda a: a[::-1, :]),           # mirrored top-bottom
    (5, lambda a: a.T),                  # transposed
    (7, lambda a: a[::-1, ::-1].T),      # transversed (about the anti-diagonal)
])
def test_tiff_orientation_tag_is_applied_and_said(mark16, code, stored):
    """The stored pixels turned/mirrored and the Orientation tag saying how to show them:
    the angle is the plain image's (before: +89.93° or the mirrored angle, no warning)."""
    import tifffile

    root, img, (a0, _, _) = mark16
    p = root / f"orient{code}.tif"
    tifffile.imwrite(p, np.ascontiguousarray(stored(img)), extratags=[(274, "H", 1, code, True)])
    a, _, doc = _angles(p)
    assert a == pytest.approx(a0, abs=1e-9)
    assert any(f"orientation tag {code} applied" in n for n in doc["marks"][0]["notes"])


def test_jpeg_exif_orientation_is_applied(mark16):
    """A JPEG whose EXIF says 'turn 90° clockwise to show': the angle of the shown image
    (lossy: within the JPEG's own scatter, 3 u), and said."""
    from PIL import Image

    root, img, _ = mark16
    gray8 = (img / 257).round().astype(np.uint8)
    Image.fromarray(gray8).save(root / "plain.jpg", quality=100)
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(np.ascontiguousarray(np.rot90(gray8, 1))).save(
        root / "turned.jpg", quality=100, exif=exif)
    (a0, u0, _), (a, u, doc) = _angles(root / "plain.jpg"), _angles(root / "turned.jpg")
    assert abs(a[0] - a0[0]) < 3 * np.hypot(u[0], u0[0]), (a, a0, u)
    assert "orientation tag 6 applied" in doc["marks"][0]["notes"][0]


def test_plus_signed_counts_are_read(session, tmp_path, capsys):
    """A counter log with every count written '+191041': before 'pyarrow refused it, no line
    found'; now the same angles as the plain log."""
    lines = (session / "gonio.csv").read_text().splitlines()
    plus = [lines[0]] + ["+" + ln for ln in lines[1:]]
    p = tmp_path / "plus.csv"
    p.write_text("\n".join(plus) + "\n")
    res = []
    for f in (session / "gonio.csv", p):
        out = tmp_path / f"{f.stem}.json"
        assert main(["gonio", str(f), "--faces", "ref,y,x,z", "--json", str(out), "-q"]) == 0
        res.append(json.loads(out.read_text()))
    assert res[0]["angles_deg"] == res[1]["angles_deg"]
    assert res[0]["angles_u_arcsec"] == res[1]["angles_u_arcsec"]


def test_npz_pose_variable_is_used(session, tmp_path):
    """An .npz with u, t and pose: the poses are the labelled ones, as from the CSV
    (before: 'pose' silently ignored, poses found from the time series instead)."""
    import csv

    rows = list(csv.reader((session / "tumble.csv").open()))
    head, rows = rows[0], rows[1:]
    assert head[:4] == ["pose", "ux", "uy", "uz"]
    u = np.array([[float(x) for x in r[1:4]] for r in rows])
    npz = tmp_path / "tumble.npz"
    np.savez(npz, u=u, t=np.array([float(r[4]) for r in rows]), pose=np.array([r[0] for r in rows]))
    docs = []
    for f in (session / "tumble.csv", npz):
        out = tmp_path / f"{f.name}.json"
        assert main(["calibrate", str(f), "--scale-sign", "-", "--json", str(out), "-q"]) == 0
        docs.append(json.loads(out.read_text()))
    assert [p["pose"] for p in docs[1]["poses"]] == [p["pose"] for p in docs[0]["poses"]]
    assert docs[0]["scale_factors_v_per_g"] == pytest.approx(docs[1]["scale_factors_v_per_g"],
                                                             rel=1e-12)


def _rewrite(src: Path, dst: Path, header: list[str], row) -> Path:
    lines = src.read_text().splitlines()
    dst.write_text(",".join(header) + "\n"
                   + "\n".join(",".join(row(ln.split(","))) for ln in lines[1:]) + "\n")
    return dst


def _cal(path: Path, tmp_path: Path, capsys) -> tuple[dict, str]:
    out = tmp_path / f"{path.name}.json"
    assert main(["calibrate", str(path), "--scale-sign", "-", "--json", str(out)]) == 0
    return json.loads(out.read_text()), capsys.readouterr().err


@pytest.mark.parametrize("unit,factor", [("ms", 1e3), ("us", 1e6), ("min", 1 / 60)])
def test_time_unit_in_the_header_is_converted(session, tmp_path, capsys, unit, factor):
    """``t [ms]``: before, the unit was ignored (a drift 1000x too small); now the times are
    seconds inside and the result is the one from the file in seconds."""
    src = session / "tumble.csv"
    assert src.read_text().split("\n", 1)[0] == "pose,ux,uy,uz,t"
    scaled = _rewrite(src, tmp_path / f"t_{unit}.csv", ["pose", "ux", "uy", "uz", f"t [{unit}]"],
                      lambda r: [*r[:4], repr(float(r[4]) * factor)])
    from align.calibration.static import STATIC
    from axisbase.table import read_table

    t_s, t_read = read_table(src, STATIC)["t"], read_table(scaled, STATIC)["t"]
    assert np.allclose(t_read, t_s, rtol=1e-12, atol=1e-9)  # before: factor x too large
    (a, _), (b, err) = _cal(src, tmp_path, capsys), _cal(scaled, tmp_path, capsys)
    assert "implausible" not in err
    for key in ("scale_factors_v_per_g", "bias_g", "beta_rad"):
        assert b[key] == pytest.approx(a[key], rel=1e-9, abs=1e-15), key


def test_counter_log_time_in_ms_gives_the_same_angles(session, tmp_path):
    src = session / "gonio.csv"
    assert src.read_text().split("\n", 1)[0] == "count,counter,ref,t"
    ms = _rewrite(src, tmp_path / "g_ms.csv", ["count", "counter", "ref", "t [ms]"],
                  lambda r: [*r[:3], repr(float(r[3]) * 1e3)])
    res = []
    for f in (src, ms):
        out = tmp_path / f"{f.name}.json"
        assert main(["gonio", str(f), "--faces", "ref,y,x,z", "--json", str(out), "-q"]) == 0
        res.append(json.loads(out.read_text()))
    assert res[1]["angles_deg"] == pytest.approx(res[0]["angles_deg"], abs=1e-12)
    assert res[1]["angles_u_arcsec"] == pytest.approx(res[0]["angles_u_arcsec"], rel=1e-6)


def test_unknown_time_unit_is_refused_by_name(session, tmp_path, capsys):
    bad = _rewrite(session / "tumble.csv", tmp_path / "t_fortnight.csv",
                   ["pose", "ux", "uy", "uz", "t [fortnights]"], lambda r: r)
    assert main(["calibrate", str(bad), "--scale-sign", "-", "-q"]) == 2
    _one_line(capsys.readouterr().err, str(bad), "t: time unit 'fortnights' not known")


def test_value_units_mg_and_g_agree(session, tmp_path, capsys):
    """The same readings in g and in mg (declared): the same calibration, in g/g (before:
    'unit mg not known')."""
    src = session / "tumble.csv"
    in_g = _rewrite(src, tmp_path / "u_g.csv", ["pose", "ux [g]", "uy [g]", "uz [g]", "t"],
                    lambda r: [r[0], *(repr(float(v) / -2.4) for v in r[1:4]), r[4]])
    in_mg = _rewrite(src, tmp_path / "u_mg.csv", ["pose", "ux [mg]", "uy [mg]", "uz [mg]", "t"],
                     lambda r: [r[0], *(repr(float(v) / -2.4e-3) for v in r[1:4]), r[4]])
    (a, _), (b, _) = _cal(in_g, tmp_path, capsys), _cal(in_mg, tmp_path, capsys)
    assert a["scale_factor_unit"] == b["scale_factor_unit"]
    assert b["scale_factors_v_per_g"] == pytest.approx(a["scale_factors_v_per_g"], rel=1e-9)
    assert b["bias_g"] == pytest.approx(a["bias_g"], rel=1e-9, abs=1e-15)


def test_times_in_ms_under_a_plain_t_are_a_warning_naming_ms(session, tmp_path, capsys):
    """A 20 Hz recording whose times are ms under a plain ``t`` (0.02 Hz as read): a warning
    that names ms and the header to write."""
    bad = _rewrite(session / "tumble.csv", tmp_path / "t_plain_ms.csv",
                   ["pose", "ux", "uy", "uz", "t"],
                   lambda r: [*r[:4], repr(float(r[4]) * 1e3)])
    _, err = _cal(bad, tmp_path, capsys)
    assert "implausible" in err and "t [ms]" in err


# ----------------------------------------------------------------------------- class 1

def _copy(session: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(session, dst)
    return dst


def _resume(folder: Path, out: Path, *extra: str) -> int:
    return main(["run", str(folder), "--json", str(out), "-q", "--resume", *extra])


def test_resume_reuses_only_a_trusted_result(session, tmp_path, capsys):
    """Same inputs, folder, version and settings, ok: reused, the file untouched."""
    s = _copy(session, tmp_path / "u1")
    out = tmp_path / "u1.json"
    assert main(["run", str(s), "--json", str(out), "-q"]) == 0
    before = out.read_bytes()
    capsys.readouterr()
    # without -q: the skip is news, not a warning (-q prints only warnings and errors)
    assert main(["run", str(s), "--json", str(out), "--resume"]) == 0
    assert "trusted, skipped" in capsys.readouterr().out
    assert out.read_bytes() == before


@pytest.mark.parametrize("spoil,reason", [
    (lambda out, s: out.write_text(out.read_text()[:500]), "unreadable"),
    (lambda out, s: out.write_text(out.read_text().replace('"ok": true', '"ok": false', 1)),
     "was not ok"),
    (lambda out, s: (s / "session.toml").write_text((s / "session.toml").read_text()
                                                    + "\n# edited\n"), "changed since"),
    (lambda out, s: out.write_text(out.read_text().replace('"tool_version": "',
                                                           '"tool_version": "0.0.0-', 1)),
     "made by version"),
], ids=["truncated", "not-ok", "input-changed", "other-version"])
def test_resume_redoes_an_untrusted_result_and_says_why(session, tmp_path, capsys, spoil,
                                                        reason):
    """Before: reused by its name (exit 0 over a not-ok result), or 'exists' for a truncated
    one. Now: redone, replacing it, with the reason on stderr."""
    s = _copy(session, tmp_path / "u1")
    out = tmp_path / "u1.json"
    assert main(["run", str(s), "--json", str(out), "-q"]) == 0
    spoil(out, s)
    capsys.readouterr()
    assert _resume(s, out) == 0
    err = capsys.readouterr().err
    assert "redone" in err and reason in err, err
    doc = json.loads(out.read_text())
    assert doc["ok"] is True
    from axisbase.provenance import sha256_file

    assert all(sha256_file(r["path"]) == r["sha256"] for r in doc["inputs"])


def test_resume_with_another_alpha_is_redone(session, tmp_path, capsys):
    s = _copy(session, tmp_path / "u1")
    out = tmp_path / "u1.json"
    assert main(["run", str(s), "--json", str(out), "-q"]) == 0
    assert _resume(s, out, "--alpha", "0.01") == 0
    assert "alpha" in capsys.readouterr().err
    assert json.loads(out.read_text())["settings"]["alpha"] == 0.01


def test_resume_never_takes_another_session_folders_result(session, tmp_path, capsys):
    """Two lots each with a session folder 'unit7', one output folder: before, the second
    batch said '2 of 2 sessions done' and kept the other unit's result, exit 0."""
    a = _copy(session, tmp_path / "lotA" / "unit7")
    b = _copy(session, tmp_path / "lotB" / "unit7")
    c = _copy(session, tmp_path / "lotB" / "unit8")
    out = tmp_path / "results"
    assert main(["run", str(a), str(_copy(session, tmp_path / "lotA" / "unit8")), "--json",
                 str(out), "-q"]) == 0
    before = (out / "unit7.json").read_bytes()
    capsys.readouterr()
    assert main(["run", str(b), str(c), "--json", str(out), "-q", "--resume"]) == 2
    cap = capsys.readouterr()
    assert "another session folder" in cap.out + cap.err
    assert (out / "unit7.json").read_bytes() == before


def test_a_session_named_cal_cannot_collide_with_a_calibration(session, tmp_path, capsys):
    """'u2' and 'u2.cal' with --json D --calibration D: both would write D/u2.cal.json
    (before: one session's output lost). Refused before computing."""
    u2 = _copy(session, tmp_path / "u2")
    u2cal = _copy(session, tmp_path / "u2.cal")
    d = tmp_path / "D"
    assert main(["run", str(u2), str(u2cal), "--json", str(d), "--calibration", str(d),
                 "-q"]) == 2
    _one_line(capsys.readouterr().err, "u2.cal.json", "--calibration", "--json")
    assert not list(d.glob("*.json"))


def test_lot_tells_results_from_calibrations_by_format(session, tmp_path, capsys):
    """A session folder named 'u2.cal' has the result u2.cal.json: before, 'align lot'
    dropped it as a calibration by its name; a platform calibration beside it is left out
    by its format field whatever its name."""
    d = tmp_path / "D"
    u2cal = _copy(session, tmp_path / "u2.cal")
    assert main(["run", str(u2cal), "--json", str(d / "u2.cal.json"), "--calibration",
                 str(d / "platform-u2.json"), "-q"]) == 0
    from align.lot.read import result_files

    assert [p.name for p in result_files([d])] == ["u2.cal.json"]


def test_json_folder_with_trailing_slash(session, tmp_path, capsys):
    """``--json out/`` for one session: a folder holding <session>.json (before: a file named
    'out'); for a command writing one file it is refused by name."""
    s = _copy(session, tmp_path / "u1")
    assert main(["run", str(s), "--json", f"{tmp_path / 'out'}/", "-q"]) == 0
    assert (tmp_path / "out" / "u1.json").is_file()
    assert main(["gonio", str(session / "gonio.csv"), "--faces", "ref,y,x,z", "--json",
                 f"{tmp_path / 'g'}/", "-q"]) == 2
    _one_line(capsys.readouterr().err, "--json", "ends with '/'")


# ----------------------------------------------------------------------------- class 6

@pytest.fixture(scope="module")
def result_doc(session, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("res") / "r.json"
    assert main(["run", str(session), "--json", str(out), "-q"]) == 0
    return json.loads(out.read_text())


def _edit_arcsec(d):
    d["misalignment_arcsec"][0][1] += 1.0


def _zero_u(d):
    d["misalignment_u_rad"][1][2] = 0.0
    d["misalignment_u_arcsec"][1][2] = 0.0


def _failed_but_ok(d):
    d["errors"] = [{"stage": "goniometer", "message": "no revolution found"}]


def _e57(d):
    d["misalignment_rad"][2][0] = 1.0
    d["misalignment_arcsec"][2][0] = 1.0 / (np.pi / 180 / 3600)


@pytest.mark.parametrize("edit,needle", [
    (_edit_arcsec, "disagree"), (_zero_u, "must be > 0"),
    (_failed_but_ok, "'ok' is true but stage goniometer failed"), (_e57, "beyond 5°"),
], ids=["units-disagree", "zero-u", "ok-with-failed-stage", "E-57deg"])
def test_lot_refuses_a_result_that_cannot_be_right(result_doc, tmp_path, capsys, edit, needle):
    """Before: each was taken into the lot's statistics. Now the file is 'not read' with the
    reason, and the lot says so (exit 2: a file was not read)."""
    d = json.loads(json.dumps(result_doc))
    edit(d)
    folder = tmp_path / "lot"
    folder.mkdir()
    (folder / "good.json").write_text(json.dumps(result_doc))
    (folder / "bad.json").write_text(json.dumps(d))
    out = tmp_path / "lot.json"
    main(["lot", str(folder), "--json", str(out), "-q"])
    lot = json.loads(out.read_text())
    assert [r["file"] for r in lot["rejected"]] == [str(folder / "bad.json")]
    assert needle in lot["rejected"][0]["reason"]
    assert "Traceback" not in capsys.readouterr().err


def test_lot_serials_are_trimmed_and_case_folded_with_a_warning(result_doc, tmp_path, capsys):
    """'SN-4' and 'SN-4 ' (and 'sn-4'): before, two units; now one, counted once, and a
    warning names the spellings."""
    folder = tmp_path / "lot"
    folder.mkdir()
    for k, serial in enumerate(["SN-4", "SN-4 ", "sn-4", "SN-5"]):
        d = json.loads(json.dumps(result_doc))
        d["metadata"] = {**(d.get("metadata") or {}), "serial": serial}
        d["session"] = f"s{k}"
        (folder / f"s{k}.json").write_text(json.dumps(d))
    out = tmp_path / "lot.json"
    main(["lot", str(folder), "--json", str(out), "-q"])
    lot = json.loads(out.read_text())
    assert lot["n_in_statistics"] == 2
    spelled = [w for w in lot["warnings"] if "written 3 ways" in w]
    assert len(spelled) == 1 and "'SN-4 '" in spelled[0] and "'sn-4'" in spelled[0]



def test_goniometer_time_unit_key_reads_a_microsecond_log(session, tmp_path):
    """``[goniometer] time_unit = "us"`` with the counter log's plain 't' in µs: the session's
    goniometer stage gives the angles and u of the log in seconds (``align gonio``); the same
    key against a header that says [ms] fails the stage in one line naming the file, its
    header line and the key."""
    from align.session import load_session, run_session

    s = tmp_path / "us"
    s.mkdir()
    toml = (session / "session.toml").read_text()
    gonio = toml[toml.index("[goniometer]"):toml.index("[platform]")]
    (s / "session.toml").write_text("latitude_deg = 50.45\n\n" + gonio.replace(
        'direction = "ccw"', 'direction = "ccw"\ntime_unit = "us"', 1))
    _rewrite(session / "gonio.csv", s / "gonio.csv", ["count", "counter", "ref", "t"],
             lambda r: [*r[:3], repr(float(r[3]) * 1e6)])
    out = tmp_path / "s.json"
    assert main(["gonio", str(session / "gonio.csv"), "--faces", "ref,y,x,z", "--latitude",
                 "50.45", "--json", str(out), "-q"]) == 0
    a = json.loads(out.read_text())
    g = run_session(load_session(s)).gonio.angles
    u = np.array(a["angles_u_arcsec"])
    assert np.all(np.abs(np.rad2deg(g.angles_rad) - a["angles_deg"]) * 3600 <= 1e-6 * u)
    assert np.allclose(g.u_rad / ARCSEC, u, rtol=1e-6, atol=0)
    _rewrite(session / "gonio.csv", s / "gonio.csv", ["count", "counter", "ref", "t [ms]"],
             lambda r: [*r[:3], repr(float(r[3]) * 1e3)])
    res = run_session(load_session(s))
    assert res.gonio is None
    said = [e.message for e in res.errors if e.stage == "goniometer"]
    assert len(said) == 1 and "gonio.csv:1: t: the header says [ms]" in said[0], said
    assert "time_unit" in said[0] and "\n" not in said[0]
