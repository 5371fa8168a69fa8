"""``align run`` on the terminal: -q prints no session block (only warnings and errors), and
a failed stage is said once."""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration.arrays import MEANS_ROWS
from align.cli import main


@pytest.fixture
def failing(tmp_path):
    """A session whose calibration fails at once (a recording without times), so its fusion
    has nothing: two failed stages."""
    rows = np.random.default_rng(3).normal(size=(MEANS_ROWS + 1, 3))
    (tmp_path / "rec.csv").write_text("ux,uy,uz\n" + "\n".join(
        ",".join(f"{v:.6f}" for v in r) for r in rows) + "\n")
    (tmp_path / "session.toml").write_text('[calibration]\nstatic = "rec.csv"\n')
    return tmp_path


def test_quiet_prints_no_session_block_and_each_failure_once(failing, capsys):
    assert main(["run", str(failing), "-q"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""  # no session block, no verdict, no timings
    lines = cap.err.strip().splitlines()
    assert len(lines) == 2, lines  # the two failed stages, one warning each
    assert "stage calibration FAILED" in lines[0] and "[calibration] rate_hz" in lines[0]
    assert "stage fusion FAILED: no stage produced observations" in lines[1]


def test_a_failed_stage_is_said_once(failing, capsys):
    """On stderr as a warning (seen when stdout goes to a file), not again in the block."""
    assert main(["run", str(failing)]) == 2
    cap = capsys.readouterr()
    assert "session " in cap.out and "VERDICT: NOT MEASURED" in cap.out
    both = cap.out + cap.err
    assert both.count("stage calibration FAILED") == 1 and "stage calibration: FAILED" \
        not in both
    assert cap.err.count("WARNING: stage calibration FAILED") == 1


def test_verbose_logs_the_static_detection_settings_by_their_keys(tmp_path, capsys):
    t = np.arange(600) / 100
    walk = np.cumsum(np.random.default_rng(1).normal(0, 0.05, (600, 3)), 0)
    (tmp_path / "rec.csv").write_text("t,ux,uy,uz\n" + "\n".join(
        ",".join(f"{v:.6f}" for v in (ti, *w)) for ti, w in zip(t, walk, strict=True)))
    (tmp_path / "session.toml").write_text('[calibration]\nstatic = "rec.csv"\n'
                                           "threshold = 4.5\n")
    assert main(["run", str(tmp_path), "-v"]) == 2
    err = capsys.readouterr().err
    assert ("static detection: [calibration] window_s 0.25, [calibration] threshold 4.5, "
            "[calibration] min_static_s 0.5") in err
    assert "static below 4.5 x the noise" in err
    assert main(["calibrate", str(tmp_path / "rec.csv"), "--window", "0.5", "-v"]) == 2
    err = capsys.readouterr().err
    assert "static detection: --window 0.5, --threshold 3" in err
    assert "window 50 samples at 100 Hz" in err
