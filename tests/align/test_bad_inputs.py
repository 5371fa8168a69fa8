"""The contract with files and the shell, tried as a new user would (issue 10).

Fault files are built here from the formats README.md describes (``pose,ux,uy,uz[,t][,temp]``,
``ux,uy,uz[,t][,temp]``, ``count,counter,ref[,t]``, ``session.toml``), starting from a seeded
synthetic session, and run through the CLI end to end. Classes:

* VALID variants (BOM, CRLF, header case, reordered columns, spaces, delimiters, units in the
  header, aliases, --columns, comments, blank lines): numerically the same result as the plain
  file, for calibrate, gonio, tilt, apply and run;
* MALFORMED tables: exit 2, one line naming the file (and line/column), never a traceback;
* FLAGS with values out of range, non-finite or duplicated: exit 2, one line naming the flag;
* SESSION keys likewise, and confinement to the session folder;
* OUTPUTS never lost; EXIT status and warnings; PROVENANCE, formats and schemas; CLI
  conventions.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from align.cli import build_parser, main
from tests.conftest import strip_images

ROOT = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module")
def base(session21, tmp_path_factory):
    """A seeded synthetic session (seed 21: ``full`` a copy of it, ``plain`` without images),
    its result and platform calibration."""
    root = tmp_path_factory.mktemp("contract")
    shutil.copytree(session21, root / "full")
    s = strip_images(root / "full", root / "plain")
    # The readings for tilt/apply: the platform file without its pose labels.
    rows = (s / "platform.csv").read_text().splitlines()
    (root / "readings.csv").write_text(
        "\n".join(",".join(r.split(",")[1:]) for r in rows) + "\n")
    out = root / "outputs"
    out.mkdir()
    assert main(["run", str(s), "--json", str(out / "result.json"), "--calibration",
                 str(out / "pc.json"), "-q"]) == 0
    assert main(["calibrate", str(s / "tumble.csv"), "--scale-sign", "-", "--json",
                 str(out / "cal.json"), "-q"]) == 0
    return root


def _err_line(capsys, *needles: str) -> str:
    """The one error line of a refused command (no traceback), containing ``needles``."""
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("align ")]
    assert len(lines) == 1, cap.err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def _json(path: Path) -> dict:
    def no_constant(name: str):
        raise AssertionError(f"{path}: non-standard JSON token {name}")

    return json.loads(Path(path).read_text(), parse_constant=no_constant)


# ----------------------------------------------------------------------------- variants

def _split(text: str) -> tuple[list[str], list[list[str]]]:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return lines[0].split(","), [ln.split(",") for ln in lines[1:]]


def _join(header: list[str], rows: list[list[str]], sep: str = ",", eol: str = "\n") -> str:
    return eol.join(sep.join(r) for r in [header, *rows]) + eol


ALIASES = {"pose": "Pose_ID", "ux": "acc_x", "uy": "acc_y", "uz": "acc_z", "t": "Time",
           "count": "Counts", "counter": "Counter_ID", "ref": "Reference"}
UNITS = {"ux": "V", "uy": "V", "uz": "V", "t": "s"}


def variant(text: str, kind: str) -> tuple[str, list[str]]:
    """The same table saved another way; returns the text and the extra CLI arguments."""
    head, rows = _split(text)
    if kind == "plain":
        return _join(head, rows), []
    if kind == "bom":
        return "\ufeff" + _join(head, rows), []
    if kind == "crlf":
        return _join(head, rows, eol="\r\n"), []
    if kind == "bom_crlf":
        return "\ufeff" + _join(head, rows, eol="\r\n"), []
    if kind == "upper":
        return _join([h.upper() for h in head], rows), []
    if kind == "spaces":
        return _join([f" {h} " for h in head], [[f" {v}" for v in r] for r in rows]), []
    if kind == "reordered":
        order = list(range(len(head)))[::-1]
        return _join([head[i] for i in order], [[r[i] for i in order] for r in rows]), []
    if kind == "semicolon":
        return _join(head, rows, sep=";"), []
    if kind == "tab":
        return _join(head, rows, sep="\t"), []
    if kind == "units":
        return _join([f"{h} [{UNITS[h]}]" if h in UNITS else h for h in head], rows), []
    if kind == "aliases":
        return _join([ALIASES.get(h, h) for h in head], rows), []
    if kind == "columns":
        new = [f"col{i}" for i in range(len(head))]
        return _join(new, rows), ["--columns", ",".join(f"{h}=col{i}"
                                                        for i, h in enumerate(head))]
    if kind == "comments":
        return "# exported by a logger\n# second comment line\n" + _join(head, rows), []
    if kind == "blank_lines":
        body = _join(head, rows).splitlines()
        body.insert(len(body) // 2, "")
        return "\n".join(body) + "\n\n\n", []
    raise ValueError(kind)


VARIANTS = ["bom", "crlf", "bom_crlf", "upper", "spaces", "reordered", "semicolon", "tab",
            "units", "aliases", "columns", "comments", "blank_lines"]


def _write(path: Path, text: str) -> Path:
    path.write_bytes(text.encode("utf-8"))
    return path


GONIO_ARGS = ["--faces", "ref,y,x,z", "--latitude", "50.45", "-q"]


@pytest.fixture(scope="module")
def refs(base, tmp_path_factory) -> Path:
    """What the plain files give (the reference every variant is compared with), computed
    once: ``gonio.json``, ``apply.csv`` and ``tilt.json``."""
    out = tmp_path_factory.mktemp("refs")
    assert main(["gonio", str(base / "plain" / "gonio.csv"), "--json", str(out / "gonio.json"),
                 *GONIO_ARGS]) == 0
    assert main(["apply", str(base / "outputs" / "pc.json"), str(base / "readings.csv"),
                 "--out", str(out / "apply.csv"), "--tilt", "-q"]) == 0
    assert main(["tilt", str(base / "readings.csv"), "--calibration",
                 str(base / "outputs" / "cal.json"), "--json", str(out / "tilt.json"),
                 "-q"]) == 0
    return out


@pytest.mark.parametrize("kind", VARIANTS)
def test_valid_variant_calibrate(base, tmp_path, kind):
    text, extra = variant((base / "plain" / "tumble.csv").read_text(), kind)
    f = _write(tmp_path / "tumble.csv", text)
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(f), "--scale-sign", "-", "--json", str(out), "-q",
                 *extra]) == 0
    got, ref = _json(out), _json(base / "outputs" / "cal.json")
    for key in ("scale_factors_v_per_g", "beta_rad", "bias_g", "scale_factors_u_v_per_g"):
        np.testing.assert_allclose(got[key], ref[key], rtol=1e-12, atol=0, err_msg=key)
    assert [p["pose"] for p in got["poses"]] == [p["pose"] for p in ref["poses"]]


@pytest.mark.parametrize("kind", VARIANTS)
def test_valid_variant_gonio(base, refs, tmp_path, kind):
    args = GONIO_ARGS
    ref_out = refs / "gonio.json"
    if kind == "units":  # the counter log's columns are counts and a time
        text = (base / "plain" / "gonio.csv").read_text().replace("t\n", "t [s]\n", 1)
        extra: list[str] = []
    else:
        text, extra = variant((base / "plain" / "gonio.csv").read_text(), kind)
    f = _write(tmp_path / "gonio.csv", text)
    out = tmp_path / "g.json"
    assert main(["gonio", str(f), "--json", str(out), *args, *extra]) == 0
    got, ref = _json(out), _json(ref_out)
    np.testing.assert_allclose(got["angles_deg"], ref["angles_deg"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got["angles_u_arcsec"], ref["angles_u_arcsec"], rtol=1e-12)
    assert got["revolutions_used"] == ref["revolutions_used"]


@pytest.mark.parametrize("kind", VARIANTS)
def test_valid_variant_apply(base, refs, tmp_path, kind):
    ref_csv = refs / "apply.csv"
    text, extra = variant((base / "readings.csv").read_text(), kind)
    f = _write(tmp_path / "readings.csv", text)
    out = tmp_path / "a.csv"
    assert main(["apply", str(base / "outputs" / "pc.json"), str(f), "--out", str(out),
                 "--tilt", "-q", *extra]) == 0
    np.testing.assert_array_equal(np.loadtxt(out, delimiter=",", skiprows=1),
                                  np.loadtxt(ref_csv, delimiter=",", skiprows=1))


@pytest.mark.parametrize("kind", VARIANTS)
def test_valid_variant_tilt(base, refs, tmp_path, kind):
    cal = str(base / "outputs" / "cal.json")
    ref = refs / "tilt.json"
    text, extra = variant((base / "readings.csv").read_text(), kind)
    f = _write(tmp_path / "readings.csv", text)
    out = tmp_path / "t.json"
    assert main(["tilt", str(f), "--calibration", cal, "--json", str(out), "-q",
                 *extra]) == 0
    a, b = _json(out), _json(ref)
    for key in ("samples", "roll_deg_mean", "pitch_deg_mean", "roll_deg_std", "pitch_deg_std"):
        assert a[key] == b[key], key


RUN_VARIANTS = ["bom", "crlf", "upper", "spaces", "reordered", "semicolon"]


@pytest.mark.parametrize("kind", RUN_VARIANTS)
def test_valid_variant_run(base, tmp_path, kind):
    """Every table of a session saved another way: the same misalignment."""
    s = tmp_path / "unit"
    s.mkdir()
    for name in ("tumble.csv", "gonio.csv", "platform.csv"):
        text, extra = variant((base / "plain" / name).read_text(), kind)
        assert not extra
        _write(s / name, text)
    toml = (base / "plain" / "session.toml").read_text()
    _write(s / "session.toml", ("\ufeff" if kind == "bom" else "")
           + (toml.replace("\n", "\r\n") if kind == "crlf" else toml))
    out = tmp_path / "r.json"
    assert main(["run", str(s), "--json", str(out), "-q"]) == 0
    got, ref = _json(out), _json(base / "outputs" / "result.json")
    np.testing.assert_allclose(got["misalignment_rad"], ref["misalignment_rad"], rtol=1e-9,
                               atol=1e-15)
    assert got["sources"] == ref["sources"] and got["ok"]


# ----------------------------------------------------------------------------- malformed

def _static_faults(plain: str) -> dict[str, tuple[str, str]]:
    """name -> (file text, what the message must contain) for a static-pose file."""
    head, rows = _split(plain)
    body = [",".join(r) for r in rows]
    h = ",".join(head)
    dup_pairs = [b for b in body for _ in (0, 1)]
    return {
        "empty": ("", "empty file"),
        "header_only": (h + "\n", "no rows"),
        "missing_column": ("pose,ux,uy,t\n" + "\n".join(",".join(r[:3] + r[4:])
                                                       for r in rows) + "\n", "lacks uz"),
        "not_a_number": (h + "\n" + body[0] + "\n0,abc,1,2,3\n", ":3: ux"),
        "nan_value": (h + "\n" + body[0] + "\n0,nan,1,2,3\n", ":3: ux"),
        "inf_value": (h + "\n" + body[0] + "\n0,1,inf,2,3\n", ":3: uy"),
        "empty_cell": (h + "\n" + body[0] + "\n0,1,,2,3\n", ":3: uy"),
        "blank_label": (h + "\n" + "\n".join(body[:5]) + "\n,1,2,3,99\n", ":7: pose"),
        "space_label": (h + "\n" + "\n".join(body[:5]) + "\n   ,1,2,3,99\n", ":7: pose"),
        "truncated_line": (h + "\n" + body[0] + "\n0,1,2\n", ":3:"),
        "extra_field": (h + "\n" + body[0] + "\n0,1,2,3,4,5\n", ":3:"),
        "decimal_comma": ("pose;ux;uy;uz;t\n0;1,5;2;3;0\n", "decimal comma"),
        "time_backwards": (h + "\n" + "\n".join(body[:3]) + "\n" + ",".join(
            rows[3][:4] + ["-5"]) + "\n", ":5: t"),
        "time_repeated": (h + "\n" + "\n".join(body[:3] + body[2:3]) + "\n", ":5: t"),
        "rows_twice_no_t": ("pose,ux,uy,uz\n" + "\n".join(",".join(r[:4]) for r in rows
                                                          for _ in (0, 1)) + "\n",
                            "written twice"),
        "block_twice_no_t": ("pose,ux,uy,uz\n" + "\n".join(",".join(r[:4]) for r in rows) * 1
                             + "\n" + "\n".join(",".join(r[:4]) for r in rows) + "\n",
                             "lines 2802-5601 repeat lines 2-2801 exactly"),
        "rows_twice_with_t": (h + "\n" + "\n".join(dup_pairs) + "\n",
                              "every row is written twice"),
        "not_utf8": ("", "UTF-8"),
        "passwd_like": ("root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/bin/sh\n",
                        "lacks"),
        "unknown_unit": (h.replace("ux", "ux [furlong]") + "\n" + "\n".join(body) + "\n",
                         "furlong"),
        "mixed_units": (h.replace("ux", "ux [V]").replace("uy", "uy [g]") + "\n"
                        + "\n".join(body) + "\n", "different units"),
        "column_twice": ("pose,ux,uy,uz,acc_x\n0,1,2,3,4\n", "ux: given 2 times"),
    }


def _write_fault(path: Path, name: str, text: str) -> Path:
    if name == "not_utf8":
        path.write_bytes(b"pose,ux,uy,uz\n0,\xff\xfe,1,2\n")
    else:
        _write(path, text)
    return path


_DUMMY = "pose,ux,uy,uz,t\n" + "".join(f"0,1,2,3,{k}\n" for k in range(6))
STATIC_FAULTS = list(_static_faults(_DUMMY))


@pytest.mark.parametrize("name", STATIC_FAULTS)
def test_malformed_static_file_calibrate(base, tmp_path, capsys, name):
    text, needle = _static_faults((base / "plain" / "tumble.csv").read_text())[name]
    f = _write_fault(tmp_path / "bad.csv", name, text)
    assert main(["calibrate", str(f), "--json", str(tmp_path / "o.json")]) == 2
    line = _err_line(capsys, str(f), needle)
    assert "root:x" not in line  # a file's contents are never echoed
    assert not (tmp_path / "o.json").exists()


READINGS_FAULTS = ["empty", "header_only", "not_a_number", "nan_value", "truncated_line",
                   "time_backwards", "rows_twice_with_t", "passwd_like", "unknown_unit",
                   "not_utf8"]


@pytest.mark.parametrize("cmd", ["tilt", "apply"])
@pytest.mark.parametrize("name", READINGS_FAULTS)
def test_malformed_readings(base, tmp_path, capsys, cmd, name):
    plain = (base / "readings.csv").read_text()
    text, needle = _static_faults("pose," + plain.replace("\n", "\n0,", plain.count("\n") - 1)
                                  )[name]
    # readings carry no pose column: drop the first field of every line again
    text = "\n".join(ln.split(",", 1)[-1] if "," in ln else ln for ln in text.split("\n"))
    needle = needle.replace(":3: ux", ":3:").replace(":5: t", ": t")
    f = _write_fault(tmp_path / "r.csv", name, text)
    out = tmp_path / "o.csv"
    if cmd == "tilt":
        args = ["tilt", str(f), "--calibration", str(base / "outputs" / "cal.json"), "--out",
                str(out)]
    else:
        args = ["apply", str(base / "outputs" / "pc.json"), str(f), "--out", str(out)]
    assert main(args) == 2
    line = _err_line(capsys, needle)
    assert "root:x" not in line
    assert not out.exists()


def _log_faults(plain: str) -> dict[str, tuple[str, str]]:
    head, rows = _split(plain)
    h = ",".join(head)
    body = [",".join(r) for r in rows]
    return {
        "empty": ("", "empty file"),
        "header_only": (h + "\n", "no rows"),
        "missing_ref": ("count,counter,t\n1,1,0\n", "lacks ref"),
        "count_not_int": (h + "\n" + body[0] + "\n1.5,2,0,1.0\n", ":3: count"),
        "count_negative": (h + "\n" + body[0] + "\n-5,2,0,1.0\n", "count"),
        "counter_3": (h + "\n" + body[0] + "\n5,3,0,1.0\n", "counter"),
        "ref_2": (h + "\n" + body[0] + "\n5,2,2,1.0\n", "ref"),
        "time_backwards": (h + "\n" + "\n".join(body[:3]) + "\n"
                           + ",".join(rows[3][:3] + ["0.0"]) + "\n", ": t"),
        "truncated": (h + "\n" + body[0] + "\n5,2\n", ":3:"),
        "not_a_number": (h + "\n" + body[0] + "\nx,2,0,1.0\n", ":3: count"),
        "passwd_like": ("root:x:0:0:root:/root:/bin/bash\n", "lacks"),
        "upper_and_spaces_bad_name": ("COUNT, COUNTER, REFX, T\n1,1,0,0\n", "lacks ref"),
    }


@pytest.mark.parametrize("name", list(_log_faults(
    "count,counter,ref,t\n" + "".join(f"5,1,0,{k}\n" for k in range(6)))))
def test_malformed_counter_log(base, tmp_path, capsys, name):
    text, needle = _log_faults((base / "plain" / "gonio.csv").read_text())[name]
    f = _write(tmp_path / "log.csv", text)
    assert main(["gonio", str(f), "--faces", "ref,y,x,z"]) == 2
    line = _err_line(capsys, str(f), needle)
    assert "root:x" not in line


@pytest.mark.parametrize("cmd", ["calibrate", "gonio", "tilt", "apply"])
@pytest.mark.parametrize("what", ["missing", "folder"])
def test_input_path_missing_or_a_folder(base, tmp_path, capsys, cmd, what):
    p = tmp_path / ("nope.csv" if what == "missing" else "adir")
    if what == "folder":
        p.mkdir()
    args = {"calibrate": ["calibrate", str(p)],
            "gonio": ["gonio", str(p), "--faces", "ref,y,x,z"],
            "tilt": ["tilt", str(p), "--calibration", str(base / "outputs" / "cal.json")],
            "apply": ["apply", str(base / "outputs" / "pc.json"), str(p), "--out",
                      str(tmp_path / "o.csv")]}[cmd]
    assert main(args) == 2
    _err_line(capsys, str(p), "no such file" if what == "missing" else "folder")


def test_columns_mapping_errors(base, tmp_path, capsys):
    f = base / "plain" / "tumble.csv"
    assert main(["calibrate", str(f), "--columns", "ux"]) == 2
    _err_line(capsys, "--columns", "NAME=HEADER")
    assert main(["calibrate", str(f), "--columns", "ux=nosuch"]) == 2
    _err_line(capsys, "--columns ux=nosuch")
    assert main(["calibrate", str(f), "--columns", "wx=ux"]) == 2
    _err_line(capsys, "wx")


# ----------------------------------------------------------------------------- flags

FLAG_FAULTS = [
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--latitude", "nan"], "--latitude"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--latitude", "inf"], "--latitude"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--latitude", "1000"], "--latitude"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--latitude", "-90.5"], "--latitude"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--latitude", "north"], "--latitude"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--alpha", "5"], "--alpha"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--alpha", "-1"], "--alpha"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--alpha", "nan"], "--alpha"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--alpha", "0"], "--alpha"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--alpha", "1"], "--alpha"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--nominal", "100,100,100,100"], "--nominal"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--nominal", "90,90,90"], "--nominal"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--nominal", "-90,90,180,180"], "--nominal"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--nominal", "nan,90,90,90"], "--nominal"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--nominal", "a,b,c,d"], "--nominal"),
    (["gonio", "{log}", "--faces", "ref,y,y,x"], "--faces"),
    (["gonio", "{log}", "--faces", "ref,,x,z"], "--faces"),
    (["gonio", "{log}", "--faces", "ref"], "--faces"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--reverse-log", "{log}"], "--reverse-log"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--reverse-log", "{logcopy}"], "--reverse-log"),
    (["gonio", "{log}", "--faces", "ref,y,x,z", "--direction", "up"], "--direction"),
    (["calibrate", "{static}", "--scale-sign", "x"], "--scale-sign"),
    (["calibrate", "{static}", "--scale-sign", "+,-"], "--scale-sign"),
    (["calibrate", "{static}", "--window", "0"], "--window"),
    (["calibrate", "{static}", "--window", "-1"], "--window"),
    (["calibrate", "{static}", "--threshold", "0.5"], "--threshold"),
    (["calibrate", "{static}", "--min-static", "nan"], "--min-static"),
    (["calibrate", "{static}", "--margin", "-1"], "--margin"),
    (["calibrate", "{static}", "--rate", "0"], "--rate"),
    (["calibrate", "{static}", "--rate", "-100"], "--rate"),
    (["calibrate", "{static}", "--rate", "nan"], "--rate"),
    (["calibrate", "{static}", "--rate", "100"], "--rate"),  # the file has its own t
    (["calibrate", "{static}", "--units", "furlongs"], "--units"),
    (["calibrate", "{static}", "--check", "{static}"], "twice"),
    (["calibrate", "{static}", "--alpha", "2"], "--alpha"),
    (["tilt", "{readings}", "--calibration", "{cal}", "--mu", "0"], "--mu"),
    (["tilt", "{readings}", "--calibration", "{cal}", "--method", "guess"], "--method"),
    (["tilt", "{readings}", "--calibration", "{cal}", "--units", "g"], "calibrated from V"),
    (["apply", "{pc}", "{readings}", "--out", "{out}", "--units", "counts"], "calibrated"),
    (["run", "{session}", "--jobs", "-1"], "--jobs"),
    (["run", "{session}", "--jobs", "0"], "--jobs"),
    (["run", "{session}", "--jobs", "two"], "--jobs"),
    (["run", "{session}", "{session}"], "twice"),
    (["run", "{session}", "--alpha", "inf"], "--alpha"),
    (["camera", "{static}", "--pattern", "0x0"], "--pattern"),
    (["camera", "{static}", "--pattern", "1x5"], "--pattern"),
    (["camera", "{static}", "--pattern", "nine"], "--pattern"),
    (["camera", "{static}", "--square", "0"], "--square"),
    (["marks", "{static}", "{static}"], "twice"),
    (["marks", "{static}", "--max-marks", "0"], "--max-marks"),
    (["marks", "{static}", "--alpha", "nan"], "--alpha"),
    (["synth", "session", "{tmp}/s", "--seed", "-1"], "--seed"),
    (["synth", "session", "{tmp}/s", "--effect", "camera_roll_A=nan"], "--effect"),
    (["synth", "session", "{tmp}/s", "--effect", "nosuch=1"], "--effect"),
    (["demo", "--seed", "x"], "--seed"),
]


@pytest.mark.parametrize("argv,flag", FLAG_FAULTS,
                         ids=[f"{a[0]}{'_'.join(a[a.index(flag) if flag in a else 2:][:2])}"
                              for a, flag in FLAG_FAULTS])
def test_bad_flag_values(base, tmp_path, capsys, argv, flag):
    (tmp_path / "logcopy.csv").write_bytes((base / "plain" / "gonio.csv").read_bytes())
    sub = {"{log}": str(base / "plain" / "gonio.csv"), "{logcopy}": str(tmp_path / "logcopy.csv"),
           "{static}": str(base / "plain" / "tumble.csv"), "{readings}": str(base / "readings.csv"),
           "{cal}": str(base / "outputs" / "cal.json"), "{pc}": str(base / "outputs" / "pc.json"),
           "{out}": str(tmp_path / "o.csv"), "{session}": str(base / "plain")}
    args = [sub.get(a, a.replace("{tmp}", str(tmp_path))) for a in argv]
    assert main(args) == 2
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("align")]
    assert len(lines) == 1 and flag in lines[0], cap.err
    assert not (tmp_path / "s").exists() and not (tmp_path / "o.csv").exists()


def test_every_option_has_help_and_shows_its_default():
    """Every option is explained; one with a default shows it (those without show none:
    tests/align/commands/test_parser.py)."""
    parser = build_parser()
    subs = [a for a in parser._actions if isinstance(a, type(parser._subparsers._group_actions[0]))]
    seen = shown = 0
    for sp in subs[0].choices.values():
        for p in [sp, *[c for a in sp._actions if hasattr(a, "choices") and isinstance(
                a.choices, dict) for c in a.choices.values()]]:
            text = " ".join(p.format_help().split())
            for a in p._actions:
                if a.option_strings and a.dest != "help":
                    assert a.help, (p.prog, a.option_strings)
                    seen += 1
                    if a.default not in (None, False, []) and "default" not in a.help:
                        assert f"(default: {a.default})" in text, (p.prog, a.option_strings)
                        shown += 1
    assert seen > 50 and shown > 15


# ----------------------------------------------------------------------------- session keys

def _session(base: Path, tmp_path: Path, edit=None, extra: str = "") -> Path:
    s = tmp_path / "unit"
    s.mkdir(exist_ok=True)
    for name in ("tumble.csv", "gonio.csv", "platform.csv"):
        (s / name).write_bytes((base / "plain" / name).read_bytes())
    toml = (base / "plain" / "session.toml").read_text()
    for old, new in ([] if not edit else edit if isinstance(edit, list) else [edit]):
        assert old in toml, old
        toml = toml.replace(old, new, 1)
    (s / "session.toml").write_text(toml + extra)
    return s


KEY_FAULTS = [
    ("latitude_nan", ("latitude_deg = 50.45", "latitude_deg = nan"), "", "latitude_deg"),
    ("latitude_1000", ("latitude_deg = 50.45", "latitude_deg = 1000"), "", "latitude_deg"),
    ("name_number", ("latitude_deg = 50.45", "name = 5\nlatitude_deg = 50.45"), "", "name"),
    ("name_blank", ("latitude_deg = 50.45", 'name = " "\nlatitude_deg = 50.45'), "", "name"),
    ("latitude_text", ("latitude_deg = 50.45", 'latitude_deg = "N"'), "", "latitude_deg"),
    ("nominal_sum", ("nominal_deg = [90.0, 90.0, 90.0, 90.0]",
                     "nominal_deg = [100.0, 100.0, 100.0, 100.0]"), "", "nominal_deg"),
    ("nominal_inf", ("nominal_deg = [90.0, 90.0, 90.0, 90.0]",
                     "nominal_deg = [inf, 90.0, 90.0, 90.0]"), "", "nominal_deg"),
    ("nominal_negative", ("nominal_deg = [90.0, 90.0, 90.0, 90.0]",
                          "nominal_deg = [-90.0, 90.0, 180.0, 180.0]"), "", "nominal_deg"),
    ("faces_twice", ('faces = ["ref", "y", "x", "z"]', 'faces = ["ref", "y", "y", "z"]'), "",
     "faces"),
    ("faces_blank", ('faces = ["ref", "y", "x", "z"]', 'faces = ["ref", "", "x", "z"]'), "",
     "faces"),
    ("offset_huge", ('direction = "ccw"', 'direction = "ccw"\nreference_offset_arcsec = 1e308'),
     "", "reference_offset_arcsec"),
    ("offset_nan", ('direction = "ccw"', 'direction = "ccw"\nreference_offset_arcsec = nan'),
     "", "reference_offset_arcsec"),
    ("steady_text", ('direction = "ccw"', 'direction = "ccw"\nsteady_table = "yes"'), "",
     "steady_table"),
    ("counters_sound_text", ('direction = "ccw"', 'direction = "ccw"\ncounters_sound = "yes"'),
     "", "counters_sound"),
    ("reverse_is_log", ('direction = "ccw"', 'direction = "ccw"\nreverse_log = "gonio.csv"'),
     "", "reverse_log"),
    ("roll_huge", None, '\n[cameras.A]\nroll_arcsec = 1e308\n', "roll_arcsec"),
    ("roll_inf", None, '\n[cameras.A]\nroll_arcsec = inf\n', "roll_arcsec"),
    ("blur_after_text", None, '\n[cameras.A]\nblur_after_pixels = "yes"\n',
     "blur_after_pixels"),
    ("tilt_huge", ('static = "platform.csv"', 'static = "platform.csv"\n'
                   'table_tilt_arcsec = [1e308, 0.0]'), "", "table_tilt_arcsec"),
    ("table_deg_nan", ('L090 = { up = "+Z", table_deg = 90.0 }',
                       'L090 = { up = "+Z", table_deg = nan }'), "", "table_deg"),
    ("units_bad", ('scale_sign = "-"', 'scale_sign = "-"\nunits = "furlong"'), "", "units"),
    ("units_mismatch", [('scale_sign = "-"', 'scale_sign = "-"\nunits = "counts"'),
                        ('static = "platform.csv"', 'static = "platform.csv"\nunits = "g"')],
     "", "units"),
    ("rate_zero", ('scale_sign = "-"', 'scale_sign = "-"\nrate_hz = 0'), "", "rate_hz"),
    ("time_unit_bad", ('scale_sign = "-"', 'scale_sign = "-"\ntime_unit = "fortnight"'), "",
     "time_unit"),
    ("gonio_time_unit_bad", ('direction = "ccw"', 'direction = "ccw"\ntime_unit = "fortnight"'),
     "", "time_unit"),
    ("columns_bad", ('scale_sign = "-"', 'scale_sign = "-"\ncolumns = "ux"'), "", "columns"),
    ("same_file_twice", ('static = "platform.csv"', 'static = "tumble.csv"'), "",
     "the same file"),
    ("unknown_key", ('scale_sign = "-"', 'scale_sign = "-"\nscale_sing = "+"'), "",
     "unknown key"),
    ("check_missing", ('scale_sign = "-"', 'scale_sign = "-"\ncheck = "nope.csv"'), "",
     "no such file"),
    ("dotdot", ('log = "gonio.csv"', 'log = "../../../../../../../../etc/passwd"'), "",
     "outside the session folder"),
    ("absolute", ('log = "gonio.csv"', 'log = "/etc/passwd"'), "",
     "outside the session folder"),
]


@pytest.mark.parametrize("name,edit,extra,key", KEY_FAULTS, ids=[k[0] for k in KEY_FAULTS])
def test_bad_session_keys(base, tmp_path, capsys, name, edit, extra, key):
    s = _session(base, tmp_path, edit, extra)
    out = tmp_path / "r.json"
    assert main(["run", str(s), "--json", str(out)]) == 2
    line = _err_line(capsys, "session.toml", key)
    assert "root:" not in line
    assert not out.exists()


def test_symlink_out_of_the_session_is_refused_unless_allowed(base, tmp_path, capsys):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "gonio.csv").write_bytes((base / "plain" / "gonio.csv").read_bytes())
    s = _session(base, tmp_path)
    (s / "gonio.csv").unlink()
    (s / "gonio.csv").symlink_to(outside / "gonio.csv")
    assert main(["run", str(s), "-q"]) == 2
    _err_line(capsys, "log", "outside the session folder")
    assert main(["run", str(s), "-q", "--allow-outside"]) == 0


def test_passwd_as_a_log_never_reaches_the_outputs(base, tmp_path, capsys):
    """Allowed outside, a non-table file fails its stage; its contents are not echoed."""
    fake = tmp_path / "passwd"
    fake.write_text("root:x:0:0:root:/root:/bin/bash\nsecret:x:1:1::/home/secret:/bin/sh\n")
    s = _session(base, tmp_path, ('log = "gonio.csv"', f'log = "{fake}"'))
    out = tmp_path / "r.json"
    assert main(["run", str(s), "--json", str(out), "--allow-outside", "-q"]) == 2
    text = out.read_text()
    assert "root:x" not in text and "secret" not in text
    assert not _json(out)["ok"]


def test_calibration_output_without_a_calibration_section(base, tmp_path, capsys):
    s = _session(base, tmp_path)
    toml = (s / "session.toml").read_text()
    start = toml.index("[calibration]")
    end = toml.index("[goniometer]")
    plat = toml.index("[platform]")
    (s / "session.toml").write_text(toml[:start] + toml[end:plat])
    cal = tmp_path / "C.json"
    assert main(["run", str(s), "--calibration", str(cal)]) == 2
    _err_line(capsys, "--calibration", "no [calibration]")
    assert not cal.exists()


# ----------------------------------------------------------------------------- outputs

def test_two_outputs_with_one_path(base, tmp_path, capsys):
    x = tmp_path / "X"
    assert main(["run", str(base / "plain"), "--json", str(x), "--report", str(x)]) == 2
    _err_line(capsys, "--report", "same path as --json")
    assert not x.exists()


def test_existing_output_is_kept_without_force_and_replaced_with_it(base, tmp_path, capsys):
    out = tmp_path / "g.json"
    out.write_text("keep me")
    log = str(base / "plain" / "gonio.csv")
    assert main(["gonio", log, "--faces", "ref,y,x,z", "--json", str(out)]) == 2
    _err_line(capsys, "exists", "--force")
    assert out.read_text() == "keep me"
    assert main(["gonio", log, "--faces", "ref,y,x,z", "--json", str(out), "--force",
                 "-q"]) == 0
    assert _json(out)["format"] == "axis-align/gonio"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]


@pytest.mark.parametrize("cmd", ["calibrate", "gonio", "tilt", "apply", "run"])
def test_output_onto_an_input_is_refused(base, tmp_path, capsys, cmd):
    inp = tmp_path / "in.csv"
    src = {"calibrate": base / "plain" / "tumble.csv", "gonio": base / "plain" / "gonio.csv",
           "tilt": base / "readings.csv", "apply": base / "readings.csv"}.get(cmd)
    if src is not None:
        inp.write_bytes(src.read_bytes())
    before = inp.read_bytes() if src is not None else None
    args = {"calibrate": ["calibrate", str(inp), "--json", str(inp), "--force"],
            "gonio": ["gonio", str(inp), "--faces", "ref,y,x,z", "--json", str(inp), "--force"],
            "tilt": ["tilt", str(inp), "--calibration", str(base / "outputs" / "cal.json"),
                     "--out", str(base / "outputs" / "cal.json"), "--force"],
            "apply": ["apply", str(base / "outputs" / "pc.json"), str(inp), "--out", str(inp),
                      "--force"],
            "run": ["run", str(base / "plain"), "--json",
                    str(base / "plain" / "gonio.csv"), "--force"]}[cmd]
    assert main(args) == 2
    _err_line(capsys, "one of the inputs")
    if before is not None:
        assert inp.read_bytes() == before


@pytest.mark.parametrize("where", ["parent_is_a_file", "missing_parent_created"])
def test_output_folder_checked_before_computing(base, tmp_path, capsys, where):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    target = (blocker / "g.json") if where == "parent_is_a_file" else (
        tmp_path / "new" / "deeper" / "g.json")
    code = main(["gonio", str(base / "plain" / "gonio.csv"), "--faces", "ref,y,x,z",
                 "--json", str(target), "-q"])
    if where == "parent_is_a_file":
        assert code == 2
        _err_line(capsys, "--json")
    else:
        assert code == 0 and _json(target)["ok"]


def test_an_output_that_appears_meanwhile_is_not_replaced(tmp_path):
    from axisbase.output import OutputError, OutputPlan, write_json

    out = OutputPlan([], force=False).add("--json", tmp_path / "r.json")
    (tmp_path / "r.json").write_text("another run's result")  # written while we computed
    with pytest.raises(OutputError, match="appeared"):
        write_json(out, {"a": 1})
    assert (tmp_path / "r.json").read_text() == "another run's result"
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_json_to_stdout_is_the_only_thing_on_stdout(base, capsys):
    assert main(["gonio", str(base / "plain" / "gonio.csv"), "--faces", "ref,y,x,z",
                 "--json", "-"]) == 0
    cap = capsys.readouterr()
    d = json.loads(cap.out)
    assert d["format"] == "axis-align/gonio" and "revolutions used" in cap.err


def test_closed_pipe_ends_quietly_with_the_files_written(base, tmp_path):
    out = tmp_path / "g.json"
    cmd = (f"{sys.executable} -m align gonio {base / 'plain' / 'gonio.csv'} --faces ref,y,x,z "
           f"--json {out} | head -1")
    r = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert "Traceback" not in r.stderr and "BrokenPipe" not in r.stderr, r.stderr
    assert r.stdout.count("\n") == 1
    assert _json(out)["ok"]


def test_strict_json_never_nan():
    from axisbase.output import dumps

    text = dumps({"a": float("nan"), "b": [np.inf, 1.0], "c": np.float64("nan"),
                  "d": np.array([1.0, np.nan])})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {
        "a": None, "b": [None, 1.0], "c": None, "d": [1.0, None]}


def test_demo_needs_force_for_a_used_folder(tmp_path, capsys):
    (tmp_path / "something").write_text("x")
    assert main(["demo", "--out", str(tmp_path)]) == 2
    _err_line(capsys, "--force")
    assert (tmp_path / "something").read_text() == "x"


# ----------------------------------------------------------------------------- exit status

def test_failed_stage_exit_2_result_written_not_ok(base, tmp_path, capsys):
    s = _session(base, tmp_path)
    (s / "gonio.csv").write_text("count,counter,ref\n")  # header only: the stage fails
    out, rep = tmp_path / "r.json", tmp_path / "r.html"
    assert main(["run", str(s), "--json", str(out), "--report", str(rep)]) == 2
    d = _json(out)
    assert d["ok"] is False and d["fused"] is True
    assert d["warnings"][0].startswith("stage goniometer FAILED")
    assert "WARNING: stage goniometer FAILED" in capsys.readouterr().err
    html = rep.read_text()
    assert html.index("Warnings") < html.index("Misalignment matrix")
    from align.contract import validate

    validate(d, "session")


def test_run_json_to_stdout_and_not_for_a_batch(base, capsys):
    assert main(["run", str(base / "plain"), "--json", "-"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["ok"] and "misalignment" in cap.err  # messages moved aside
    assert main(["run", str(base / "plain"), "--json", "-", "-q"]) == 0
    cap = capsys.readouterr()  # -q: stderr is left to warnings and errors
    assert json.loads(cap.out)["ok"] and "misalignment" not in cap.err
    assert main(["run", str(base / "plain"), str(base / "full"), "--json", "-"]) == 2
    _err_line(capsys, "--json -", "batch")


def test_ctrl_c_exits_130(monkeypatch, capsys):
    import align.commands.gonio

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(align.commands.gonio, "cmd_gonio", interrupted)
    assert main(["gonio", "x.csv", "--faces", "a,b"]) == 130
    assert "interrupted" in capsys.readouterr().err


# ----------------------------------------------------------------------------- provenance

@pytest.mark.parametrize("kind,path", [
    ("session", "outputs/result.json"), ("platform-calibration", "outputs/pc.json"),
    ("calibration", "outputs/cal.json")])
def test_outputs_validate_against_shipped_schemas(base, kind, path):
    import hashlib

    from align.contract import FORMATS, validate

    d = _json(base / path)
    validate(d, kind)
    # the contract's provenance keys, at the top level
    assert d["tool_version"] == _pyproject_version() and d["command"][0] == "align"
    assert d["format_version"] == FORMATS[kind] and d["created_utc"].endswith("Z")
    assert d["inputs"]
    for i in d["inputs"]:
        assert i["sha256"] == hashlib.sha256(Path(i["path"]).read_bytes()).hexdigest()


def test_a_schema_refuses_what_it_should(base):
    """The shipped schemas are not vacuous: a file without its provenance, with a NaN-like
    string for a number or with a wrong format version fails validation."""
    import jsonschema

    from align.contract import validate

    d = _json(base / "outputs" / "cal.json")
    for bad in ({k: v for k, v in d.items() if k != "created_utc"},
                dict(d, format_version=2), dict(d, inputs=[{"path": "x"}])):
        with pytest.raises(jsonschema.ValidationError):
            validate(bad, "calibration")


def test_schemas_hold_skipped_candidates_and_internal_errors(base):
    """``skipped_candidates`` (each loop) and ``errors[].internal`` are in the schemas, not
    passed as unknown keys: a well-formed one validates, a malformed one does not."""
    import copy

    import jsonschema

    from align.contract import schema, validate

    d = _json(base / "outputs" / "result.json")
    assert "skipped_candidates" in schema("session")["properties"]
    good = copy.deepcopy(d)
    good["skipped_candidates"] = [{"name": "scale_drift", "reason": "no times"}]
    good["errors"] = [{"stage": "marks", "message": "internal error", "internal": True}]
    validate(good, "session")
    for key, bad in (("skipped_candidates", [{"name": "scale_drift"}]),
                     ("skipped_candidates", [{"name": "x", "reason": "y", "extra": 1}]),
                     ("errors", [{"stage": "marks", "message": "m", "internal": False}]),
                     ("errors", [{"stage": "marks", "message": "m", "internals": True}])):
        with pytest.raises(jsonschema.ValidationError):
            validate(dict(d, **{key: bad}), "session")
    cal = _json(base / "outputs" / "cal.json")
    validate(dict(cal, skipped_candidates=[{"name": "k", "reason": "r"}]), "calibration")
    with pytest.raises(jsonschema.ValidationError):
        validate(dict(cal, skipped_candidates=[{"reason": "r"}]), "calibration")


def test_provenance_round_trip_and_earlier_layout(base):
    from axisbase.provenance import Provenance

    d = _json(base / "outputs" / "result.json")
    p = Provenance.from_dict(d)
    assert p.to_dict() == {k: d[k] for k in p.to_dict()}
    old = {"provenance": {"tool": "axis-align", "version": "0.0.9", "written_utc": "x",
                          "command_line": ["align", "run"], "settings": {"a": 1},
                          "inputs": [{"path": "p", "sha256": None, "bytes": None}]}}
    q = Provenance.from_dict(old)
    assert (q.tool_version, q.command, q.settings, q.inputs[0].path) == (
        "0.0.9", ("align", "run"), {"a": 1}, "p")


@pytest.mark.parametrize("cmd", ["gonio", "tilt"])
def test_other_outputs_validate(base, tmp_path, cmd):
    from align.contract import validate

    out = tmp_path / "o.json"
    args = {"gonio": ["gonio", str(base / "plain" / "gonio.csv"), "--faces", "ref,y,x,z"],
            "tilt": ["tilt", str(base / "readings.csv"), "--calibration",
                     str(base / "outputs" / "cal.json")]}[cmd]
    assert main([*args, "--json", str(out), "-q"]) == 0
    validate(_json(out), cmd)


def _pyproject_version() -> str:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"axis-align {_pyproject_version()}"


def _old_format(d: dict) -> dict:
    """A file as format version 1 wrote it: no envelope, no units."""
    d = {k: v for k, v in d.items() if k not in ("format", "format_version", *PROV)}
    d["model"] = {k: v for k, v in d["model"].items() if k != "output_unit"}
    return d


PROV = ("tool", "tool_version", "created_utc", "command", "settings", "inputs")


def _v2(d: dict) -> dict:
    """A file as format version 2 wrote it: provenance nested in a block of its own."""
    out = {k: v for k, v in d.items() if k not in PROV}
    out["format_version"] = 2
    out["provenance"] = {"tool": d["tool"], "version": d["tool_version"],
                         "written_utc": d["created_utc"], "command_line": d["command"],
                         "settings": d["settings"], "inputs": d["inputs"]}
    return out


@pytest.mark.parametrize("version", ["v1_platform", "v1_session", "v2_session", "v2_platform",
                                     "v3_session", "v99", "wrong_format",
                                     "no_platform_calibration"])
def test_apply_reads_earlier_formats_or_says_which_it_cannot(base, tmp_path, capsys, version):
    pc = _json(base / "outputs" / "pc.json")
    res = _json(base / "outputs" / "result.json")
    d = {"v1_platform": _old_format(pc),
         "v1_session": {k: v for k, v in res.items()
                        if k not in ("format", "format_version", *PROV)},
         "v2_session": _v2(res), "v2_platform": _v2(pc), "v3_session": res,
         "v99": dict(pc, format_version=99),
         "wrong_format": dict(pc, format="axis-align/gonio"),
         "no_platform_calibration": {k: v for k, v in res.items()
                                     if k != "platform_calibration"}}[version]
    f = tmp_path / "c.json"
    f.write_text(json.dumps(d))
    out = tmp_path / "a.csv"
    code = main(["apply", str(f), str(base / "readings.csv"), "--out", str(out), "-q"])
    if version[:2] in ("v1", "v2", "v3"):
        assert code == 0
        ref = tmp_path / "ref.csv"
        assert main(["apply", str(base / "outputs" / "pc.json"), str(base / "readings.csv"),
                     "--out", str(ref), "-q"]) == 0
        assert out.read_text() == ref.read_text()
    else:
        assert code == 2
        needle = {"v99": "version 99 is newer", "wrong_format": "axis-align/gonio",
                  "no_platform_calibration": "without a platform calibration"}[version]
        _err_line(capsys, needle)


# ----------------------------------------------------------------------------- conventions

def test_help_imports_no_heavy_library():
    code = ("import sys, contextlib, io\nfrom align.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    main(['--help']); main(['gonio', '--help'])\n"
            "heavy = [m for m in ('numpy', 'scipy', 'matplotlib', 'pyarrow', 'cv2') "
            "if m in sys.modules]\nprint(heavy)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert r.stdout.strip() == "[]", r.stdout + r.stderr


def test_ascii_console_fallback(base):
    r = subprocess.run([sys.executable, "-m", "align", "gonio", str(base / "plain" / "gonio.csv"),
                        "--faces", "ref,y,x,z"], capture_output=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT), "PYTHONIOENCODING": "ascii"},
                       timeout=120)
    assert r.returncode == 0, r.stderr
    text = r.stdout.decode("ascii")  # would raise on any non-ASCII byte
    assert '+/- ' in text and '"' in text


def test_quiet_and_verbose(base, capsys):
    log = str(base / "plain" / "gonio.csv")
    assert main(["run", str(base / "plain"), "-q"]) == 0
    assert "[plain]" not in capsys.readouterr().err
    assert main(["run", str(base / "plain")]) == 0
    assert "[plain] fusion" in capsys.readouterr().err
    assert main(["gonio", log, "--faces", "ref,y,x,z", "-q", "-v"]) == 2


@pytest.mark.slow
def test_two_concurrent_runs_on_the_same_outputs(base, tmp_path):
    """Both check their outputs before computing; the exclusive rename lets exactly one
    write, the other says so (exit 2) — no result is silently lost."""
    out = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "align", "run", str(base / "plain"), "--json", str(out), "-q"]
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(c for c, _ in results)
    assert codes == [0, 2], results
    loser = next(err for c, err in results if c == 2)
    assert str(out) in loser and ("exists" in loser or "appeared" in loser)
    assert _json(out)["ok"]
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_tilt_takes_any_calibration_file_and_says_its_frame(base, tmp_path):
    """A triad calibration gives the triad frame's roll/pitch; a platform calibration and the
    session result holding it give the platform's, exactly as 'align apply --tilt'."""
    outs = []
    for cal in ("cal.json", "pc.json", "result.json"):
        out = tmp_path / f"{cal}.tilt.json"
        assert main(["tilt", str(base / "readings.csv"), "--calibration",
                     str(base / "outputs" / cal), "--json", str(out), "--out",
                     str(tmp_path / f"{cal}.csv"), "-q"]) == 0
        outs.append(_json(out))
    assert [o["frame"] for o in outs] == ["triad", "platform", "platform"]
    from align.contract import validate

    for o in outs:
        validate(o, "tilt")
    assert outs[1]["roll_deg_mean"] == outs[2]["roll_deg_mean"]
    ap = tmp_path / "ap.csv"
    assert main(["apply", str(base / "outputs" / "pc.json"), str(base / "readings.csv"),
                 "--out", str(ap), "--tilt", "-q"]) == 0
    A = np.genfromtxt(ap, delimiter=",", names=True)
    T = np.genfromtxt(tmp_path / "pc.json.csv", delimiter=",", names=True)
    # the same numbers, printed with 9 (tilt) and 10 (apply) significant digits: half a unit
    # of the 9th digit plus of the 10th is at most 5.5e-9 relative
    assert np.allclose(T["roll_deg"], A["roll_deg"], rtol=5.5e-9, atol=1e-12)
    assert np.allclose(T["pitch_deg"], A["pitch_deg"], rtol=5.5e-9, atol=1e-12)


