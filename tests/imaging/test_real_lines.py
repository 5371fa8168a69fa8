"""OpenCV's sample photographs with straight lines (../shared/data/real/opencv-lines): what the
detector honestly does on them. Skips when the data are absent."""

from __future__ import annotations

from pathlib import Path

import pytest

from align.marks import measure_image
from imaging import read_image

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real" / "opencv-lines"


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "building.jpg").exists(), reason=f"{DATA} absent")
def test_building_lines_measured_and_families_are_rulings():
    res = measure_image(read_image(DATA / "building.jpg"), "building.jpg")
    ok = [r for r in res if r.found]
    assert len(ok) >= 5  # long window and floor edges (13 measured when written)
    for r in ok:
        f = r.family
        # A family is side-by-side lines at least 8 px apart, never one edge found twice.
        if f is not None:
            assert len(f.members) >= 3 and f.pitch_px >= 8.0


@pytest.mark.skipif(not (DATA / "board.jpg").exists(), reason=f"{DATA} absent")
@pytest.mark.parametrize("name", ["board.jpg", "charuco_choriginal.jpg"])
def test_pcb_and_charuco_refused_in_one_line(name):
    """The PCB's pin rows (~50 px lines at ~11 px pitch, alike their neighbours) and the
    ChArUco board's squares: no line stands out, said in one line; the pin rows are not a
    grating's single periodic field, so none is named (docs/ruled-scales.md, Limits)."""
    res = measure_image(read_image(DATA / name), name)
    assert len(res) == 1 and not res[0].found
    assert res[0].error.startswith(f"{name}: no mark found") and "\n" not in res[0].error
    assert "grating" not in res[0].error


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "building.jpg").exists(), reason=f"{DATA} absent")
def test_building_no_dial_from_a_vanishing_point():
    """Window edges converge on a vanishing point: lines meeting at a point, but not a
    graduation (spaced anyhow): no dial."""
    res = measure_image(read_image(DATA / "building.jpg"), "building.jpg")
    assert all(r.dial is None for r in res if r.found)
