"""'align check': every problem of a session at once (keys, files, table headers and units,
images), one line each naming the file and key, exit 2; a ready session in well under a
second; and the round trip 'align init' -> fill in -> 'align check' -> 'align run'."""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from align.cli import main
from align.session.check import check_session
from synth.session import SessionSpec, write_session

DATA = ("tumble.csv", "gonio.csv", "platform.csv", "x_A.png", "z_A.png", "x_Ar.png",
        "z_Ar.png", "y_B.png", "z_B.png", "y_Br.png", "z_Br.png")


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    """A small synthetic session (the instruments of the standard layout) with its truth."""
    folder = tmp_path_factory.mktemp("chk") / "syn"
    write_session(folder, SessionSpec(seed=8, image_size=(320, 240), mark_length_px=200,
                                      revolutions=40, samples_per_pose=60))
    return folder


@pytest.mark.slow
def test_init_fill_in_check_run(synthetic, tmp_path, capsys):
    folder = tmp_path / "mine"
    assert main(["init", str(folder), "--cameras", "A,B", "--gonio", "--tumble",
                 "--static"]) == 0
    toml = folder / "session.toml"
    assert toml.is_file() and "FILL IN" in toml.read_text()
    capsys.readouterr()
    # Nothing filled in yet: every missing file and placeholder, all at once.
    assert main(["check", str(folder)]) == 2
    out = capsys.readouterr().out.splitlines()
    missing = [x for x in out if x.endswith(": no such file")]
    assert len(missing) == len(DATA) and all(f"'{name}'" in " ".join(missing) for name in DATA)
    assert sum("not filled in" in x for x in out) == 2  # serial, operator
    assert out[-1] == f"{folder}: {len(DATA) + 2} problem(s)"
    # The user puts the files in and fills in what only they know.
    for name in DATA:
        shutil.copy(synthetic / name, folder)
    text = toml.read_text()
    for old, new in [('serial = "FILL IN"', 'serial = "SN-RT-1"'),
                     ('operator = "FILL IN"', 'operator = "kim"'),
                     ('scale_sign = "+"', 'scale_sign = "-"'),
                     ("# latitude_deg = 50.45", "latitude_deg = 50.45")]:
        assert old in text
        text = text.replace(old, new, 1)
    # and switches the template's [tolerance] on, as written there
    tol = text[text.index("# [tolerance]"):]
    text = text.replace(tol, re.sub(r"^# ", "", tol, flags=re.M))
    toml.write_text(text)
    assert main(["check", str(folder)]) == 0
    assert capsys.readouterr().out.strip() == f"{folder}: ready to run"
    res, page = tmp_path / "r.json", tmp_path / "r.html"
    # The cameras were never calibrated and nothing is said of their lenses: camera B's
    # off-centre marks are lens-limited, so the result is not ok (exit 2), saying which and
    # what to do; the user knows their lenses are distortion-free and says so, as the
    # template shows (all lens ranges 0), and runs again.
    assert main(["run", str(folder), "--json", str(res), "--report", str(page), "-q"]) == 2
    d = json.loads(res.read_text())
    assert not d["ok"] and any("lens-limited" in p for p in d["problems"]), d["problems"]
    assert "NOT OK" in capsys.readouterr().err
    text = re.sub(r"^# (lens_(k1|k2|p|aspect|pp_px)) = [0-9.]+", r"\1 = 0.0",
                  toml.read_text(), flags=re.M)
    toml.write_text(text)
    assert main(["run", str(folder), "--json", str(res), "--report", str(page), "-q",
                 "--force"]) == 0
    d = json.loads(res.read_text())
    assert d["ok"] and d["metadata"]["serial"] == "SN-RT-1"
    # the verdict against the template's tolerance heads the report, as the JSON has it
    verdict = d["disposition"]["verdict"]
    assert verdict in ("PASS", "FAIL", "INCONCLUSIVE") and d["disposition"]["rule"] == "guarded"
    html = page.read_text()
    assert f'<span class="verdict">{verdict}</span>' in html and "SN-RT-1" in html
    truth = np.array(json.loads((synthetic / "truth.json").read_text())["misalignment_rad"])
    E, U = np.array(d["misalignment_rad"]), np.array(d["misalignment_u_rad"])
    off = ~np.eye(3, dtype=bool)
    assert np.all(np.abs(E - truth)[off] < 4.5 * U[off])
    # init never overwrites a session.toml unless told
    assert main(["init", str(folder), "--gonio"]) == 2
    assert "exists" in capsys.readouterr().err
    assert "SN-RT-1" in toml.read_text()


