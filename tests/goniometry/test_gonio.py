"""Goniometry against synth truth: angles, uncertainty, faults, Earth rate, bad logs."""

from __future__ import annotations

import numpy as np
import pytest

from align.cli import main
from align.gonio import EARTH, loop_gonio
from axisbase.units import DEG
from goniometry import (
    LogError,
    earth_rate_counts,
    face_angles,
    kept_table,
    read_revolutions,
    vertical_earth_rate,
)
from synth.gonio import GonioSpec, simulate, write_log


def _log(tmp_path, name="log.csv", **kw):
    sim = simulate(GonioSpec(**kw))
    return write_log(sim, tmp_path / name), np.array(sim["truth"]["angles_rad"])


def test_normalised_errors_over_seeded_logs(tmp_path):
    z = []
    for seed in range(12):
        p, truth = _log(tmp_path, f"l{seed}.csv", revolutions=150, seed=seed)
        fa = face_angles(read_revolutions(p, 4))
        z.append((fa.angles_rad - truth) / fa.u_rad)
        # The stated uncertainty is the quantisation limit averaged over the revolutions.
        q = 2 * np.pi / fa.counts_per_rev
        assert np.all(fa.u_rad < 1.2 * q / np.sqrt(6) / np.sqrt(150) * 1.5)
    z = np.array(z).ravel()
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.4


def test_uncertainty_with_dithering_jitter_is_the_exact_one(tmp_path):
    """Jitter of 1 count dithers the quantisation: the pulse errors are independent, so the
    exact u of a mean is q sqrt(2 (sigma_j^2 + 1/12) / R) (the reference pulses' share
    telescopes). Batch means alone put u anywhere in 0.4-2.2 x it (8-16 blocks); the lag-1
    variance has ~R/3 degrees of freedom (u to ~10 %): no u below 0.7 x the exact one."""
    arcsec = np.pi / 180 / 3600
    z, r = [], []
    for seed in range(12):
        p, truth = _log(tmp_path, f"j{seed}.csv", revolutions=150, seed=seed,
                        jitter_rad=1.7 * arcsec)
        fa = face_angles(read_revolutions(p, 4))
        q = 2 * np.pi / fa.counts_per_rev
        exact = q * np.sqrt(2 * ((1.7 * arcsec / q) ** 2 + 1 / 12) / fa.revolutions)
        z.append((fa.angles_rad - truth) / fa.u_rad)
        r.append(fa.u_rad / exact)
    z, r = np.ravel(z), np.ravel(r)
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.3, z
    assert 0.85 < np.median(r) < 1.2 and r.min() > 0.7, r


def test_faults_are_repaired_or_excluded_and_reported(tmp_path):
    p, truth = _log(tmp_path, revolutions=2000, seed=2, p_missing=1e-3, p_spurious=1e-3,
                    failed_refs=3)
    s = read_revolutions(p, 4)
    reasons = " ".join(s.exclusions.counts)
    assert "spurious" in reasons and "missing" in reasons and "reference signal failed" in reasons
    fa = face_angles(s)
    assert 1900 < fa.revolutions < 2000
    assert np.all(np.abs(fa.angles_rad - truth) < 4.5 * fa.u_rad)


def test_locked_quantisation_is_not_averaged(tmp_path):
    # An integer count per revolution at the equator and a quiet autocollimator: the
    # quantisation phase repeats every revolution and must not be divided by sqrt(R).
    p, truth = _log(tmp_path, revolutions=300, latitude_deg=0.0, jitter_rad=0.0, seed=1)
    fa = face_angles(read_revolutions(p, 4))
    assert fa.quantisation_locked.all()
    assert np.all(np.abs(fa.angles_rad - truth) < 3 * fa.u_rad)


def test_earth_rate_with_unsteady_table(tmp_path):
    lat = 50.45
    p, truth = _log(tmp_path, revolutions=600, seed=3, ripple=0.02, wander=0.01,
                    latitude_deg=lat, latency_s=0.0)
    raw = face_angles(read_revolutions(p, 4))
    rate = vertical_earth_rate(lat * DEG, 1)
    fixed = face_angles(read_revolutions(p, 4, correct=lambda c, dt: earth_rate_counts(
        c, dt, rate)))
    assert np.max(np.abs(fixed.angles_rad - truth) / fixed.u_rad) < 4.5
    assert np.max(np.abs(raw.angles_rad - truth)) > np.max(np.abs(fixed.angles_rad - truth))
    # Latitude not given: the loop finds the rate from counts per revolution vs period.
    rep = loop_gonio(*kept_table(read_revolutions(p, 4)))
    e = {x.name: x for x in rep.effects}
    assert EARTH in e and abs(e[EARTH].estimate - rate) < 4.5 * e[EARTH].u


