"""Readings declared in an acceleration unit must have a scale factor of about one g of that
unit per g: g declared as m/s² (or the reverse) is refused, a 10 % departure warned of."""

from __future__ import annotations

import json

import numpy as np
import pytest

from align.calibration import TriadModel
from align.calibration.units import UNIT_SCALE_WARN, unit_scale_check
from align.cli import main
from axisbase.errors import InputError
from axisbase.units import G0


def _model(k, beta=(0.0, 0.0, 0.0)):
    return TriadModel(np.asarray(k, float), np.asarray(beta, float), np.zeros(3))


@pytest.mark.parametrize(("units", "k", "needle"), [
    ("m/s2", 1.0, "look like g (give --units g)"),
    ("g", G0, "look like m/s² (give --units m/s2)"),
    ("g", -G0, "look like m/s²"),          # a negative triad: the magnitude counts
    ("g", 1000.0, "volts or counts"),
    ("m/s2", 1e-3 * G0, "volts or counts"),
])
def test_a_unit_the_scale_factors_contradict_is_refused(units, k, needle):
    with pytest.raises(InputError) as e:
        unit_scale_check(_model([k, k, k]), units, f"--units {units}")
    msg = str(e.value)
    assert msg.startswith(f"--units {units}:") and needle in msg
    assert f"{abs(k):.4g}" in msg


def test_realistic_triads_pass_and_volts_counts_are_not_checked():
    """Scale errors up to 5 % (beyond any datasheet's 1-3 %) and local gravity 9.78-9.83
    m/s²: never refused nor warned; V and counts carry no expectation."""
    rng = np.random.default_rng(0)
    for _ in range(500):
        k = 1 + rng.uniform(-0.05, 0.05, 3)
        g_local = rng.uniform(9.78, 9.835) / G0
        assert unit_scale_check(_model(k * g_local), "g", "--units g") == []
        assert unit_scale_check(_model(-k * g_local * G0, (0.01, -0.01, 0.02)), "m/s2",
                                "x") == []
    assert unit_scale_check(_model([G0, 1.0, 4096.0]), "counts", "--units") == []
    assert unit_scale_check(_model([1e-4, 1.0, 100.0]), "V", "--units") == []


def test_counts_read_as_the_default_volts_are_warned():
    """Counts left at the default unit V give thousands of "V"/g (the newcomer's 25,000):
    beyond V_PER_G_RANGE, a warning naming the unit's source and the key to declare it."""
    src = "tumble.csv: no unit in its header, the default V"
    w = unit_scale_check(_model([25000.0, 24800.0, 25300.0]), "V", src,
                         "[calibration] units")
    assert len(w) == 1 and src in w[0] and '[calibration] units = "counts"' in w[0]
    assert "2.5e+04" in w[0] and "0.0001–100 V/g" in w[0]
    w = unit_scale_check(_model([2e-5, 1.0, 1.0]), "V", "--units V")
    assert len(w) == 1 and "--units counts" in w[0]


def test_a_wrong_factor_short_of_another_unit_is_warned():
    w = unit_scale_check(_model([1.0, 2.0, 1.0]), "g", "u.csv: header unit [g]")
    assert len(w) == 1 and "k_y = 2 g/g" in w[0] and "u.csv: header unit [g]" in w[0]
    assert unit_scale_check(_model([1 + 0.9 * UNIT_SCALE_WARN] * 3), "g", "x") == []


def _pose_file(path, scale, header="pose,ux,uy,uz"):
    rng = np.random.default_rng(7)
    d = rng.normal(size=(16, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rows = [f"P{i}," + ",".join(f"{v:.9f}" for v in r)
            for i, m in enumerate(d) for r in m * scale + rng.normal(0, 2e-5 * scale, (10, 3))]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")


def test_cli_refuses_in_one_line_naming_the_flag_or_header(tmp_path, capsys):
    f = tmp_path / "g.csv"
    _pose_file(f, 1.0)
    out = tmp_path / "c.json"
    assert main(["calibrate", str(f), "--units", "m/s2", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--units m/s2" in err[0] and "give --units g" in err[0]
    assert not out.exists()
    h = tmp_path / "h.csv"
    _pose_file(h, G0, "pose,ux [g],uy [g],uz [g]")
    assert main(["calibrate", str(h), "--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{h}: header unit [g]" in err and "give --units m/s2" in err
    # the right unit: accepted, scale factor ~ g0, no unit warning
    m = tmp_path / "m.csv"
    _pose_file(m, G0)
    assert main(["calibrate", str(m), "--units", "m/s2", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert np.allclose(d["scale_factors_m_s2_per_g"], G0, rtol=1e-4)
    assert not any("unit" in w for w in d["warnings"])


def test_a_session_is_told_its_key_not_the_flag(tmp_path):
    """``[calibration] units = "m/s2"`` on readings in g: the hint names the key."""
    from align.session import load_session, run_session

    _pose_file(tmp_path / "g.csv", 1.0)
    (tmp_path / "session.toml").write_text('[calibration]\nstatic = "g.csv"\n'
                                           'units = "m/s2"\n')
    err = run_session(load_session(tmp_path)).errors[0]
    assert err.stage == "calibration" and err.message.startswith("[calibration] units: ")
    assert 'give [calibration] units = "g"' in err.message and "--" not in err.message