def test_every_problem_at_once(synthetic, tmp_path, capsys):
    folder = tmp_path / "bad"
    shutil.copytree(synthetic, folder)
    toml = folder / "session.toml"
    text = toml.read_text()
    for old, new in [('housing = "y"', 'housing = "w"'),         # a value out of its set
                     ('log = "gonio.csv"', 'log = "gonio2.csv"'),  # a missing file
                     ('direction = "ccw"', 'directon = "ccw"'),    # a misspelt key
                     ("latitude_deg = 50.45", "latitude_deg = 95.0")]:
        assert old in text
        text = text.replace(old, new, 1)
    toml.write_text(text)
    (folder / "x_A.png").write_text("not an image")
    tumble = folder / "tumble.csv"
    lines = tumble.read_text().splitlines()
    head = next(i for i, x in enumerate(lines) if x.strip() and not x.startswith("#"))
    lines[head] = lines[head].replace("uz", "u_z_typo")
    tumble.write_text("\n".join(lines) + "\n")
    problems = check_session(folder)
    src = str(toml)
    assert all(p.startswith(f"{src}: ") for p in problems), problems
    expect = ["[[images]] #5 housing: 'w' is not one of",
              "[goniometer] log = 'gonio2.csv': no such file",
              "[goniometer]: unknown key(s) directon",
              "latitude_deg: 95.0 is greater than the maximum of 90",
              "[[images]] #1 file = 'x_A.png': not an image",
              "[calibration] static = 'tumble.csv': ", "lacks uz"]
    for e in expect:
        assert any(e in p for p in problems), (e, problems)
    assert len(problems) == 6, problems  # one line each, none said twice
    assert main(["check", str(folder), str(synthetic)]) == 2
    out = capsys.readouterr().out
    assert f"{folder}: 6 problem(s)" in out and f"{synthetic}: ready to run" in out


def test_what_only_the_keys_together_say_is_reported(synthetic, tmp_path):
    folder = tmp_path / "contra"
    shutil.copytree(synthetic, folder)
    toml = folder / "session.toml"
    toml.write_text(toml.read_text().replace('nominal = "horizontal"', 'nominal = "vertical"',
                                             1))
    problems = check_session(folder)
    assert len(problems) == 1 and "contradictory nominal orientation" in problems[0]


def test_a_ready_session_is_checked_in_well_under_a_second(synthetic):
    assert check_session(synthetic) == []  # imports made
    t = time.perf_counter()
    assert check_session(synthetic) == []
    assert time.perf_counter() - t < 1.0


def test_no_session_toml_or_not_toml(tmp_path):
    assert "no such file" in check_session(tmp_path)[0]
    (tmp_path / "session.toml").write_text("[calibration\n")
    p = check_session(tmp_path)
    assert len(p) == 1 and "not valid TOML" in p[0]


@pytest.mark.parametrize("keys", [["lens_k1 = 0.1"], ["lens_p = 0.0", "lens_pp_px = 5.0"]])
def test_a_camera_model_beside_lens_ranges_is_refused_naming_both(synthetic, tmp_path, keys):
    """A camera model *is* the lens: lens_ ranges given beside it would be silently ignored."""
    folder = tmp_path / "both"
    shutil.copytree(synthetic, folder)
    (folder / "camA.json").write_text(json.dumps(
        {"camera_matrix": [[800, 0, 160], [0, 800, 120], [0, 0, 1]],
         "dist_coeffs": [0.0] * 5, "image_size": [320, 240]}))
    toml = folder / "session.toml"
    text = toml.read_text()
    head, rest = text.split("[cameras.A]\n", 1)
    own, tail = rest.split("\n\n", 1)  # camera A's own lines, up to the blank line
    kept = [x for x in own.splitlines() if not x.startswith("lens_")]
    toml.write_text(head + "[cameras.A]\n" + "\n".join([*kept, 'model = "camA.json"',
                                                          "lens_max_u_arcsec = 30.0"])
                    + "\n\n" + tail)
    assert check_session(folder) == []  # the model alone (and its bound on u) is ready
    toml.write_text(toml.read_text().replace('model = "camA.json"\n',
                                             'model = "camA.json"\n' + "\n".join(keys) + "\n"))
    problems = check_session(folder)
    assert len(problems) == 1, problems
    p = problems[0]
    assert "[cameras.A] model = 'camA.json'" in p and "\n" not in p
    assert all(k.split(" =")[0] in p for k in keys), p


def test_a_camera_model_of_two_cameras_is_a_problem(synthetic, tmp_path):
    """A camera file whose views the one-camera check split (issue 18): align check names
    it, as align run records it as that camera's error."""
    folder = tmp_path / "two"
    shutil.copytree(synthetic, folder)
    split = {"tested": True, "one_camera": False, "W": 50.0, "p": 1e-8, "alpha": 0.01,
             "parameters": ["fx", "cx", "cy"], "groups": [["l1", "l2", "l3"], ["r1", "r2", "r3"]],
             "group_values": [[800.0, 160.0, 120.0], [801.0, 170.0, 130.0]]}
    (folder / "camA.json").write_text(json.dumps(
        {"camera_matrix": [[800, 0, 160], [0, 800, 120], [0, 0, 1]],
         "dist_coeffs": [0.0] * 5, "image_size": [320, 240], "views_one_camera": split}))
    toml = folder / "session.toml"
    head, rest = toml.read_text().split("[cameras.A]\n", 1)
    own, tail = rest.split("\n\n", 1)
    kept = [x for x in own.splitlines() if not x.startswith("lens_")]
    toml.write_text(head + "[cameras.A]\n" + "\n".join([*kept, 'model = "camA.json"'])
                    + "\n\n" + tail)
    problems = check_session(folder)
    assert len(problems) == 1, problems
    assert "[cameras.A] model = 'camA.json'" in problems[0]
    assert "not of one camera" in problems[0] and "[l1 l2 l3] and [r1 r2 r3]" in problems[0]