def test_synth_force_replaces_only_what_synth_wrote(tmp_path, capsys):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("my notes")
    assert main(["synth", "session", str(mine), "--force"]) == 2
    _err_line(capsys, "not a session written by 'align synth'")
    assert (mine / "notes.txt").read_text() == "my notes"


def test_marks_output_validates_and_carries_warnings(tmp_path):
    from align.contract import validate
    from synth import write_synth
    from tests.conftest import mark_image

    s = mark_image(25.0, seed=4, size=(480, 360), length_px=250, with_crlb=False)
    p, _ = write_synth(s, tmp_path / "mark.png")
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    out = tmp_path / "m.json"
    assert main(["marks", str(p), str(bad), "--json", str(out), "-q"]) == 2
    d = _json(out)
    validate(d, "marks")
    assert d["ok"] is False and any("bad.png" in w for w in d["warnings"])


def test_rate_gives_a_recording_without_times_the_same_result(tmp_path, capsys):
    """A continuous recording t,ux,uy,uz (t = k / 20 Hz) and the same without its time column
    plus --rate 20: the same static intervals, the same calibration."""
    from synth.tumble import Triad, TumbleSpec, recording

    t, u, _ = recording(TumbleSpec(triad=Triad(noise_v=4.8e-5), seed=3, dwell_s=6.0))
    k = np.round(t * 20).astype(int)
    assert np.allclose(k / 20, t, atol=1e-9) and k[0] == 0
    with_t = tmp_path / "rec_t.csv"
    with_t.write_text("t,ux,uy,uz\n" + "".join(
        f"{ki / 20:.2f},{a:.9e},{b:.9e},{c:.9e}\n" for ki, (a, b, c) in zip(k, u, strict=True)))
    no_t = tmp_path / "rec.csv"
    no_t.write_text("ux,uy,uz\n" + "".join(f"{a:.9e},{b:.9e},{c:.9e}\n" for a, b, c in u))
    outs = []
    for f, extra in ((with_t, []), (no_t, ["--rate", "20"])):
        out = tmp_path / f"{f.stem}.json"
        assert main(["calibrate", str(f), "--json", str(out), "-q", *extra]) == 0
        outs.append(_json(out))
    assert outs[0]["static_intervals"] == outs[1]["static_intervals"]
    assert outs[0]["scale_factors_v_per_g"] == outs[1]["scale_factors_v_per_g"]
    assert main(["calibrate", str(no_t)]) == 2
    _err_line(capsys, "--rate")


