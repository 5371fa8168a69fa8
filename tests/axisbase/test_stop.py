"""Stopping cleanly: a signal raises Stopped, except during a commit, when it waits for the
commit to finish; and an output set is whole or absent even then."""

from __future__ import annotations

import signal

import pytest

from axisbase.output import OutputSet
from axisbase.stop import Stopped, on_signal, stops_held


def test_a_signal_raises_at_once_outside_a_commit():
    with pytest.raises(Stopped) as exc:
        on_signal(signal.SIGTERM, None)
    assert exc.value.exit_status == 143
    assert isinstance(exc.value, KeyboardInterrupt)
    assert Stopped(signal.SIGINT).exit_status == 130


def test_a_signal_during_a_commit_waits_for_its_end():
    done = []
    with pytest.raises(Stopped):
        with stops_held():
            on_signal(signal.SIGTERM, None)  # held back
            done.append("renamed")
    assert done == ["renamed"]
    with stops_held():  # nothing pending any more
        pass


def test_a_stop_during_an_output_commit_leaves_the_whole_set(tmp_path, monkeypatch):
    import axisbase.output as output

    real = output._link_exclusive
    calls = []

    def link_then_signal(tmp, p):
        real(tmp, p)
        calls.append(p.name)
        if len(calls) == 1:
            on_signal(signal.SIGTERM, None)  # arrives between the two renames

    monkeypatch.setattr(output, "_link_exclusive", link_then_signal)
    with pytest.raises(Stopped), OutputSet() as out:
        out.stage(tmp_path / "a.html", "<html>")
        out.stage(tmp_path / "a.json", "{}")
        out.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.html", "a.json"]


def test_a_stop_while_a_temporary_file_is_created_leaves_nothing(tmp_path, monkeypatch):
    """The signal arrives after mkstemp made the file and before it is recorded for removal
    (in CI a batch stopped just then left a ``.part`` behind)."""
    import axisbase.output as output

    real = output.tempfile.mkstemp

    def mkstemp_then_signal(*args, **kwargs):
        made = real(*args, **kwargs)
        on_signal(signal.SIGTERM, None)
        return made

    monkeypatch.setattr(output.tempfile, "mkstemp", mkstemp_then_signal)
    with pytest.raises(Stopped), OutputSet() as out:
        out.stage(tmp_path / "a.json", "{}")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(Stopped):
        output.write_atomic(tmp_path / "b.json", "{}")
    assert list(tmp_path.iterdir()) == []


def test_a_second_stop_while_temporary_files_are_removed_removes_them_all(tmp_path,
                                                                         monkeypatch):
    import axisbase.output as output

    real = output.os.unlink
    calls = []

    def unlink_then_signal(path):
        real(path)
        calls.append(path)
        if len(calls) == 1:
            on_signal(signal.SIGTERM, None)  # e.g. the batch's parent has just ended

    with pytest.raises(Stopped), OutputSet() as out:
        out.stage(tmp_path / "a.html", "<html>")
        out.stage(tmp_path / "a.json", "{}")
        monkeypatch.setattr(output.os, "unlink", unlink_then_signal)
        raise Stopped(signal.SIGTERM)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []
