"""A table written twice (whole or in part), or a block pasted again, is refused in one line
naming both line ranges — on every table a user brings — and no clean table is: real
recordings (timed or not), quantised accelerometers at rest, stuck and periodic stretches."""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration import READINGS, STATIC, read_poses, read_readings
from align.calibration.arrays import read_arrays
from axisbase.errors import InputError
from axisbase.header import parse_column_map
from axisbase.repeats import COPY_BITS, COPY_ROWS, entropy_bits, find_copy, row_keys
from axisbase.table import read_table
from synth.tumble import Triad, TumbleSpec, recording
from tests.conftest import real_folder

MPU_HEAD = 5  # the MPU-6050 logger's four settings lines and its header


def _twice(src, dst, copy: slice | None = None, crlf: bool = False):
    """``(cat f; tail -n +HEAD+1 f)``: the rows again, no second header (``copy``: which)."""
    lines = src.read_text().splitlines()
    head, rows = lines[:MPU_HEAD], lines[MPU_HEAD:]
    end = "\r\n" if crlf else "\n"
    dst.write_text(end.join(head + rows + rows[copy or slice(None)]) + end, newline="")
    return dst, len(rows)


def test_the_real_mpu6050_recording_written_twice_is_refused_by_calibrate(tmp_path, capsys):
    """The lead's reproduction: read as 20 poses at u/sqrt 2, exit 0, before the rule."""
    from align.cli import main

    src = real_folder("mpu6050-tomisuarez") / "example_data_calibration.csv"
    twice, n = _twice(src, tmp_path / "twice.csv")
    code = main(["calibrate", str(twice), "--rate", "100", "--units", "counts"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    a, b = MPU_HEAD + n + 1, MPU_HEAD + 2 * n
    assert err[-1].endswith(f"twice.csv:{a}: lines {a}-{b} repeat lines {MPU_HEAD + 1}-"
                            f"{MPU_HEAD + n} exactly ({n} rows): the file was written twice? "
                            "keep one copy"), err
    assert not any("Traceback" in e for e in err)


@pytest.mark.parametrize("copy, crlf", [(slice(None), True), (slice(0, 1000), False)])
def test_partial_and_windows_copies_of_a_real_recording_are_refused(tmp_path, copy, crlf):
    src = real_folder("mpu6050-tomisuarez") / "imu_static_test.csv"
    twice, n = _twice(src, tmp_path / "twice.csv", copy, crlf)
    k = len(range(n)[copy])
    with pytest.raises(InputError, match=rf"lines {MPU_HEAD + n + 1}-{MPU_HEAD + n + k} "
                                         rf"repeat lines 6-{MPU_HEAD + k} exactly"):
        read_table(twice, STATIC, rate_hz=100.0)
    assert len(read_table(src, STATIC, rate_hz=100.0)) == n


def _real_tables(tmp_path):
    """(name, path, kwargs) of every real accelerometer table as the tool reads it, and each
    timed one again without its time (as a CSV in tmp_path: the harder case)."""
    mpu = real_folder("mpu6050-tomisuarez")
    out = [(p.name, p, {"rate_hz": 100.0}) for p in sorted(mpu.glob("*.csv"))]
    gyro = parse_column_map("ux=gx,uy=gy,uz=gz")
    out += [(f"{p.name} gyro", p, {"rate_hz": 100.0, "columns": gyro})
            for p in sorted(mpu.glob("*.csv"))]  # (quantised counts at rest, few counts wide)
    fer = real_folder("imucal-ferraris") / "example_ferraris_session.csv"
    out.append(("ferraris", fer, {"rate_hz": 102.4}))
    timed = []
    oa = real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv"
    for sensor in ("ADXL355", "BMI160"):
        cols = parse_column_map(",".join(f"u{a}=ACCEL_{sensor}_{i}"
                                         for i, a in enumerate("xyz")))
        timed.append((f"openaxes {sensor}", oa, {"columns": {**cols, "t": "time"},
                                                 "time_unit": "us"}))
    for name in ("xsens_acc.mat", "xsens_gyro.mat"):  # (whitespace text: t, three counts)
        p = tmp_path / f"{name}.csv"
        np.savetxt(p, np.loadtxt(real_folder("imu_tk-xsens") / name), fmt="%.9g",
                   delimiter=",", header="t,ux,uy,uz", comments="")
        timed.append((name, p, {}))
    for name, p, kw in timed:
        tab = read_table(p, STATIC, **kw)
        q = tmp_path / f"{name} untimed.csv"
        np.savetxt(q, np.column_stack([tab[c] for c in ("ux", "uy", "uz")]), fmt="%.17g",
                   delimiter=",", header="ux,uy,uz", comments="")
        out += [(name, p, kw), (f"{name} untimed", q, {"rate_hz": 100.0})]
    return out


def _read_and_copied(tmp_path, tables) -> list[str]:
    """Each table read whole (> 5000 rows), and its first third pasted again at its end
    refused naming both line ranges: what went otherwise, one line each."""
    bad = []
    for name, path, kw in tables:
        n = len(read_table(path, STATIC, **kw))
        if n <= 5000:
            bad.append(f"{name}: {n} rows read")
            continue
        lines = path.read_text().splitlines()
        head = MPU_HEAD if "mpu" in str(path) else 1
        q = tmp_path / "copy.csv"
        q.write_text("\n".join(lines + lines[head:head + n // 3]) + "\n")
        want = (f"lines {head + n + 1}-{head + n + n // 3} "
                f"repeat lines {head + 1}-{head + n // 3} ")
        try:
            read_table(q, STATIC, **kw)
            bad.append(f"{name}: its copy was read")
        except InputError as e:
            if want not in str(e):
                bad.append(f"{name}: {e}")
    return bad


def test_a_real_quantised_gyro_at_rest_is_no_copy_and_its_copy_is(tmp_path):
    """The MPU-6050's gyro at rest: raw counts a few counts wide, no time (the slow twin
    runs every real table)."""
    p = real_folder("mpu6050-tomisuarez") / "imu_static_test.csv"
    assert _read_and_copied(tmp_path, [("gyro", p, {
        "rate_hz": 100.0, "columns": parse_column_map("ux=gx,uy=gy,uz=gz")})]) == []


@pytest.mark.slow
def test_no_real_table_is_taken_for_a_copy_and_each_written_twice_is(tmp_path):
    """Every real recording (timed, and again without its time) is read as it is; the same
    written twice is refused naming the copy."""
    tables = _real_tables(tmp_path)
    assert len(tables) == 17
    assert _read_and_copied(tmp_path, tables) == []


def _counts(seed: int, lsb_v: float, rate_hz: float = 50.0):
    """A synthetic tumble recording (cube14, motion between) in quantised counts."""
    spec = TumbleSpec(Triad(lsb_v=lsb_v), rate_hz=rate_hz, dwell_s=4.0, move_s=2.0,
                      seed=seed)
    t, u, _ = recording(spec, vibration_g=0.02)
    return t, np.round(u / lsb_v).astype(np.int64)


def _save(path, t, u, with_time: bool):
    cols = [t, *u.T] if with_time else list(u.T)
    fmt = (["%.6f"] if with_time else []) + ["%d"] * 3
    np.savetxt(path, np.column_stack(cols), fmt=fmt, delimiter=",",
               header=("t," if with_time else "") + "ux,uy,uz", comments="")
    return path


def _clean_and_copies(tmp_path, seeds, lsbs=(2.4e-5, 1e-4, 1e-3)):
    """Refusals of clean recordings (must be none), copies missed although their rows carry
    the information the rule asks for (must be none), copies missed that carry less (the
    rule's stated limit: a stuck stretch copied is a stuck sensor's twin), copies tried:
    whole, partial, a block pasted again; with and without a time column."""
    false, missed, too_little, tried = [], [], [], 0
    for seed in seeds:
        for lsb in lsbs:
            t, u = _counts(seed, lsb)
            n = len(t)
            rng = np.random.default_rng(seed)
            k = int(rng.integers(COPY_ROWS, n // 2))
            a = int(rng.integers(0, n - k))
            for with_time in (False, True):
                kw = {} if with_time else {"rate_hz": 50.0}
                p = _save(tmp_path / f"c{seed}_{lsb}_{with_time}.csv", t, u, with_time)
                try:
                    read_table(p, STATIC, **kw)
                except InputError as e:
                    false.append((seed, lsb, with_time, str(e)))
                for name, copied, rows in (("whole", np.r_[0:n], np.r_[0:n, 0:n]),
                                           ("partial", np.r_[0:k], np.r_[0:n, 0:k]),
                                           ("block", np.r_[a:a + k], np.r_[0:a + k, a:n])):
                    q = _save(tmp_path / f"{name}{seed}_{lsb}_{with_time}.csv", t[rows],
                              u[rows], with_time)
                    tried += 1
                    try:
                        read_table(q, STATIC, **kw)
                    except InputError as e:
                        if "repeat lines" in str(e):
                            continue
                    bits = entropy_bits(row_keys(list(u[copied].T)))
                    enough = with_time or bits >= COPY_BITS + 2 * np.log2(len(rows))
                    (missed if enough else too_little).append((seed, lsb, with_time, name,
                                                               round(bits)))
    return false, missed, too_little, tried


def test_quantised_recordings_are_read_and_their_copies_refused(tmp_path):
    """Quantised counts (noise 0.24 LSB: a reading stuck at rest between flips): the clean
    recording read, every copy refused (one seed; the slow twin runs 60 seeds at 1, 0.24 and
    0.024 LSB of noise)."""
    false, missed, too_little, tried = _clean_and_copies(tmp_path, range(1), lsbs=(1e-4,))
    assert not false, false
    assert not missed and not too_little, (missed, too_little)
    assert tried == 6


@pytest.mark.slow
def test_many_quantised_recordings_no_false_copy_every_copy_found(tmp_path):
    """0 clean recordings refused; every copy refused but those whose copied rows carry too
    little information to tell from chance (stated, and few: they are printed)."""
    false, missed, too_little, tried = _clean_and_copies(tmp_path, range(2, 62))
    print(f"{len(false)} of {tried // 3} clean refused; {tried - len(too_little)} of {tried} "
          f"copies refused; too little information: {too_little}")
    assert not false, false
    assert not missed, missed
    assert len(too_little) <= 0.01 * tried, too_little
    assert tried == 60 * 3 * 2 * 3


def test_stuck_periodic_and_short_repeats_are_no_copy():
    """What repeats by itself is no copy: a stuck sensor twice at one value, a periodic
    noise-free signal, a quantised stretch shorter than a copy must be; a file written three
    times is one."""
    rng = np.random.default_rng(3)
    noisy = rng.normal(0, 1, (3000, 3))
    stuck = noisy.copy()
    stuck[500:800] = 0.0
    stuck[2000:2300] = 0.0  # (the sensor disconnected twice: zeros both times)
    assert find_copy(row_keys(list(stuck.T)), COPY_ROWS, 80.0) is None
    periodic = noisy.copy()  # a noise-free periodic stretch (period 250 rows > a copy)
    periodic[1000:2500] = np.round(100 * np.sin(2 * np.pi * np.arange(1500)[:, None] / 250
                                                + np.array([0, 1, 2])))
    assert find_copy(row_keys(list(periodic.T)), COPY_ROWS, 80.0) is None
    short = noisy.copy()
    short[2000:2000 + COPY_ROWS - 1] = noisy[100:100 + COPY_ROWS - 1]
    assert find_copy(row_keys(list(short.T)), COPY_ROWS, 80.0) is None
    short[2000:2000 + COPY_ROWS] = noisy[100:100 + COPY_ROWS]
    c = find_copy(row_keys(list(short.T)), COPY_ROWS, 80.0)
    assert (c.first, c.start, c.rows) == (100, 2000, COPY_ROWS)
    thrice = np.concatenate([noisy[:400]] * 3)
    c = find_copy(row_keys(list(thrice.T)), COPY_ROWS, 80.0)
    assert (c.first, c.start, c.rows) == (0, 400, 800)


def test_pose_and_readings_files_and_arrays_written_twice_are_refused(tmp_path):
    """The same rule for `align tilt`/`apply` readings, check/pose files with labels, and
    .npz arrays (rows named by index there)."""
    t, u = _counts(7, 1e-4)
    p = _save(tmp_path / "r.csv", t, u, False)
    rows = p.read_text().splitlines()
    q = tmp_path / "r2.csv"
    q.write_text("\n".join(rows + rows[1:]) + "\n")
    assert len(read_readings(p, rate_hz=50.0)) == len(t)
    with pytest.raises(InputError, match="r2.csv:.* the file was written twice"):
        read_readings(q, rate_hz=50.0)
    labelled = tmp_path / "poses.csv"
    lines = ["pose,ux,uy,uz"] + [f"P{i // 200},{a},{b},{c}" for i, (a, b, c)
                                 in enumerate(u[:2800])]
    labelled.write_text("\n".join(lines + lines[201:601]) + "\n")
    with pytest.raises(InputError, match=r"lines 2802-3201 repeat lines 202-601 exactly"):
        read_poses(labelled)
    npz = tmp_path / "u.npz"
    np.savez(npz, u=np.concatenate([u, u[:500]]).astype(float))
    n = len(u)
    with pytest.raises(InputError, match=rf"u\.npz: rows {n}-{n + 499} repeat rows 0-499"):
        read_arrays(npz, READINGS, rate_hz=50.0)