@pytest.mark.parametrize("version", [None, 2, 3, 99, "gonio"])
def test_camera_model_format_versions(tmp_path, version):
    from imaging import CameraModel, ImageInputError

    d = {"camera_matrix": [[800, 0, 320], [0, 800, 240], [0, 0, 1]],
         "dist_coeffs": [0.1, 0, 0, 0, 0], "image_size": [640, 480]}
    if version == "gonio":
        d.update(format="axis-align/gonio", format_version=2)
    elif version is not None:
        d.update(format="axis-align/camera", format_version=version)
    f = tmp_path / "cam.json"
    f.write_text("\ufeff" + json.dumps(d))  # a BOM, as a Windows editor saves it
    if version in (None, 2, 3):
        assert CameraModel.load(f).image_size == (640, 480)
    else:
        with pytest.raises(ImageInputError, match="newer" if version == 99 else "gonio"):
            CameraModel.load(f)


def test_units_are_carried_and_checked(base, tmp_path, capsys):
    """Scale factors labelled in the data's unit; readings stated in another unit refused,
    unstated ones taken in the calibration's."""
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(base / "plain" / "tumble.csv"), "--scale-sign", "-",
                 "--units", "counts", "--json", str(out)]) == 0
    cap = capsys.readouterr()
    assert "k_x [counts/g]" in cap.out and "V/g" not in cap.out
    d = _json(out)
    assert d["output_unit"] == "counts" and d["scale_factor_unit"] == "counts/g"
    assert d["model"]["output_unit"] == "counts"
    r = str(base / "readings.csv")
    assert main(["tilt", r, "--calibration", str(out), "-q"]) == 0
    assert main(["tilt", r, "--calibration", str(out), "--units", "m/s2"]) == 2
    _err_line(capsys, "m/s2", "counts")
    text, _ = variant((base / "readings.csv").read_text(), "units")  # header says [V]
    f = _write(tmp_path / "r.csv", text)
    assert main(["tilt", str(f), "--calibration", str(out)]) == 2
    _err_line(capsys, "V", "counts")


