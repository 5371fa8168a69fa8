"""Two readings of one thing are not taken as two (issue 22, class 2, the goniometer's
cases): a counter log written twice, two different tables' logs concatenated, and a
``--reverse-log`` that turns the same way as the forward log (or is another table's) are
refused with one line naming the file and, in a log, the line — never measured (u/sqrt 2,
a mixture of two tables, or a direction-dependent part of arc-minutes "cancelled"). Their
valid neighbours are measured: long clean logs without times (steady or jittery), and a
real reversal."""

from __future__ import annotations

import numpy as np
import pytest

from align.errors import InputError
from align.gonio import measure_log
from axisbase.units import DEG
from goniometry import LogError
from synth.gonio import ARCSEC, GonioSpec, simulate, write_log

N_FACES = 4


def _log(tmp_path, name: str, **kw):
    spec = GonioSpec(**{"revolutions": 150, **kw})
    return write_log(simulate(spec), tmp_path / f"{name}.csv")


def _lines(path) -> list[str]:
    return path.read_text().splitlines()


@pytest.mark.parametrize("with_time", [True, False])
def test_a_log_written_twice_is_refused_naming_the_line(tmp_path, with_time):
    p = _log(tmp_path, "once", seed=1, with_time=with_time)
    rows = _lines(p)
    q = tmp_path / "twice.csv"
    q.write_text("\n".join(rows + rows[1:]) + "\n")
    first_copy_line = len(rows) + 1
    with pytest.raises(LogError) as e:
        measure_log(q, N_FACES, 50.45 * DEG)
    msg = str(e.value)
    assert f"twice.csv:{first_copy_line}:" in msg, msg
    assert "repeat" in msg
    if with_time:  # (streamed: the copy's start, from the first row again)
        assert f"lines {first_copy_line}- repeat lines 2- exactly" in msg, msg
        assert "written twice? keep one copy" in msg, msg


@pytest.mark.parametrize("with_time", [True, False])
def test_two_tables_logs_concatenated_are_refused_naming_the_line(tmp_path, with_time):
    a = _lines(_log(tmp_path, "a", seed=1, with_time=with_time))
    b = _lines(_log(tmp_path, "b", seed=2, with_time=with_time,
                    face_offsets_rad=(40 * ARCSEC, -100 * ARCSEC, 20 * ARCSEC)))
    if with_time:  # the second log's times continue the first's (one interval later)
        t_end = float(a[-1].split(",")[3])
        dt = float(b[2].split(",")[3]) - float(b[1].split(",")[3])
        b = [b[0]] + [",".join([*r.split(",")[:3], f"{float(r.split(',')[3]) + t_end + dt:.9f}"])
                      for r in b[1:]]
    q = tmp_path / "two.csv"
    q.write_text("\n".join(a + b[1:]) + "\n")
    with pytest.raises(LogError) as e:
        measure_log(q, N_FACES, 50.45 * DEG)
    msg = str(e.value)
    assert "face pattern changes" in msg, msg
    line = int(msg.split("two.csv:")[1].split(":")[0])
    assert len(a) + 1 <= line <= len(a) + 1 + 2 * N_FACES, (line, len(a) + 1)


def test_a_reverse_log_turning_the_same_way_is_refused(tmp_path):
    fwd = _log(tmp_path, "f", seed=1, ripple=0.02)
    same = _log(tmp_path, "s", seed=5, ripple=0.02)
    other = _log(tmp_path, "o", seed=7, direction=-1,
                 face_offsets_rad=(30 * ARCSEC, -220 * ARCSEC, 95 * ARCSEC))
    with pytest.raises(InputError, match="turned the same way"):
        measure_log(fwd, N_FACES, 50.45 * DEG, reverse_log=same)
    with pytest.raises(InputError, match="not a run in the other direction"):
        measure_log(fwd, N_FACES, 50.45 * DEG, reverse_log=other)


def test_a_real_reversal_is_combined(tmp_path):
    """The other direction, a 2 % speed ripple and 5 us latency (a significant
    direction-dependent part of a fraction of an arc-second): combined, within 4 u."""
    spec = GonioSpec(revolutions=150, seed=1, ripple=0.02)
    fwd = write_log(simulate(spec), tmp_path / "f.csv")
    rev = _log(tmp_path, "r", seed=6, direction=-1, ripple=0.02)
    run = measure_log(fwd, N_FACES, 50.45 * DEG, reverse_log=rev)
    truth = np.array(simulate(spec)["truth"]["angles_rad"])
    assert np.max(np.abs(run.angles.angles_rad - truth) / run.angles.u_rad) < 4.0


@pytest.mark.parametrize("jitter", [0.0, 0.02, 0.1])
def test_long_clean_logs_without_times_are_not_taken_for_copies(tmp_path, jitter):
    """20 000 revolutions without times at the equator (no Earth rate: with a whole number
    of counts a revolution and no jitter, every revolution alike) and at 50 deg."""
    for lat in (0.0, 50.45):
        p = _log(tmp_path, f"l{jitter}_{lat}", revolutions=20000, seed=3, with_time=False,
                 jitter_rad=jitter * ARCSEC, latitude_deg=lat)
        run = measure_log(p, N_FACES)
        assert run.summary.stats.n > 19000


def _revolutions_measured(tmp_path, logs: int) -> np.ndarray:
    """Revolutions measured in each of ``logs`` steady 120-revolution logs without times."""
    n = []
    for seed in range(logs):
        p = _log(tmp_path, f"c{seed}", revolutions=120, seed=100 + seed, with_time=False,
                 rev_per_s=float(np.random.default_rng(seed).uniform(0.2, 5.0)))
        n.append(measure_log(p, N_FACES).summary.stats.n)
    return np.array(n)


def test_short_steady_logs_without_times_repeating_by_chance_are_measured(tmp_path):
    """A steady table's counts come back count for count after a near-period (29 of 120
    revolutions was seen): such 120-revolution logs without times are measured, not refused
    as a log written twice."""
    assert np.all(_revolutions_measured(tmp_path, 10) >= 110)


@pytest.mark.slow
def test_many_short_steady_logs_without_times_are_measured(tmp_path):
    n = _revolutions_measured(tmp_path, 300)
    assert np.all(n >= 110), np.flatnonzero(n < 110)
