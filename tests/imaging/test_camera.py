"""The camera file loader (:meth:`imaging.CameraModel.load`): bad tables named by key."""

from __future__ import annotations

import json

import pytest

from imaging import CameraModel, ImageInputError

GOOD = {"camera_matrix": [[800, 0, 320], [0, 800, 240], [0, 0, 1]],
        "dist_coeffs": [0.1, 0, 0, 0, 0], "image_size": [640, 480],
        "u": {"fx": 0.5, "k1": 1e-3}, "per_view_rms_px": {"a.png": 0.2}}


def _write(tmp_path, **change) -> str:
    f = tmp_path / "cam.json"
    f.write_text(json.dumps({**GOOD, **change}))
    return str(f)


def test_a_good_file_loads_its_u(tmp_path):
    m = CameraModel.load(_write(tmp_path))
    assert m.u == {"fx": 0.5, "k1": 1e-3}
    assert CameraModel.load(_write(tmp_path, u={"k1": None})).u["k1"] != 0  # null: NaN


@pytest.mark.parametrize(("table", "value", "says"), [
    ("u", {"fx": 0.5, "k1": "abc"}, r"'u\.k1' is \"abc\", not a number"),
    ("u", {"k2": True}, r"'u\.k2' is true, not a number"),
    ("u", {"cx": -0.3}, r"'u\.cx' is -0\.3: an uncertainty is >= 0"),
    ("u_formal", {"p1": [1, 2]}, r"'u_formal\.p1' is \[1, 2\], not a number"),
    ("u", [0.1, 0.2], r"'u' is not a table"),
    ("per_view_rms_px", {"a.png": "x"}, r"'per_view_rms_px\.a\.png'"),
])
def test_a_bad_table_entry_names_file_and_key(tmp_path, table, value, says):
    f = _write(tmp_path, **{table: value})
    with pytest.raises(ImageInputError, match=says) as e:
        CameraModel.load(f)
    assert str(e.value).startswith(f) and "\n" not in str(e.value)


def test_files_that_are_not_camera_json_are_named_for_what_they_are(tmp_path):
    """OpenCV's own FileStorage files (YAML, XML) and binary files given as a camera model:
    one line naming what the file is and what to give instead, not a JSON parser's words."""
    yml = tmp_path / "cam.yml"
    yml.write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n")
    xml = tmp_path / "cam.xml"
    xml.write_text('<?xml version="1.0"?>\n<opencv_storage>\n<camera_matrix/>\n'
                   "</opencv_storage>\n")
    png = tmp_path / "cam.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    for f, words in ((yml, "an OpenCV FileStorage YAML file"),
                     (xml, "an OpenCV FileStorage XML file"), (png, "binary data, not text")):
        with pytest.raises(ImageInputError, match=rf"{f.name}: not a camera file: {words}"):
            CameraModel.load(f)
    broken = tmp_path / "broken.json"
    broken.write_text('{"camera_matrix": [[1, 0, 0]],\n')
    with pytest.raises(ImageInputError, match=r"not JSON \(.* at line 2, column 1\)"):
        CameraModel.load(broken)
