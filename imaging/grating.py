"""Gratings beside measured marks: where in the frame a field of identical fine lines lies.

A grating is not measured (:func:`imaging.families.grating_note` says why when an image holds
nothing else). Beside a measured mark it must not pass unsaid either: the tiles of the frame
around the marks (:data:`TILE` px squares, each within one tile of a mark's line) are each
tested for a grating's spectrum — :func:`spectral_grating`, the same test as
:func:`~imaging.families.grating_note`'s on the frame's middle — and the tiles that show one
grating (pitch within :data:`SAME_PITCH`, direction within :data:`SAME_ANGLE`) are reported
together as one region (the bounding box of their tiles).

Only the tiles near the marks: the test costs ~1 ms per tile, and a frame's far corners are
not what the marks' results are read beside. A family of lines that was measured (a ruled
scale's graduations) shows the same peak: the caller leaves out gratings with a measured
family's pitch and direction (:func:`grating_regions`'s ``known``).

Geometry: pixel boxes (x0, y0, x1, y1) in the image's columns and rows (x1, y1 exclusive);
angles [rad] from +x towards -y as in :mod:`imaging.detect`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imaging.families import spectral_grating

TILE = 256
"""Side of the tiles tested [px]: at least 4 periods of the coarsest pitch looked for."""
SAME_PITCH = 0.1
"""Tiles whose pitches differ by less than this fraction show one grating."""
SAME_ANGLE = np.deg2rad(3.0)
"""... and whose line directions differ by less than this."""


@dataclass(frozen=True)
class GratingRegion:
    """A grating seen in a region of the frame: its pitch [px], its lines' direction [rad],
    the pixel box (x0, y0, x1, y1) of the tiles that show it, and their number."""

    pitch_px: float
    angle_rad: float
    box: tuple[int, int, int, int]
    tiles: int

    def describe(self) -> str:
        """One sentence naming the grating, where it is, and that it is not measured."""
        x0, y0, x1, y1 = self.box
        return (f"a grating (identical parallel lines) of pitch {self.pitch_px:.1f} px, lines "
                f"at {np.rad2deg(self.angle_rad):.1f}°, in pixels x {x0}–{x1 - 1}, y {y0}–"
                f"{y1 - 1}: not measured (gratings are not; the marks beside it are)")


def _near(box: tuple[int, int, int, int], segments: np.ndarray, reach: float) -> bool:
    """Whether any segment ((N, 2, 2) end points, image pixels) comes within ``reach`` [px]
    of the box (distance from the box's centre to the segment, less its half-diagonal)."""
    c = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
    half = float(np.hypot(box[2] - box[0], box[3] - box[1])) / 2
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    t = np.clip(np.sum((c - a) * d, axis=1) / np.maximum(np.sum(d * d, axis=1), 1e-12), 0, 1)
    dist = np.hypot(*(a + t[:, None] * d - c).T)
    return bool(np.any(dist - half <= reach))


def grating_regions(image: np.ndarray, segments: Sequence[np.ndarray],
                    known: Sequence[tuple[float, float]] = ()) -> list[GratingRegion]:
    """The gratings in the tiles near the marks.

    Parameters
    ----------
    image : (H, W) array
        The frame [DN].
    segments : sequence of (2, 2) arrays
        Each measured mark's end points (x, y) [px, image columns and rows].
    known : sequence of (pitch [px], angle [rad])
        Rulings already measured (a family's pitch and direction): not named again.

    Returns
    -------
    list of GratingRegion
        One per grating, largest first; empty when none.
    """
    h, w = image.shape
    if not len(segments) or min(h, w) < TILE:
        return []
    seg = np.asarray(segments, float).reshape(-1, 2, 2)
    found: list[tuple[float, float, tuple[int, int, int, int]]] = []
    for y0 in range(0, h - TILE + 1, TILE):
        for x0 in range(0, w - TILE + 1, TILE):
            box = (x0, y0, x0 + TILE, y0 + TILE)
            if not _near(box, seg, TILE):
                continue
            got = spectral_grating(image[y0:y0 + TILE, x0:x0 + TILE], TILE / 4)
            if got is not None:
                found.append((*got, box))
    groups: list[list[tuple[float, float, tuple[int, int, int, int]]]] = []
    for f in found:
        g = next((g for g in groups if abs(f[0] / g[0][0] - 1) < SAME_PITCH
                  and abs((f[1] - g[0][1] + np.pi / 2) % np.pi - np.pi / 2) < SAME_ANGLE), None)
        if g is None:
            groups.append([f])
        else:
            g.append(f)
    out = []
    for g in groups:
        pitch = float(np.median([f[0] for f in g]))
        ang = g[0][1]
        if any(abs(pitch / p - 1) < SAME_PITCH
               and abs((ang - a + np.pi / 2) % np.pi - np.pi / 2) < SAME_ANGLE
               for p, a in known):
            continue
        boxes = np.array([f[2] for f in g])
        out.append(GratingRegion(pitch, ang, (int(boxes[:, 0].min()), int(boxes[:, 1].min()),
                                              int(boxes[:, 2].max()), int(boxes[:, 3].max())),
                                 len(g)))
    return sorted(out, key=lambda r: -r.tiles)
