"""Clipped pixels named where marks were measured (:mod:`imaging.clipped`, issue 18 user 12):
the region, its share of the frame and the level; the marks whose bands touch it, with how
much of each band was left out; nothing for a frame without clipping."""

from __future__ import annotations

import numpy as np

from imaging.candidate import MarkCandidate
from imaging.clipped import clipped_notes

# A horizontal mark through the centre of a 200 x 120 frame, x from -80 to +80 px.
MARK = MarkCandidate(0.0, 0.0, -80.0, 80.0, True, 3.0, 100.0)


def test_a_clipped_side_is_named_with_the_mark_it_touches():
    hot = np.zeros((120, 200), bool)
    hot[:, 150:] = True  # the right quarter at full scale: 10 of the mark's 160 px
    notes = clipped_notes(hot, 4095.0, "f.tif", [(0, MARK)])
    assert len(notes) == 1
    n = notes[0]
    assert n.startswith("f.tif: region 150,") and "clipped at 4095 (the 12-bit" in n
    assert "25 % of the frame" in n
    got = int(n.split("mark 0 ")[1].split(" px")[0])
    assert 0 < got < hot.sum()  # only the band's share of the clipped pixels


def test_clipping_away_from_the_marks_is_named_without_them_and_none_is_silent():
    hot = np.zeros((120, 200), bool)
    hot[:10, :40] = True  # a corner, 1.7 % of the frame, far from the mark
    notes = clipped_notes(hot, 255.0, "f.png", [(0, MARK)])
    assert len(notes) == 1 and "region 0,0–" in notes[0] and "mark 0" not in notes[0]
    assert clipped_notes(np.zeros((120, 200), bool), 255.0, "f.png", [(0, MARK)]) == ()
    few = np.zeros((120, 200), bool)
    few[0, 0] = True  # one hot pixel, away from every mark: no exposure problem
    assert clipped_notes(few, 255.0, "f.png", [(0, MARK)]) == ()
