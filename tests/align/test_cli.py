"""The align command: JSON contract, exit codes, never overwriting, batch failures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from align.cli import main
from synth import write_synth
from tests.conftest import mark_image, real_folder


@pytest.fixture
def mark_file(tmp_path):
    s = mark_image(25.0, seed=4, size=(640, 480), length_px=350, with_crlb=False)
    p, _ = write_synth(s, tmp_path / "mark.png")
    return p, s.truth

FLAT = ("--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")
"""synth's lens-free renders, declared so (an undeclared lens is carried in u, and most
marks are then lens-limited: exit 2; see docs/camera.md)."""


def test_marks_json_contract(mark_file, tmp_path):
    p, truth = mark_file
    out = tmp_path / "out.json"
    assert main(["marks", str(p), "--json", str(out), "--plot", str(tmp_path / "plots"),
                 *FLAT]) == 0
    js = json.loads(out.read_text())
    m = js["marks"][0]
    for key in ("image", "found", "error", "angle_deg", "angle_u_deg", "offset_px", "effects",
                "unexplained_structure"):
        assert key in m
    assert m["found"] is True and m["error"] is None
    err = m["angle_deg"] - np.rad2deg(truth.marks[0].image_angle_rad)
    assert abs(err) < 4.5 * m["angle_u_deg"]
    assert list((tmp_path / "plots").glob("*.png"))


def test_batch_keeps_good_results_and_marks_failures(mark_file, tmp_path, capsys):
    p, _ = mark_file
    bad = tmp_path / "bad.png"
    bad.write_text("hello")
    out = tmp_path / "out.json"
    assert main(["marks", str(bad), str(p), "--json", str(out)]) == 2
    js = json.loads(out.read_text())["marks"]
    assert js[0]["found"] is False and "bad.png" in js[0]["error"]
    assert js[1]["found"] is True
    assert "bad.png" in capsys.readouterr().err


def test_never_overwrites(mark_file, tmp_path, capsys):
    p, _ = mark_file
    out = tmp_path / "exists.json"
    out.write_text("keep me")
    assert main(["marks", str(p), "--json", str(out)]) == 2
    assert out.read_text() == "keep me"
    assert main(["marks", str(p), "--json", str(p)]) == 2
    assert "refusing" in capsys.readouterr().err


def test_usage_errors_exit_2():
    assert main(["marks"]) == 2
    assert main(["camera", "x.png", "--pattern", "nine"]) == 2


def test_camera_calibration_on_real_chessboards(tmp_path):
    folder = real_folder("opencv-chessboard")
    out = tmp_path / "cam.json"
    imgs = sorted(str(p) for p in folder.glob("left0*.jpg"))
    assert main(["camera", *imgs, "--pattern", "9x6", "--json", str(out)]) == 0
    cam = json.loads(out.read_text())
    # The folder's README: fx ~ 538-542 px, k1 ~ -0.28 (barrel), RMS ~ 0.49 px.
    assert 520 < cam["camera_matrix"][0][0] < 560
    assert -0.35 < cam["dist_coeffs"][0] < -0.2
    assert cam["rms_px"] < 1.0


def test_camera_photos_skipped_are_warned_and_kept_apart_from_the_used(tmp_path, capsys):
    """A photograph of another size and one that is no image: each a WARNING on the terminal
    and in the JSON's warnings, listed in ``skipped`` with why, not among the ``inputs`` (the
    used ones); the file matches its schema and is read back as a camera model."""
    import cv2

    from align.contract import validate
    from imaging import CameraModel

    folder = real_folder("opencv-chessboard")
    big, junk = tmp_path / "big.png", tmp_path / "junk.png"
    g = cv2.imread(str(folder / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(big), cv2.resize(g, (1280, 960)))
    junk.write_text("not an image")
    used = [str(folder / f"left0{i}.jpg") for i in (2, 3, 4)]
    out = tmp_path / "cam.json"
    assert main(["camera", *used, str(big), str(junk), "--json", str(out)]) == 0
    err = capsys.readouterr().err
    doc = json.loads(out.read_text())
    validate(doc, "camera")
    assert doc["ok"] and doc["views"] == 3
    assert [s["file"] for s in doc["skipped"]] == [str(junk), str(big)]
    assert "1280x960" in doc["skipped"][1]["reason"]
    assert [i["path"] for i in doc["inputs"]] == used
    for name in (big, junk):
        assert any(str(name) in w for w in doc["warnings"]), doc["warnings"]
        assert f"WARNING: {name}: skipped" in err, err
    assert CameraModel.load(out).views == 3


def test_two_competing_marks_when_one_is_expected(tmp_path, capsys):
    from synth import ImageSpec, MarkSpec, render_marks

    spec = ImageSpec(marks=(MarkSpec(0.1, -100, 400, 4.0), MarkSpec(1.4, 120, 400, 4.0)),
                     width=640, height=480, seed=3)
    p, _ = write_synth(render_marks(spec, with_crlb=False), tmp_path / "two.png")
    assert main(["marks", str(p), *FLAT]) == 0  # several marks per image are normal...
    assert main(["marks", str(p), "--one"]) == 2  # ...unless the user says there is one
    assert "two competing marks" in capsys.readouterr().err


def test_sixteen_bit_tiff_through_the_cli(tmp_path):
    s = mark_image(-20.0, seed=9, size=(500, 400), length_px=300, bits=16, with_crlb=False)
    p, _ = write_synth(s, tmp_path / "m16.tif")
    out = tmp_path / "o.json"
    assert main(["marks", str(p), "--json", str(out), *FLAT]) == 0
    m = json.loads(out.read_text())["marks"][0]
    assert abs(m["angle_deg"] - np.rad2deg(s.truth.marks[0].image_angle_rad)) < (
        4.5 * m["angle_u_deg"])


def test_calibrate_and_tilt_contract(tmp_path):
    from synth.tumble import Triad, TumbleSpec, tumble, write_tumble_csv

    tr = Triad(noise_v=4.8e-5)
    d = tumble(TumbleSpec(triad=tr, seed=12))
    st = write_tumble_csv(d, tmp_path / "static.csv")
    ck = write_tumble_csv(d, tmp_path / "check.csv", check=True)
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(st), "--check", str(ck), "--scale-sign", "-", "--json",
                 str(out)]) == 0
    js = json.loads(out.read_text())
    for key in ("scale_factors_v_per_g", "beta_rad", "bias_g", "residual_rms_g", "effects",
                "check", "unexplained_structure"):
        assert key in js
    assert np.allclose(js["scale_factors_v_per_g"], tr.k, atol=2e-5)
    assert max(abs(c["dg_g"]) for c in js["check"]) < 3e-5
    tilt = tmp_path / "tilt.json"
    assert main(["tilt", str(ck), "--calibration", str(out), "--json", str(tilt)]) == 0
    assert json.loads(tilt.read_text())["samples"] > 0
    bad = tmp_path / "bad.csv"
    bad.write_text("pose,ux,uy\n1,2,3\n")
    assert main(["calibrate", str(bad)]) == 2
    assert main(["tilt", str(ck), "--calibration", str(bad)]) == 2
    assert main(["calibrate", str(st), "--scale-sign", "x"]) == 2
