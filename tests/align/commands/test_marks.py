"""``align marks`` on the terminal: a failed image is said once (its error), not also as a
"not measured" warning; the JSON keeps the warning."""

from __future__ import annotations

import json

import numpy as np
from PIL import Image

from align.cli import main


def test_a_failed_image_prints_one_line(tmp_path, capsys):
    rng = np.random.default_rng(5)
    img = (128 + rng.normal(0, 2, (240, 320))).clip(0, 255).astype(np.uint8)  # no mark
    Image.fromarray(img).save(tmp_path / "blank.png")
    out = tmp_path / "m.json"
    assert main(["marks", str(tmp_path / "blank.png"), "--json", str(out)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if "blank.png" in ln]
    assert len(err) == 1 and "FAILED" in err[0], err
    assert any("blank.png: not measured" in w for w in json.loads(out.read_text())["warnings"])
