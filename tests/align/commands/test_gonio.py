"""``align gonio -v``: what the pipeline decided, and a byte-based progress bar on stderr."""

from __future__ import annotations

import align.commands.common as common
from align.cli import main
from synth.gonio import GonioSpec, simulate, write_log


def test_verbose_says_what_each_step_decided_and_shows_a_bar(tmp_path, monkeypatch, capsys):
    log = write_log(simulate(GonioSpec(revolutions=150, seed=4)), tmp_path / "log.csv")
    monkeypatch.setattr(common, "BAR_BYTES", 0)  # a small log gets the bar too
    assert main(["gonio", str(log), "--faces", "ref,z,y,x", "-v"]) == 0
    err = capsys.readouterr().err
    assert "gonio log.csv: one pass in" in err and "revolutions excluded" in err
    assert "gonio: Earth rate from the loop:" in err
    assert "loop RevolutionStage: declared model" in err and "candidate earth_rate: p" in err
    assert "reading" in err and "B/s" in err  # tqdm's byte bar (unit B, scaled)


def test_no_bar_and_no_debug_at_normal_verbosity_off_a_terminal(tmp_path, monkeypatch,
                                                                capsys):
    log = write_log(simulate(GonioSpec(revolutions=150, seed=4)), tmp_path / "log.csv")
    monkeypatch.setattr(common, "BAR_BYTES", 0)
    assert main(["gonio", str(log), "--faces", "ref,z,y,x"]) == 0
    err = capsys.readouterr().err
    assert "one pass in" not in err and "reading" not in err
