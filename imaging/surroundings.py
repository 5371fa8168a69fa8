"""What the frame around one mark its measurement needs: the lines beside it, the others that
may cross it, the file's JPEG encoder and the removed stripes' offsets.

Kept with the measurement (:attr:`imaging.measure.MarkMeasurement.around`) so that every
measurement of the mark again — under a shadow's edge divided out, a kink's part, the
background put back — is made in the same frame: passed one argument at a time, a re-measure
under a shadow dropped the file's encoder (a JPEG's mark lost its ``jpeg_blocks`` term and
its within-block correlation), the crossing marks and the stripes' offsets."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imaging.beside import neighbours
from imaging.candidate import MarkCandidate
from imaging.jpeg import JpegBlocks


@dataclass(frozen=True)
class Surroundings:
    """The frame around one candidate.

    Attributes
    ----------
    neighbours_px : tuple of float
        Signed distances of other lines beside it [px] (:func:`imaging.beside.neighbours`),
        kept out of the texture's replicas.
    jpeg : JpegBlocks or None
        The image's JPEG encoder (:func:`imaging.jpeg.find_jpeg`), whose effect on the
        angle is then measured.
    offsets_var : tuple of ndarray or None
        Variances of the removed column and row offsets [DN^2] (:mod:`imaging.stripes`),
        carried into the centres' covariance.
    crossing : tuple of (int, MarkCandidate)
        The other marks with their indices, whose grooves are kept out of this one's fit
        where they cross it (:func:`imaging.crossmask.crossing_skip`).
    """

    neighbours_px: tuple[float, ...] = ()
    jpeg: JpegBlocks | None = None
    offsets_var: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
    crossing: tuple[tuple[int, MarkCandidate], ...] = ()


ALONE = Surroundings()
"""A mark measured on its own (no other line, no JPEG, no stripes removed)."""


def surroundings_of(cands: Sequence[MarkCandidate], i: int, jpeg: JpegBlocks | None,
           offsets_var: tuple[np.ndarray | None, np.ndarray | None]) -> Surroundings:
    """Candidate i's surroundings among the frame's candidates ``cands``."""
    return Surroundings(neighbours(cands, i), jpeg, offsets_var, tuple(crossings(cands, i)))


def crossings(cands: Sequence[MarkCandidate], i: int) -> list[tuple[int, MarkCandidate]]:
    """The other candidates with their indices (the ones that cross candidate i are found
    by :func:`imaging.crossmask.crossing_skip` once its groove's width is known)."""
    return [(j, o) for j, o in enumerate(cands) if j != i]

