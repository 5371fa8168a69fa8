"""``align camera``'s output says which lens model it chose and why (the terminal and the
JSON's ``lens_choice``), and what the model's own u leaves a typical mark (``field_u``,
warned beyond the lens bound); the document matches its schema (camera format 5) and reads
back with the carried k3."""

from __future__ import annotations

import functools
import json
from dataclasses import replace

import numpy as np

from align.camera_model_u import left_out_k3
from align.contract import validate
from align.documents import camera_document
from align.present import camera_lines
from imaging import CameraModel
from tests.imaging.test_camera_cov import D_T
from tests.imaging.test_camera_k3 import _calibrate


@functools.cache
def _model() -> CameraModel:
    """7 views of the known lens D_T (the two tests share one calibration)."""
    return _calibrate(0, D_T)


def test_the_document_names_the_model_chosen_and_the_field_u():
    cam = _model()
    doc = json.loads(json.dumps(camera_document(cam, {}, ["b0.png"])))
    validate(doc, "camera")
    assert doc["format_version"] == 6
    assert doc["lens_choice"]["k3"] == "left out" and "do not determine k3" in \
        doc["lens_choice"]["why"]
    f = doc["field_u"]
    assert 0 < f["median_u_arcsec"] <= f["max_u_arcsec"] and f["marks"] >= 16
    lens_limited = [w for w in doc["warnings"] if "will be lens-limited" in w]
    assert bool(lens_limited) == (f["median_u_arcsec"] > 60.0), doc["warnings"]
    text = "\n".join(camera_lines(cam, f))
    assert "k3 left out" in text and "carried" in text and "median" in text
    back = CameraModel.from_dict(doc)
    w0, s0 = left_out_k3(cam)
    w1, s1 = left_out_k3(back)
    assert s1 == s0 and np.array_equal(w1, w0)
    np.testing.assert_array_equal(back.cov, cam.cov)


def test_a_format_4_file_still_reads_without_a_choice(tmp_path):
    """A camera file of format 4 (no ``lens_choice``: k3 as the file has it) loads as
    before; nothing is carried for it."""
    cam = _calibrate(1, D_T, views=5, k3="free")
    d = {k: v for k, v in cam.to_dict().items() if k != "lens_choice"}
    p = tmp_path / "cam4.json"
    p.write_text(json.dumps({"format": "axis-align/camera", "format_version": 4, **d}))
    back = CameraModel.load(p)
    assert back.lens_choice is None and left_out_k3(back) is None
    np.testing.assert_array_equal(back.cov, cam.cov)


def test_a_model_of_two_cameras_is_not_ok_and_marks_through_it_say_so(tmp_path, capsys):
    """A camera file whose views the one-camera check split (``views_one_camera``,
    imaging/camera_views.py) is ``ok: false`` with the NOT OK warning naming the groups; and
    ``align marks --camera`` with it repeats the warning, ``ok: false``, exit 2; the same
    model with its views passing says nothing of it."""
    import cv2

    from align.cli import main
    from tests.conftest import mark_image

    cam = _model()
    assert cam.views_one_camera["tested"] and cam.views_one_camera["one_camera"]
    split = {**cam.views_one_camera, "one_camera": False, "W": 50.0, "p": 1e-8,
             "groups": [["0", "1", "2"], ["3", "4", "5", "6"]],
             "group_values": [[533.0, 330.0, 240.0], [536.0, 340.0, 250.0]]}
    img = tmp_path / "m.png"
    cv2.imwrite(str(img), mark_image(30.0, 1, size=(640, 480), length_px=150).image)
    for model, ok in ((cam, True), (replace(cam, views_one_camera=split), False)):
        doc = json.loads(json.dumps(camera_document(model, {}, ["b0.png"])))
        validate(doc, "camera")
        said = [w for w in doc["warnings"] if "not of one camera" in w]
        assert doc["ok"] is ok and bool(said) is not ok, doc["warnings"]
        assert CameraModel.from_dict(doc).problems == said
    path, out = tmp_path / "cam.json", tmp_path / "marks.json"
    path.write_text(json.dumps(doc))
    code = main(["marks", str(img), "--camera", str(path), "--json", str(out), "-q"])
    marks = json.loads(out.read_text())
    named = [w for w in marks["warnings"] if "not of one camera" in w]
    assert code == 2 and not marks["ok"] and named, marks["warnings"]
    assert all(m["found"] for m in marks["marks"])  # measured: not ok for the model alone
    assert "[0 1 2] and [3 4 5 6]" in named[0] and str(path) in named[0]
    assert "NOT OK: the views are not of one camera" in capsys.readouterr().err
