"""``align camera``'s output says which lens model it chose and why (the terminal and the
JSON's ``lens_choice``), and what the model's own u leaves a typical mark (``field_u``,
warned beyond the lens bound); the document matches its schema (camera format 5) and reads
back with the carried k3."""

from __future__ import annotations

import json

import numpy as np

from align.camera_model_u import left_out_k3
from align.contract import validate
from align.documents import camera_document
from align.present import camera_lines
from imaging import CameraModel
from tests.imaging.test_camera_cov import D_T
from tests.imaging.test_camera_k3 import _calibrate


def test_the_document_names_the_model_chosen_and_the_field_u():
    cam = _calibrate(0, D_T)
    doc = json.loads(json.dumps(camera_document(cam, {}, ["b0.png"])))
    validate(doc, "camera")
    assert doc["format_version"] == 5
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
