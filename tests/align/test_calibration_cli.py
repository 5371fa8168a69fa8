"""``align calibrate`` on what real users bring: a phone's stream in m/s² without time, a
six-face session, named-array files; outputs that say what they are; refusals that list
what was found."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io as sio

from align.cli import build_parser, main
from synth.handheld import HandheldSpec, handheld
from synth.tumble import Triad, TumbleSpec, tumble, write_tumble_csv

G0 = 9.80665


def phone(seed: int = 11, n_poses: int = 30, k2=(0.0, 0.0, 0.0)):
    tr = Triad(k=(G0 * 1.01, G0 * 0.99, G0), bias=(0.01, -0.02, 0.03),
               beta=(0.002, -0.001, 0.003), noise_v=0.0, k2=k2, full_scale_v=1e6)
    return handheld(HandheldSpec(triad=tr, rate_hz=50.0, noise_g=2e-3, n_poses=n_poses,
                                 seed=seed))


def test_phone_stream_without_time(tmp_path, capsys):
    rec = phone()
    p = rec.write_csv(tmp_path / "phone.csv")
    out = tmp_path / "cal.json"
    plots = tmp_path / "plots"
    assert main(["calibrate", str(p), "--rate", "50", "--units", "m/s2", "--json", str(out),
                 "--plot", str(plots)]) == 0
    text = capsys.readouterr().out
    assert "30 static intervals found" in text
    assert "k_x [(m/s²)/g]" in text
    js = json.loads(out.read_text())
    assert js["scale_factor_unit"] == "(m/s²)/g"
    assert np.allclose(js["scale_factors_m_s2_per_g"], [G0 * 1.01, G0 * 0.99, G0], rtol=2e-3)
    assert len(js["static_intervals"]) == 30 and "mean" in js["static_intervals"][0]
    assert js["effects"] == [] and js["refused_effects"] == []
    assert {q.name for q in plots.glob("*.png")} >= {"calibration.png", "static_intervals.png"}


def test_effects_printed_per_axis(tmp_path, capsys):
    rec = phone(seed=3, n_poses=40, k2=(3e-3, 0.0, -2e-3))
    p = rec.write_csv(tmp_path / "phone.csv")
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(p), "--rate", "50", "--units", "m/s2", "--json",
                 str(out)]) == 0
    text = capsys.readouterr().out
    assert "added nonlinearity_k2" in text
    for ax in "xyz":
        assert f"nonlinearity_k2_{ax}:" in text
    eff = json.loads(out.read_text())["effects"][0]
    assert [c["axis"] for c in eff["components"]] == ["x", "y", "z"]


def test_too_few_poses_lists_every_interval(tmp_path, capsys):
    rec = phone(seed=5, n_poses=6)
    p = rec.write_csv(tmp_path / "few.csv")
    assert main(["calibrate", str(p), "--rate", "50"]) == 2
    err = capsys.readouterr().err
    assert "too few poses: 6 static intervals found" in err
    assert err.count("interval ") >= 6 and "mean" in err


def test_plane_is_blamed_on_geometry_with_the_list(tmp_path, capsys):
    t = np.arange(0, 60, 0.02)
    u = np.zeros((len(t), 3))
    ang = np.repeat(np.arange(12) * np.pi / 6, 250)[: len(t)]
    u[: len(ang), 0], u[: len(ang), 1] = np.cos(ang), np.sin(ang)
    u += np.random.default_rng(0).normal(0, 1e-3, u.shape)
    p = tmp_path / "plane.csv"
    np.savetxt(p, np.column_stack([t, u]), delimiter=",", header="t,ux,uy,uz", comments="")
    assert main(["calibrate", str(p)]) == 2
    err = capsys.readouterr().err
    assert "geometry" in err and "plane" in err and "interval 1:" in err


def test_six_faces_file(tmp_path, capsys):
    tr = Triad(noise_v=4.8e-5)
    d = tumble(TumbleSpec(triad=tr, poses="six", check_poses=0, seed=1))
    p = write_tumble_csv(d, tmp_path / "six.csv")
    text = p.read_text().splitlines()
    names = ["+x", "+y", "+z", "-x", "-y", "-z"]
    p2 = tmp_path / "six_labelled.csv"
    p2.write_text("\n".join([text[0]] + [",".join([names[int(r.split(",")[0])]]
                                                   + r.split(",")[1:]) for r in text[1:]]))
    out = tmp_path / "six.json"
    assert main(["calibrate", str(p2), "--scale-sign", "-", "--json", str(out)]) == 0
    assert "known-pose (six-position) method" in capsys.readouterr().out
    js = json.loads(out.read_text())
    assert js["method"] == "known-pose" and len(js["poses"]) == 6
    assert np.allclose(js["scale_factors_v_per_g"], tr.k, rtol=1e-3)
    assert js["known_pose"]["fixture_error_rad"] == pytest.approx(np.deg2rad(0.5))


def test_named_arrays_read(tmp_path):
    rec = phone(seed=7, n_poses=20)
    mat = tmp_path / "rec.mat"
    sio.savemat(mat, {"acc": rec.u, "time": rec.t})
    npz = tmp_path / "rec.npz"
    np.savez(npz, a=rec.u.T, ts=rec.t, other=np.zeros(4))
    csv = rec.write_csv(tmp_path / "rec.csv", with_time=True)
    outs = []
    for f, extra in ((mat, []), (npz, ["--columns", "u=a,t=ts"]), (csv, [])):
        o = tmp_path / (f.name + ".json")
        assert main(["calibrate", str(f), "--units", "m/s2", "--json", str(o), *extra]) == 0
        outs.append(json.loads(o.read_text())["scale_factors_m_s2_per_g"])
    # the same data saved differently give the same numbers
    assert np.allclose(outs[0], outs[2], rtol=1e-9) and np.allclose(outs[1], outs[2], rtol=1e-9)


def test_named_arrays_ambiguous_or_missing(tmp_path, capsys):
    p = tmp_path / "two.npz"
    np.savez(p, a=np.zeros((100, 3)), b=np.ones((100, 3)))
    assert main(["calibrate", str(p)]) == 2
    assert "several N x 3 arrays (a, b" in capsys.readouterr().err
    assert main(["calibrate", str(p), "--columns", "u=c"]) == 2
    assert "no variable 'c'" in capsys.readouterr().err


def test_help_shows_every_detection_default():
    sub = build_parser()._subparsers._group_actions[0].choices["calibrate"]
    text = sub.format_help()
    for flag, default in (("--window", "0.25"), ("--threshold", "3.0"), ("--min-static", "0.5"),
                          ("--margin", "0.1"), ("--split-sigma", "8.0"), ("--split-deg", "1.0"),
                          ("--fixture-error", "0.5")):
        i = text.index(f"\n  {flag}")  # the option's entry, not the usage line
        assert f"default: {default}" in " ".join(text[i:i + 400].split()), flag


def test_pose_means_without_pose_column(tmp_path, capsys):
    """A short ux,uy,uz file (160 poses in g, no time) is per-pose means; a long one is a
    recording that needs --rate."""
    from synth.tumble import pose_directions

    up = pose_directions("random", 160, np.random.default_rng(3))
    tr = Triad(k=(1.01, 0.99, 1.0), noise_v=0.0)
    u = tr.outputs(up, np.zeros(160), np.zeros(160), None)
    u = u + np.random.default_rng(4).normal(0, 1e-4, u.shape)
    p = tmp_path / "means.csv"
    np.savetxt(p, u, delimiter=",", header="ux,uy,uz", comments="")
    out = tmp_path / "m.json"
    assert main(["calibrate", str(p), "--units", "g", "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    assert len(js["poses"]) == 160 and js["noise_known"] is False
    assert np.allclose(js["scale_factors_g_per_g"], tr.k, rtol=1e-3)
    long = tmp_path / "long.csv"
    np.savetxt(long, np.repeat(u, 5, axis=0) + 1e-6 * np.arange(800)[:, None],
               delimiter=",", header="ux,uy,uz", comments="")
    assert main(["calibrate", str(long)]) == 2
    assert "800 rows and neither a pose column nor a time column" in capsys.readouterr().err


@pytest.mark.parametrize("given, signs", [("-", (-1.0,) * 3), ("+", (1.0,) * 3),
                                          ("-,-,-", (-1.0,) * 3), ("-,+,-", (-1.0, 1.0, -1.0)),
                                          ("+,-,+", (1.0, -1.0, 1.0))])
def test_scale_sign_as_the_help_writes_it(given, signs):
    from align.commands.args import attach_signs
    from align.commands.args import signs as parse_signs

    args = build_parser().parse_args(attach_signs(["calibrate", "s.csv", "--scale-sign",
                                                   given]))
    assert parse_signs(args.scale_sign) == signs


def test_scale_sign_of_two_axes_is_refused_naming_the_flag(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "s.csv"), "--scale-sign", "-,+"]) == 2
    err = capsys.readouterr().err
    assert "--scale-sign '-,+'" in err and len(err.strip().splitlines()) == 1


def test_a_warning_on_how_the_file_was_read_reaches_the_json(tmp_path, capsys):
    """Rows without pose or time are read as pose means: said once on the terminal and in
    the JSON's warnings (it was only logged)."""
    data = tumble(TumbleSpec(seed=3, check_poses=0))
    means = write_tumble_csv(data, tmp_path / "means.csv", per_sample=False)
    rows = [ln.split(",") for ln in means.read_text().splitlines()]
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(",".join(r[1:4]) for r in rows) + "\n")
    out = tmp_path / "cal.json"
    assert main(["calibrate", str(bare), "--json", str(out)]) == 0
    said = "no pose or time column: each row read as one pose's mean"
    assert capsys.readouterr().err.count(said) == 1
    assert sum(said in w for w in json.loads(out.read_text())["warnings"]) == 1


