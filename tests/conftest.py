"""Shared fixtures: seeded synthetic images (every failure reproducible from its seed)."""

from __future__ import annotations

import contextlib
import ctypes
import gc
import io
import os
import shutil
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

from axisbase.threads import one_thread_environment

# The tests run the library as `align` runs it (axisbase.threads): one BLAS thread unless the
# environment says otherwise; set before numpy loads its BLAS, and inherited by the CLI runs
# the tests start.
os.environ.update(one_thread_environment())

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks


def _keep_freed_memory() -> None:
    """glibc's allocator, told to keep up to 256 MiB of freed heap and to serve blocks up to
    32 MiB from it: the tests allocate and free image-sized arrays thousands of times, and by
    default each comes from a fresh mmap whose pages the kernel faults in and zeroes again
    (measured on imaging and fusion tests: 16.8 s -> 14.7 s of CPU, most of it system time;
    the same peak memory). Only where that libc is; nothing a test computes changes."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (macOS, Windows, musl): the defaults
        return
    m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3  # malloc.h
    mallopt(m_mmap_threshold, 32 << 20)
    mallopt(m_trim_threshold, 256 << 20)
    mallopt(m_top_pad, 64 << 20)


_keep_freed_memory()


def pytest_collection_finish(session) -> None:
    """After collection, the collected objects (modules, fixtures, items: most of the heap)
    go to the permanent generation, and the young generation is collected every 10000
    allocations instead of 700: the cyclic garbage collector otherwise re-walks them in every
    full collection and runs ~2x as often (measured: 0.84 s -> 0.35 s of the garbage
    collector's CPU over 30 s of tests). Nothing a test checks depends on when cycles are
    freed; reference counting still frees everything else at once."""
    gc.freeze()
    gc.set_threshold(10000, 10, 10)


REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
ARCSEC = np.pi / 180 / 3600


def real_folder(name: str) -> Path:
    p = REAL / name
    if not p.is_dir():
        pytest.skip(f"real data folder {p} is absent (it lives in ../shared/data/real)")
    return p


def angle_error(measured: float, truth: float) -> float:
    """Difference of two line directions, wrapped to (-pi/2, pi/2] [rad]."""
    return (measured - truth + np.pi / 2) % np.pi - np.pi / 2


def mark_image(angle_deg: float, seed: int, snr: float = 30.0, width_px: float = 4.0,
               length_px: float = 500.0, offset_px: float = 12.3, size=(800, 600),
               with_crlb: bool = False, **kw):
    spec = ImageSpec(
        marks=(MarkSpec(np.deg2rad(angle_deg), offset_px, length_px, width_px,
                        centre_t_px=kw.pop("centre_t_px", 0.0),
                        contrast=kw.pop("contrast", -0.6)),),
        width=size[0], height=size[1], full_well_e=full_well_for_snr(snr, -0.6), seed=seed,
        **kw)
    return render_marks(spec, with_crlb=with_crlb)


def _strip_images(text: str) -> str:
    """session.toml without cameras, views and images (a fast session)."""
    out, skip = [], False
    for line in text.splitlines():
        if line.startswith("["):
            skip = line.startswith(("[cameras", "[views", "[[images"))
        if not skip:
            out.append(line)
    return "\n".join(out) + "\n"


def strip_images(full: Path, plain: Path) -> Path:
    """A copy of the session ``full`` without its images at ``plain`` (calibration,
    goniometer, platform: ~1 s to run); returns ``plain``."""
    plain.mkdir()
    for name in ("tumble.csv", "gonio.csv", "platform.csv"):
        (plain / name).write_bytes((full / name).read_bytes())
    (plain / "session.toml").write_text(_strip_images((full / "session.toml").read_text()))
    return plain


def _unrendered(spec: ImageSpec, with_crlb: bool = False):
    """What ``render_marks`` gives ``synth.session`` for an image nobody will read: no pixels,
    the mark's scene angle for truth.json (not its image angle: no test of an unrendered session
    reads it)."""
    mark = SimpleNamespace(image_angle_rad=spec.marks[0].angle_rad)
    return SimpleNamespace(image=None, truth=SimpleNamespace(marks=[mark]))


def write_unrendered(out: Path, spec) -> dict:
    """``synth.session.write_session(out, spec)`` without drawing the mark images: no PNGs and
    truth.json's image angles are the scene's; every other file byte for byte (the random
    draws that place the images are still taken;
    ``test_imageless_session_is_the_full_session_without_its_images``), for a test that reads
    session.toml, the tumble, the log or the platform poses only (~0.5 s of CPU saved)."""
    from synth.session import write_session

    with mock.patch("synth.session.render_marks", _unrendered), \
            mock.patch("synth.session.write_synth", lambda *a, **k: None):
        return write_session(out, spec)


def imageless_session(root: Path, spec, render: bool = False) -> Path:
    """A synthetic session (``synth.session.SessionSpec``) written under ``root/full`` and its
    copy without images under ``root/plain`` (see :func:`strip_images`); returns the copy.
    The images are not drawn (:func:`write_unrendered`) unless ``render``."""
    from synth.session import write_session

    (write_session if render else write_unrendered)(root / "full", spec)
    return strip_images(root / "full", root / "plain")


@pytest.fixture(scope="session")
def session21(tmp_path_factory) -> Path:
    """The synthetic session of seed 21 (``SessionSpec(seed=21)``: images, tumble, counter
    log, platform), written once for the whole run as folder ``unit7``. Read-only: a test
    that edits a session edits a copy."""
    from synth.session import SessionSpec, write_session

    folder = tmp_path_factory.mktemp("seed21") / "unit7"
    write_session(folder, SessionSpec(seed=21))
    return folder


@pytest.fixture(scope="session")
def session21_run(session21):
    """``run_session`` of the session of seed 21, once for the run (a full session is ~1 s of
    CPU): ``(result, truth misalignment [rad])``. Results are frozen: a test that changes
    one changes a ``dataclasses.replace`` copy."""
    import json

    from align.session import load_session, run_session

    truth = np.array(json.loads((session21 / "truth.json").read_text())["misalignment_rad"])
    return run_session(load_session(session21)), truth


@pytest.fixture(scope="session")
def session21_result(session21, tmp_path_factory) -> Path:
    """The session of seed 21 with [metadata], run once by ``align run``: the path
    of its result JSON, beside it its platform calibration (``pc.json``) and what the command
    printed (``run.stdout``, ``run.stderr``). Shared by the lot tests (test_lot,
    test_lot_duplicates), 'align apply' (test_session) and the clean session's terminal
    (test_warnings), which only read them; a full session run is seconds of CPU."""
    from align.cli import main

    folder = tmp_path_factory.mktemp("seed21meta") / "unit1"
    shutil.copytree(session21, folder)
    with open(folder / "session.toml", "a") as f:
        f.write('\n[metadata]\nserial = "SN-0001"\noperator = "kim"\n'
                "date = 2026-11-20T08:30:00Z\nbatch = 7\n")
    out = folder.parent / "r.json"
    printed, said = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(said):
        rc = main(["run", str(folder), "--json", str(out), "--calibration",
                   str(folder.parent / "pc.json")])
    (folder.parent / "run.stdout").write_text(printed.getvalue(), encoding="utf-8")
    (folder.parent / "run.stderr").write_text(said.getvalue(), encoding="utf-8")
    assert rc == 0, said.getvalue()
    return out


@pytest.fixture
def tmp_out(tmp_path: Path) -> Path:
    return tmp_path