def test_bad_logs_name_the_line(tmp_path):
    p, _ = _log(tmp_path, revolutions=20, seed=0)
    lines = p.read_text().splitlines()
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines[:6] + ["12a,1,0,0.5"] + lines[7:]) + "\n")
    with pytest.raises(LogError, match=r"bad.csv:7: count: .12a. is not a number"):
        read_revolutions(bad, 4)
    trunc = tmp_path / "trunc.csv"
    trunc.write_text("\n".join(lines[:-1] + [lines[-1].split(",")[0]]) + "\n")
    with pytest.raises(LogError, match="truncated"):
        read_revolutions(trunc, 4)
    noref = tmp_path / "noref.csv"
    noref.write_text("count,counter,ref\n" + "\n".join(f"100,{1 + i % 2},0" for i in range(40)))
    with pytest.raises(LogError, match="no reference pulse"):
        read_revolutions(noref, 4)
    same = tmp_path / "same.csv"
    rows = [r.split(",") for r in lines[1:]]
    rows[9][1] = rows[8][1]  # counter does not alternate: a row lost from the log
    same.write_text(lines[0] + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    s = read_revolutions(same, 4)
    assert any("did not alternate" in k for k in s.exclusions.counts)


def test_gonio_command_contract(tmp_path):
    import json

    p, truth = _log(tmp_path, revolutions=100, seed=5)
    out = tmp_path / "g.json"
    assert main(["gonio", str(p), "--faces", "ref,z,y,x", "--nominal", "90,90,90,90",
                 "--latitude", "50.45", "--json", str(out)]) == 0
    js = json.loads(out.read_text())
    for key in ("faces", "angles_deg", "angles_u_arcsec", "revolutions_used", "effects"):
        assert key in js
    assert abs(sum(js["angles_deg"]) - 360) < 1e-9
    assert main(["gonio", str(p), "--faces", "a"]) == 2


@pytest.mark.slow
def test_loop_adds_nothing_to_fifty_clean_logs(tmp_path):
    false = 0
    for seed in range(50):
        p, _ = _log(tmp_path, f"c{seed}.csv", revolutions=300, seed=100 + seed)
        rep = loop_gonio(*kept_table(read_revolutions(p, 4)))
        false += bool(rep.effects)
    assert false <= 1


def test_too_short_logs_and_wrong_face_count_are_refused(tmp_path):
    """A log shorter than one revolution, one with fewer than 8 usable revolutions, and faces
    named in another number than the reference marks are apart: one LogError naming the file
    (never a traceback from deeper in the pipeline)."""
    from goniometry import FaceCountError

    p, _ = _log(tmp_path, revolutions=40, seed=0)
    lines = p.read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join(lines[:4]) + "\n")  # header + 3 rows
    with pytest.raises(LogError, match=r"short.csv: 3 rows, fewer than one revolution"):
        read_revolutions(short, 4)
    few = tmp_path / "few.csv"
    few.write_text("\n".join(lines[:1 + 4 * 5]) + "\n")  # ~5 revolutions
    with pytest.raises(LogError, match=r"few.csv: only \d usable revolutions .* at least 8"):
        read_revolutions(few, 4)
    for n in (3, 5):
        with pytest.raises(FaceCountError, match=rf"has 4 pulses per revolution.*{n} faces"):
            read_revolutions(p, n)
    assert read_revolutions(p, 4).stats.n >= 38


def test_arming_between_faces_is_a_lead_in_not_a_fault(tmp_path):
    """The counters armed by a pulse that is no face (the first row's count ends on face 0
    but starts elsewhere): that lead-in is not a revolution and not a listed fault."""
    p, _ = _log(tmp_path, revolutions=60, seed=4)
    lines = p.read_text().splitlines()
    cut = tmp_path / "lead_in.csv"
    # Drop the first revolution's rows up to (not including) its reference-marked row, and
    # shorten that row's count to 40 % of it: the arming pulse lies between two faces.
    first_ref = next(i for i, ln in enumerate(lines[1:], 1) if ln.split(",")[2] == "1")
    row = lines[first_ref].split(",")
    row[0] = str(int(int(row[0]) * 0.4))
    cut.write_text("\n".join([lines[0], ",".join(row), *lines[first_ref + 1:]]) + "\n")
    s = read_revolutions(cut, 4)
    assert not s.exclusions.counts, dict(s.exclusions.counts)
    assert s.incomplete_head == 1 and s.armed_face is None


@pytest.mark.parametrize("block, chunk", [(2 << 10, 1 << 10), (37 << 10, 5 << 10),
                                          (64 << 20, 1 << 19)])
def test_where_the_log_is_cut_changes_nothing(tmp_path, monkeypatch, block, chunk):
    """The parse blocks (parallel) and the pass's chunks fall anywhere — inside a revolution,
    on a fault, on a reference pulse: the same revolutions, faults with their lines, angles
    (to rounding) and u as one block read in one chunk."""
    import axisbase.csvblocks as csvblocks

    p, _ = _log(tmp_path, revolutions=1500, seed=5, p_missing=2e-3, p_spurious=2e-3,
                failed_refs=3, arm_face=2, stop_pulses=1)
    monkeypatch.setattr(csvblocks, "PARALLEL_BLOCK", 1 << 26)
    ref = read_revolutions(p, 4, block_bytes=1 << 26)
    fa_ref = face_angles(ref)
    monkeypatch.setattr(csvblocks, "PARALLEL_BLOCK", block)
    got = read_revolutions(p, 4, block_bytes=chunk)
    fa = face_angles(got)
    assert got.exclusions.counts == ref.exclusions.counts and got.exclusions.counts
    assert got.exclusions.lines == ref.exclusions.lines
    assert (got.rows, got.incomplete_head, got.incomplete_tail, got.armed_face) == (
        ref.rows, ref.incomplete_head, ref.incomplete_tail, ref.armed_face)
    assert fa.revolutions == fa_ref.revolutions
    assert np.allclose(fa.angles_rad, fa_ref.angles_rad, rtol=0, atol=1e-14)
    assert np.allclose(fa.u_rad, fa_ref.u_rad, rtol=1e-9, atol=0)


def test_the_loop_started_during_the_pass_is_the_loop_after_it(tmp_path, monkeypatch):
    """On a log longer than the loop's head (no latitude, with times), the loop runs on a
    thread while the rest is read: the same report as run on the kept head afterwards."""
    import threading

    import align.gonio as gonio
    from align.gonio import LOOP_REVOLUTIONS, measure_log

    where = []

    def recorded(*a, **k):
        where.append(threading.current_thread().name)
        return loop_gonio(*a, **k)

    monkeypatch.setattr(gonio, "loop_gonio", recorded)
    p, _ = _log(tmp_path, revolutions=LOOP_REVOLUTIONS + 300, seed=4)
    run = measure_log(p, 4)
    assert len(where) == 1 and where[0].startswith("loop"), where
    counts, dt, t_end = run.summary.stats.kept()
    m = LOOP_REVOLUTIONS
    after = loop_gonio(counts[:m], dt[:m], t_end[:m])
    assert run.loop.summary_lines() == after.summary_lines()
    assert run.loop.summary().to_dict() == after.summary().to_dict()


def test_stamp_resolution_is_the_grid_or_the_float_step():
    from goniometry.timing import stamp_resolution

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.2, 0.3, 500))
    assert stamp_resolution(np.round(t, 7)) == 1e-7  # a 10 MHz clock
    assert stamp_resolution(np.round(t, 3)) == 1e-3
    # Unix epoch seconds: float64 holds them to 2^-22 s, whatever was written
    assert stamp_resolution(np.round(1.7e9 + t, 7)) == np.spacing(1.7e9 + t.max())
    assert stamp_resolution(t) == np.spacing(t.max())  # full-precision stamps
    # near-whole seconds (reference pulses at 1 rev/s) are no 1 s grid
    assert stamp_resolution(np.round(np.arange(1, 300) + rng.normal(0, 1e-7, 299), 9)) == 1e-9