def test_microsecond_times_and_meta_lines_read_as_the_plain_file(tmp_path, capsys):
    """The phone's recording as a logger writes it — settings lines before the header, a
    plain 't' in µs — read with --time-unit us: the numbers of the plain file at --rate;
    the skipped lines said in the JSON's warnings. A header that says [ms] against
    --time-unit us is refused in one line naming file, line and flag."""
    plain = phone(n_poses=28).write_csv(tmp_path / "phone.csv")
    lines = plain.read_text().splitlines()
    logged = tmp_path / "logger.csv"
    logged.write_text("Fs,50\nLogging Type,0\nsensor,phone\n" + f"{lines[0]},t\n" + "\n".join(
        f"{ln},{k * 20000}" for k, ln in enumerate(lines[1:])) + "\n")
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["calibrate", str(plain), "--rate", "50", "--units", "m/s2", "-q",
                 "--json", str(a)]) == 0
    assert main(["calibrate", str(logged), "--time-unit", "us", "--units", "m/s2", "-q",
                 "--json", str(b)]) == 0
    ja, jb = json.loads(a.read_text()), json.loads(b.read_text())
    assert np.allclose(jb["scale_factors_m_s2_per_g"], ja["scale_factors_m_s2_per_g"],
                       rtol=1e-12, atol=0)
    assert any("3 line(s) before the header at line 4 skipped" in w for w in jb["warnings"])
    capsys.readouterr()
    said = tmp_path / "said.csv"
    said.write_text(logged.read_text().replace(",t\n", ",t [ms]\n", 1))
    assert main(["calibrate", str(said), "--time-unit", "us", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "said.csv:4: t: the header says [ms]" in err[0], err
    assert "--time-unit" in err[0]
