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


def _microsecond_log(log, path, header: str = "t"):
    """``log`` with its times [s] rewritten in µs under a plain ``t`` (the decimal point moved
    six places in the text: the same instants, no rounding)."""
    lines = log.read_text().splitlines()
    out = [lines[0].replace(",t", f",{header}")]
    for ln in lines[1:]:
        head, t = ln.rsplit(",", 1)
        whole, frac = t.split(".")
        out.append(f"{head},{int(whole + frac[:6])}.{frac[6:]}")
    path.write_text("\n".join(out) + "\n")
    return path


def test_microsecond_times_give_the_angles_of_seconds(tmp_path, capsys):
    """A logger's plain 't' in µs, read with --time-unit us: the angles, u and the loop's
    Earth rate of the same log in seconds (with and without --latitude: the times enter
    both the correction and the loop). Without the flag the µs read as seconds are warned of,
    naming the flag; a header that says [ms] against --time-unit us is refused in one line
    naming file, line and flag."""
    import json

    import numpy as np

    s = write_log(simulate(GonioSpec(revolutions=150, seed=4)), tmp_path / "s.csv")
    us = _microsecond_log(s, tmp_path / "us.csv")
    for lat in ([], ["--latitude", "50.45"]):
        got = []
        for log, extra in ((s, []), (us, ["--time-unit", "us"])):
            out = tmp_path / f"{log.stem}{len(lat)}.json"
            assert main(["gonio", str(log), "--faces", "ref,z,y,x", "-q", "--json", str(out),
                         *lat, *extra]) == 0
            got.append(json.loads(out.read_text()))
        a, b = got
        ua = np.array(a["angles_u_arcsec"])
        assert np.all(np.abs(np.subtract(a["angles_deg"], b["angles_deg"])) * 3600
                      <= 1e-6 * ua), (a["angles_deg"], b["angles_deg"])
        assert np.allclose(b["angles_u_arcsec"], ua, rtol=1e-6, atol=0)
        assert [e["name"] for e in a["effects"]] == [e["name"] for e in b["effects"]]
    capsys.readouterr()
    # Forgotten: the µs read as seconds (a face every 2.5e5 s) is warned of, naming the flag.
    forgot = tmp_path / "forgot.json"
    assert main(["gonio", str(us), "--faces", "ref,z,y,x", "-q", "--json", str(forgot)]) == 0
    err = capsys.readouterr().err
    assert "us.csv: t: median sample interval" in err and "--time-unit us" in err, err
    # ... and the warning reaches the JSON (every warning does), once on the terminal
    said_json = json.loads(forgot.read_text())["warnings"]
    assert [w for w in said_json if "median sample interval" in w and "--time-unit us" in w]
    assert err.count("median sample interval") == 1, err
    said = _microsecond_log(s, tmp_path / "said.csv", header="t [ms]")
    assert main(["gonio", str(said), "--faces", "ref,z,y,x", "--time-unit", "us", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "said.csv:1: t: the header says [ms]" in err[0], err
    assert "--time-unit" in err[0] and "Traceback" not in err[0]
