"""A platform calibration carries whether the session it came from was ok; ``align apply``
and ``align tilt`` warn (terminal; tilt's JSON too) and exit 2 on one that was not."""

from __future__ import annotations

import json

import numpy as np

from align.apply import PlatformCalibration
from align.calibration import TriadModel
from align.cli import main


def _files(tmp_path, not_ok: tuple[str, ...]):
    m = TriadModel(np.array([2.0, -1.5, 1.8]), np.array([1e-4, -2e-4, 3e-4]),
                   np.array([1e-3, -2e-3, 5e-4]))
    pc = PlatformCalibration(m, np.full(6, 1e-4), np.eye(6) * 1e-12, not_ok)
    cal = tmp_path / f"cal{len(not_ok)}.json"
    cal.write_text(json.dumps(pc.document("V", {}, [])))
    rd = tmp_path / "r.csv"
    rd.write_text("ux,uy,uz\n0.01,0.02,1.8\n0.02,0.01,1.81\n")
    return cal, rd


def test_a_calibration_from_a_not_ok_session_is_warned_and_exits_2(tmp_path, capsys):
    why = ("fusion: the instruments disagree beyond their uncertainties",)
    cal, rd = _files(tmp_path, why)
    loaded = PlatformCalibration.load(cal)
    assert loaded.not_ok == why
    d = json.loads(cal.read_text())
    assert d["source_ok"] is False and d["source_problems"] == list(why)
    assert main(["apply", str(cal), str(rd), "--out", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert "NOT OK" in err and why[0] in err
    assert (tmp_path / "o.csv").exists()  # written, and said not to be trusted

    js = tmp_path / "t.json"
    assert main(["tilt", str(rd), "--calibration", str(cal), "--json", str(js)]) == 2
    assert any("NOT OK" in w for w in json.loads(js.read_text())["warnings"])


def test_a_calibration_from_an_ok_session_applies_silently(tmp_path, capsys):
    cal, rd = _files(tmp_path, ())
    assert json.loads(cal.read_text())["source_ok"] is True
    assert main(["apply", str(cal), str(rd), "--out", str(tmp_path / "o.csv")]) == 0
    assert "NOT OK" not in capsys.readouterr().err
    d = json.loads(cal.read_text())
    del d["source_ok"], d["source_problems"]  # files written before the key: read as ok
    cal.write_text(json.dumps(d))
    assert PlatformCalibration.load(cal).not_ok == ()
