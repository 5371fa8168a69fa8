"""One BLAS thread per run unless the user set a thread count (axisbase.threads)."""

from __future__ import annotations

import os

import pytest

from axisbase.threads import THREAD_VARIABLES, one_blas_thread


@pytest.fixture
def no_thread_setting(monkeypatch):
    for v in THREAD_VARIABLES:
        monkeypatch.delenv(v, raising=False)


def test_one_thread_inside_and_restored_after(no_thread_setting):
    with one_blas_thread():
        assert {v: os.environ.get(v) for v in THREAD_VARIABLES} == dict.fromkeys(
            THREAD_VARIABLES, "1")
    assert not any(v in os.environ for v in THREAD_VARIABLES)


def test_restored_when_the_run_fails(no_thread_setting):
    with pytest.raises(RuntimeError), one_blas_thread():
        raise RuntimeError("a failing command")
    assert not any(v in os.environ for v in THREAD_VARIABLES)


def test_a_users_thread_count_stands(no_thread_setting, monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")
    with one_blas_thread():
        assert os.environ["OPENBLAS_NUM_THREADS"] == "4"
        assert "OMP_NUM_THREADS" not in os.environ and "MKL_NUM_THREADS" not in os.environ
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"
