"""The shipped JSON Schemas are strict: every key a command writes is described, and a key
they do not describe is refused (``unevaluatedProperties: false`` at the top, where the
envelope composes by ``allOf``/``$ref``; ``additionalProperties: false`` on fixed nested
objects). A field added to a result without its schema (and docs/generated/schemas.md) fails
here."""

from __future__ import annotations

import copy
import glob
import json
import shutil

import jsonschema
import pytest

from align.cli import main
from align.contract import validate
from tests.conftest import real_folder

# A nested object of fixed keys in each document, to show the strictness bites below the
# top level too: (kind, path to the object; an int indexes a list).
NESTED = {"marks": ("marks", 0), "camera": ("lens_choice",), "calibration": ("model",),
          "tilt": None, "gonio": ("allan",), "session": ("stages", "marks", 0),
          "platform-calibration": ("model",), "lot": ("units", 0), "plan": ("options", 0)}


def _nested(d: dict, path: tuple) -> dict:
    for p in path:
        d = d[p]
    return d


@pytest.mark.slow
def test_every_command_writes_what_its_strict_schema_describes(tmp_path):
    demo = tmp_path / "demo"
    assert main(["demo", "--out", str(demo), "-q"]) == 0  # 'align run' inside: result, pc
    s, o = demo / "session", tmp_path / "o"
    (tmp_path / "lot").mkdir()
    for name in ("a", "b"):  # one unit twice: the lot's duplicates are written too
        shutil.copy(demo / "result.json", tmp_path / "lot" / f"{name}.json")
    boards = sorted(glob.glob(str(real_folder("opencv-chessboard") / "left0*.jpg")))[:4]
    o.mkdir()
    runs = {
        "marks": ["marks", *sorted(str(p) for p in s.glob("*.png"))[:2]],
        "camera": ["camera", *boards, "--pattern", "9x6"],
        "calibration": ["calibrate", str(s / "tumble.csv")],
        "tilt": ["tilt", str(s / "platform.csv"), "--calibration",
                 str(demo / "platform_calibration.json")],
        "gonio": ["gonio", str(s / "gonio.csv"), "--faces", "ref,y,x,z"],
        "lot": ["lot", str(tmp_path / "lot")],
        "plan": ["plan", str(demo / "result.json")]}
    docs = {"session": demo / "result.json", "platform-calibration":
            demo / "platform_calibration.json"}
    for kind, args in runs.items():
        docs[kind] = o / f"{kind}.json"
        assert main([*args, "--json", str(docs[kind]), "-q"]) == 0, kind
    assert set(docs) == set(NESTED)
    for kind, path in docs.items():
        d = json.loads(path.read_text(encoding="utf-8"))
        validate(d, kind)
        with pytest.raises(jsonschema.ValidationError, match="trial"):
            validate(dict(d, trial=1), kind)  # an unknown key at the top
        if NESTED[kind] is not None:
            bad = copy.deepcopy(d)
            _nested(bad, NESTED[kind])["trial"] = 1
            with pytest.raises(jsonschema.ValidationError, match="trial"):
                validate(bad, kind)
