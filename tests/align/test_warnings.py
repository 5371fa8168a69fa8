"""What reaches a mark's warnings: a handled crossing is a note, not a warning."""

from __future__ import annotations

from align import LensRanges, measure_image
from align.present import mark_lines
from align.warnings import handled_crossing, mark_warnings
from synth import render_marks
from tests.align.test_marks_crossing import crossing_scene


def test_a_handled_crossing_is_a_note_not_a_warning():
    # Two marks crossing at 20 deg in their middles (seeded): each is measured with the
    # other's groove left out of its fit (tests/align/test_marks_crossing.py checks their
    # angles against the truth over seeds), so nothing about them is less to be trusted.
    img = render_marks(crossing_scene(20.0, "middle", 1), with_crlb=False).image.astype(float)
    res = measure_image(img, "x.png", ranges=LensRanges.none())
    found = [r for r in res if r.found]
    assert len(found) == 2
    crossings = [n for r in found for n in r.notes if handled_crossing(n)]
    assert len(crossings) == 2  # one per mark, in its notes (and so in the JSON's)
    assert all("crossing with mark" in n and "px excluded" in n for n in crossings)
    warnings = mark_warnings(res)
    assert not any("crossing" in w for w in warnings)
    text = "\n".join(line for r in found for line in mark_lines(r))
    assert text.count("    note: crossing with mark") == 2


def test_other_notes_still_warn():
    assert not handled_crossing("x.png mark 0: NOT OK: the angle is lens-limited")
    assert not handled_crossing("x.png mark 0: crossing with mark 1: refused")
    assert handled_crossing("a b.png mark 3: crossing with a groove not found as a mark: 12 px "
                            "excluded (the other groove lies in its profile window there)")
