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
