"""A frame's clipped (saturated) pixels named where marks were measured in it.

A pixel at full scale says only "at least this": every fit of the stage already leaves such
pixels out (the profile's centres, :mod:`imaging.centres`; the texture replicas,
:mod:`imaging.texture`; the background tests, :mod:`imaging.oriented`), so a mark's u rests on
the pixels that remain. What was missing is the word: a 16-bit frame 58 % clipped (a lamp
brighter to one side) was reported with a "defocus gradient" and "an end under an
obstruction", the clipping never named (user 12). The frame's clipped region, its share and
the level are named here, and each mark whose band (groove and background ring, as measured)
touches them, with how much of it was left out.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imaging.band import band_indices
from imaging.candidate import MarkCandidate
from imaging.io import clipped_region

LEAST = 1e-3
"""Share of the frame (of a mark's band) clipped below which nothing is said of it (a few hot
pixels are no exposure problem; they are left out all the same)."""


def clipped_notes(hot: np.ndarray, top: float, where: str,
                  marks: Sequence[tuple[int, MarkCandidate]]) -> tuple[str, ...]:
    """What the clipped pixels ``hot`` (the frame's mask at full scale ``top`` [DN], one pass
    over the image) did to the marks ``marks`` (each its index in the results and its
    candidate): one note for the frame, naming the region, its share and the level, and the
    marks whose bands hold clipped pixels; () when the frame has (almost) none.

    Parameters
    ----------
    hot : numpy.ndarray of bool
        The frame's pixels at full scale.
    top : float
        The full scale [DN].
    where : str
        The image's name.
    marks : sequence of (int, MarkCandidate)
        The marks measured: their index as reported and their candidate.
    """
    n = int(np.count_nonzero(hot))
    if n == 0:
        return ()
    touched = []
    for k, c in marks:
        idx = band_indices(hot, c)
        m = int(np.count_nonzero(hot.flat[idx]))
        if m > LEAST * idx.size:  # a hot speck in a band is left out, not worth a word
            touched.append(f"mark {k} {m} px ({100 * m / max(idx.size, 1):.0f} % of its band)")
    if n < LEAST * hot.size and not touched:
        return ()
    marks_said = ("; clipped pixels in the bands of " + ", ".join(touched) + ": left out of "
                  "their profile, texture and background fits (each angle and its u rest on "
                  "the pixels that remain; what is said of their blur and ends there may be the "
                  "clipping's)" if touched else "")
    return (f"{where}: {clipped_region(hot, top)}: saturated pixels say only 'at least "
            f"this'{marks_said}; expose less (or dim the light on that side)",)
