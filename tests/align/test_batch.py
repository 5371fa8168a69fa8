"""Batches of sessions (``align.session.batch``): stopped cleanly by signals with no orphan
worker and nothing half-written, ``--resume``, a worker that dies, and the same results on a
Dask cluster as on the local process pool.

The signal tests run ``align run`` as a real subprocess and send it real signals; every wait
is bounded.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from align.cli import main
from align.session.batch import SessionJob, batch_jobs, is_complete
from axisbase.output import OutputError, OutputSet

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
psutil = pytest.importorskip("psutil")  # a dependency of distributed


@pytest.fixture(scope="module")
def sessions(session21, tmp_path_factory) -> list[Path]:
    """Four sessions (copies of the run's synthetic session of seed 21: each takes ~1 s of
    one core to run)."""
    base = tmp_path_factory.mktemp("batch")
    first = base / "unit1"
    shutil.copytree(session21, first)
    out = [first]
    for k in range(2, 5):
        shutil.copytree(first, base / f"unit{k}")
        out.append(base / f"unit{k}")
    return out


@pytest.fixture(scope="module")
def bad_session(sessions) -> Path:
    """A session that fails: its counter log is missing."""
    bad = sessions[0].parent / "unit_bad"
    shutil.copytree(sessions[0], bad)
    (bad / "gonio.csv").unlink()
    return bad


def _start(argv: list[str]) -> subprocess.Popen:
    """``align`` in a process group of its own (as a shell job: Ctrl-C reaches the group)."""
    return subprocess.Popen([sys.executable, "-m", "align", *argv], env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def _wait_for(cond, timeout: float, what: str) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


def _workers(proc: subprocess.Popen) -> list:
    _wait_for(lambda: len(psutil.Process(proc.pid).children()) >= 2, 60, "2 worker processes")
    return psutil.Process(proc.pid).children()


def _gone(procs: list, timeout: float) -> bool:
    _, alive = psutil.wait_procs(procs, timeout=timeout)
    return not alive


def _outputs_all_or_nothing(out: Path, names: list[str]) -> list[str]:
    """The sessions whose outputs are complete; fails on a half-written set or a leftover
    temporary file."""
    files = sorted(p.name for p in out.iterdir())
    assert not [f for f in files if f.startswith(".") or f.endswith(".part")], files
    done = []
    for n in names:
        have = [f"{n}.json" in files, f"{n}.cal.json" in files]
        assert all(have) or not any(have), (n, files)
        if all(have):
            assert json.loads((out / f"{n}.json").read_text())["ok"]
            done.append(n)
    return done


# ----------------------------------------------------------------------------- signals

@pytest.mark.slow
@pytest.mark.parametrize("sig,status", [
    (signal.SIGTERM, 143), pytest.param(signal.SIGINT, 130, marks=pytest.mark.slow)])
def test_a_stopped_batch_stops_its_workers_and_leaves_nothing_half_written(
        sessions, tmp_path, sig, status):
    out = tmp_path / "out"
    names = [s.name for s in sessions]
    proc = _start(["run", *map(str, sessions), "--json", str(out), "--calibration", str(out),
                   "--jobs", "2", "-q"])
    try:
        workers = _workers(proc)
        _wait_for(lambda: out.is_dir() and any(out.glob("*.cal.json")), 60,
                  "a first session finished")
        if sig == signal.SIGINT:  # Ctrl-C in a terminal: the whole group gets it
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        assert proc.wait(timeout=30) == status
        assert "--resume" in proc.stderr.read()
        assert _gone(workers, 10), "orphaned workers"
    finally:
        proc.kill()
    done = _outputs_all_or_nothing(out, names)
    assert len(done) < len(names)
    before = {n: (out / f"{n}.json").stat().st_mtime_ns for n in done}
    # --resume: the finished sessions are skipped (not rewritten), the others done.
    assert main(["run", *map(str, sessions), "--json", str(out), "--calibration", str(out),
                 "-q", "--jobs", "2", "--resume"]) == 0
    assert _outputs_all_or_nothing(out, names) == names
    assert {n: (out / f"{n}.json").stat().st_mtime_ns for n in done} == before  # skipped


def test_a_stopped_single_session_writes_nothing(sessions, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    proc = _start(["run", str(sessions[0]), "--json", str(out / "r.json"), "--report",
                   str(out / "r.html"), "--calibration", str(out / "c.json")])
    try:
        # Stopped at its first mark (progress on stderr): the marks, the fusion and the
        # report (seconds) are still to come. A fixed sleep raced a fast machine.
        while "marks:" not in (line := proc.stderr.readline()):
            assert line, "finished before it could be stopped"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 143
        assert "stopped (SIGTERM)" in proc.stderr.read()
    finally:
        proc.kill()
    assert list(out.iterdir()) == []


@pytest.mark.slow
def test_killing_the_batch_ends_its_workers(sessions, tmp_path):
    """SIGKILL cannot be caught: the workers notice their parent has gone and stop, leaving
    no orphan and no half-written output."""
    out = tmp_path / "out"
    proc = _start(["run", *map(str, sessions), "--json", str(out), "--calibration", str(out),
                   "--jobs", "2", "-q"])
    try:
        workers = _workers(proc)
        time.sleep(1.0)  # inside the sessions
        proc.kill()
        proc.wait(timeout=10)
        assert _gone(workers, 10), "orphaned workers after SIGKILL of the batch"
    finally:
        proc.kill()
    _outputs_all_or_nothing(out, [s.name for s in sessions])


@pytest.mark.slow
def test_a_dead_local_worker_loses_no_session(sessions, tmp_path):
    """A worker killed mid-batch (out of memory, say): the pool is rebuilt and every session
    still finishes."""
    out = tmp_path / "out"
    # not -q: the batch's count is on stdout, which -q leaves to warnings and errors
    proc = _start(["run", *map(str, sessions), "--json", str(out), "--jobs", "2"])
    try:
        workers = _workers(proc)
        time.sleep(1.0)
        workers[0].kill()
        code = proc.wait(timeout=180)
        stdout = proc.stdout.read()
    finally:
        proc.kill()
    assert code == 0, stdout
    assert "4 of 4 sessions done" in stdout
    assert sorted(p.name for p in out.iterdir()) == [f"{s.name}.json" for s in sessions]


# ----------------------------------------------------------------------------- outputs

def test_an_output_set_appears_whole_or_not_at_all(tmp_path):
    (tmp_path / "b.html").write_text("someone else's")
    with pytest.raises(OutputError, match="appeared"), OutputSet() as out:
        out.stage(tmp_path / "a.json", "{}")
        out.stage(tmp_path / "b.html", "<html>")
        out.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.html"]  # a.json taken back
    assert (tmp_path / "b.html").read_text() == "someone else's"
    with OutputSet() as out:
        out.stage(tmp_path / "c.json", "{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.html"]  # never committed


def _minimal_result(**keys) -> dict:
    """The smallest session result the one reader takes: a session that did not fuse."""
    return {"format": "axis-align/session", "format_version": 3, "session": "unit1",
            "ok": True, "fused": False, **keys}


def test_complete_means_every_output_asked_for(sessions, tmp_path):
    out = tmp_path / "o"
    job, = batch_jobs([str(sessions[0])], json=str(out), report=None, cal=str(out))
    assert not is_complete(job)
    (out / "unit1.cal.json").write_text("{}")
    assert not is_complete(job)  # the JSON (put in place last) is missing
    # a session result the one reader reads (a stub with only its format is not one)
    (out / "unit1.json").write_text('{"format": "axis-align/session"}')
    assert not is_complete(job)
    (out / "unit1.json").write_text(json.dumps(_minimal_result()))
    assert is_complete(job)
    assert not is_complete(SessionJob(job.folder, job.json, str(out / "r.html"), job.cal))
    (out / "unit1.json").write_text("not json")
    assert not is_complete(job)


def test_resume_does_not_pass_off_a_result_made_with_another_alpha(sessions, tmp_path):
    from dataclasses import replace

    from align.session.batch import skipped

    out = tmp_path / "o"
    out.mkdir()
    job, = batch_jobs([str(sessions[0])], json=str(out), report=None, cal=None)
    (out / "unit1.json").write_text(json.dumps(_minimal_result(settings={"alpha": job.alpha})))
    same = skipped(job)
    assert same["ok"] and not same["warnings"]
    other = skipped(replace(job, alpha=0.01))
    assert not other["ok"] and "alpha" in other["warnings"][0]


# ----------------------------------------------------------------------------- Dask

def _comparable(d: dict) -> dict:
    """A result without what must differ between two runs: times, command line and the
    output folders named in the settings."""
    d = json.loads(json.dumps(d))
    for k in ("created_utc", "command"):
        d.pop(k)
    for k in ("json", "report", "calibration"):
        d["settings"].pop(k, None)
    return d


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as c:
        yield c


@pytest.mark.slow
def test_dask_cluster_gives_the_local_pool_results(sessions, bad_session, tmp_path, cluster,
                                                   capsys):
    batch = [*map(str, sessions[:2]), str(bad_session)]
    local, dask = tmp_path / "local", tmp_path / "dask"
    assert main(["run", *batch, "--json", str(local), "--calibration", str(local),
                 "--jobs", "2"]) == 2
    assert main(["run", *batch, "--json", str(dask), "--calibration", str(dask),
                 "--scheduler", cluster.scheduler_address]) == 2
    cap = capsys.readouterr()
    assert cap.out.count("2 of 3 sessions done, 1 failed") == 2
    assert "unit_bad: FAILED" in cap.err and "gonio.csv" in cap.err
    names = sorted(p.name for p in local.iterdir())
    assert names == sorted(p.name for p in dask.iterdir()) and len(names) == 4
    for n in names:
        a, b = (json.loads((d / n).read_text()) for d in (local, dask))
        assert _comparable(a) == _comparable(b), n


@pytest.mark.slow
def test_dask_from_the_environment_and_resume(sessions, tmp_path, cluster, monkeypatch,
                                              capsys):
    out = tmp_path / "out"
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", cluster.scheduler_address)
    assert main(["run", *map(str, sessions[:2]), "--json", str(out)]) == 0
    assert "on the Dask cluster at" in capsys.readouterr().err
    (out / "unit2.json").unlink()
    assert main(["run", *map(str, sessions[:2]), "--json", str(out), "--resume"]) == 0
    cap = capsys.readouterr()
    assert "1 of 2 sessions already complete" in cap.err and "2 of 2 sessions done" in cap.out


@pytest.mark.slow
def test_a_dask_worker_killed_mid_batch_loses_no_session(sessions, tmp_path, cluster):
    from distributed import Client

    out = tmp_path / "out"
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        pids = client.run(os.getpid)
        killed: list[str] = []

        def kill_one_busy_worker() -> None:
            t0 = time.monotonic()
            while time.monotonic() - t0 < 60:
                busy = [w for w, keys in client.processing().items()
                        if any("align-run" in str(k) for k in keys)]
                if busy:
                    time.sleep(0.5)  # inside the session
                    os.kill(pids[busy[0]], signal.SIGKILL)
                    killed.append(busy[0])
                    return
                time.sleep(0.05)

        t = threading.Thread(target=kill_one_busy_worker, daemon=True)
        t.start()
        code = main(["run", *map(str, sessions), "--json", str(out), "--calibration",
                     str(out), "--scheduler", cluster.scheduler_address, "-q"])
        t.join(5)
        assert killed, "no worker was killed"
        client.wait_for_workers(2, timeout=60)  # the nanny restarts it
    assert code == 0
    assert _outputs_all_or_nothing(out, [s.name for s in sessions]) == [
        s.name for s in sessions]


def test_an_unreachable_scheduler_is_one_line(sessions):
    pytest.importorskip("distributed")
    from align.errors import InputError
    from align.session.batch import DaskCluster

    with pytest.raises(InputError, match=r"--scheduler tcp://127\.0\.0\.1:9: cannot reach"):
        DaskCluster("tcp://127.0.0.1:9", connect_timeout_s=1).run(
            [SessionJob(str(sessions[0]))], lambda r: None)