def test_batch_outputs_may_share_a_folder(base, tmp_path):
    """Several sessions: --json and --calibration name folders, and may name the same one
    (the files are <session>.json and <session>.cal.json)."""
    b = tmp_path / "unit2"
    b.mkdir()
    for f in (base / "plain").iterdir():
        (b / f.name).write_bytes(f.read_bytes())
    out = tmp_path / "results"
    assert main(["run", str(base / "plain"), str(b), "--json", str(out), "--calibration",
                 str(out), "--jobs", "1", "-q"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["plain.cal.json", "plain.json",
                                                     "unit2.cal.json", "unit2.json"]


def test_apply_never_invents_times(base, tmp_path):
    """Readings without a time column keep none in the output (t blank), and the specific
    force is the same as with their times when the model has no drift."""
    src = (base / "readings.csv").read_text().splitlines()
    head = src[0].split(",")
    if "t" not in head:
        pytest.skip("the readings of this fixture have no time column")
    k = head.index("t")
    drop = [",".join(v for i, v in enumerate(r.split(",")) if i != k) for r in src]
    (tmp_path / "no_t.csv").write_text("\n".join(drop) + "\n")
    cal = str(base / "outputs" / "pc.json")
    for name, out in (("no_t.csv", "a.csv"), (str(base / "readings.csv"), "b.csv")):
        assert main(["apply", cal, str(tmp_path / name), "--out", str(tmp_path / out),
                     "-q"]) == 0
    a = (tmp_path / "a.csv").read_text().splitlines()
    b = (tmp_path / "b.csv").read_text().splitlines()
    assert a[0] == b[0] == "t,ax_g,ay_g,az_g"
    assert all(r.startswith(",") for r in a[1:])
    model = json.loads((base / "outputs" / "pc.json").read_text())["model"]
    assert not any(model["drift_g_per_s"]) and not any(model["drift2_g_per_s2"])
    assert [r[1:] for r in a[1:]] == [r.split(",", 1)[1] for r in b[1:]]
