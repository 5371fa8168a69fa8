"""Gratings beside measured marks: where in the frame a field of identical fine lines lies.

A grating is not measured (:func:`grating_note` says why when an image holds
nothing else). Beside a measured mark it must not pass unsaid either: the tiles of the frame
around the marks (:data:`TILE` px squares, each within one tile of a mark's line) are each
tested for a grating's spectrum — :func:`spectral_grating`, the same test as
:func:`grating_note`'s on the frame's middle — and the tiles that show one
grating (pitch within :data:`SAME_PITCH`, direction within :data:`SAME_ANGLE`) are reported
together as one region (the bounding box of their tiles).

Only the tiles near the marks: the test costs ~1 ms per tile, and a frame's far corners are
not what the marks' results are read beside. A family of lines that was measured (a ruled
scale's graduations) shows the same peak, or its harmonics (pitch / m: a tile's search
reaches pitches up to a quarter of its side, so a coarse ruling shows its second harmonic
strongest): the caller leaves out gratings with a measured family's direction and its pitch
or a harmonic of it (:func:`grating_regions`'s ``known``, :func:`explained_by_ruling`).

Geometry: pixel boxes (x0, y0, x1, y1) in the image's columns and rows (x1, y1 exclusive);
angles [rad] from +x towards -y as in :mod:`imaging.detect`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imaging.detect import wrap_angle

GRATING_PEAK = 30.0
"""A spectral peak this many times the median power at its spatial frequency (over all
directions) is a grating's."""
GRATING_SHARE = 0.05
"""... and holding at least this share of the image's power beyond the longest pitch."""
GRATING_MAX_PITCH_PX = 120.0
"""Longest pitch looked for [px] (coarser rulings are found line by line)."""


@functools.lru_cache(maxsize=8)
def _rings(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For an rfft2 of this (rows, columns) shape: frequencies fy (rows, 1), fx (1, cols),
    |f|, and each frequency's ring index round(|f| min(shape)). Per shape (read-only; the
    patches of one frame size share them: ~0.5 ms per 256 x 256 patch, twice a frame)."""
    n_r, n_c = shape
    fy = np.fft.fftfreq(n_r)[:, None]
    fx = np.fft.rfftfreq(n_c)[None, :]
    f = np.hypot(fx, fy)
    out = (fy, fx, f, np.rint(f * min(n_r, n_c)).astype(int))
    for x in out:
        x.flags.writeable = False
    return out


@functools.lru_cache(maxsize=8)
def _window_and_counts(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """For a patch of this shape: its 2-D Hann window and the number of rfft2 bins in each
    ring of :func:`_rings` (read-only; a frame's ~40 tiles near a 5 MP mark share them)."""
    win = np.outer(np.hanning(shape[0]), np.hanning(shape[1]))
    cnt = np.bincount(_rings(shape)[3].ravel())
    for x in (win, cnt):
        x.flags.writeable = False
    return win, cnt


def spectral_grating(a: np.ndarray, max_pitch_px: float = 120.0
                     ) -> tuple[float, float] | None:
    """(pitch [px], line direction [rad]) of a grating filling the patch ``a`` [DN], or None.

    The spectrum (Hann window, mean removed) of a grating is a sharp peak at 1/pitch across
    its lines; texture, noise and isolated lines spread their power. The frequency standing
    out most above the typical power of its ring (at least :data:`GRATING_PEAK` times), or
    its lowest, stronger sub-harmonic that also does (a sharp-edged ruling's fundamental), must
    hold :data:`GRATING_SHARE` of all the power at frequencies above 1/``max_pitch_px``.
    A ring's typical power is its median, taken as 1.23 times its geometric mean (the two's
    ratio for noise's exponentially distributed power, ln 2 e^gamma): one sum per ring
    instead of a sort, ~1 ms per 256 x 256 patch.
    """
    n_r, n_c = a.shape
    if min(n_r, n_c) < 32:
        return None
    a = np.asarray(a, float)
    win, cnt = _window_and_counts(a.shape)
    a = (a - a.mean()) * win
    p = np.abs(np.fft.rfft2(a)) ** 2
    fy, fx, f, rb = _rings(a.shape)
    band = f > 1 / max_pitch_px
    if not band.any() or p[band].sum() == 0:
        return None
    # Each frequency's power against its ring's (all directions): an edge's or a blob's
    # power falls off smoothly with frequency, a grating's stands out of its ring.
    logp = np.log(np.maximum(p, 1e-300))
    med = np.log(2) * np.exp(np.euler_gamma) * np.exp(
        np.bincount(rb.ravel(), logp.ravel()) / np.maximum(cnt, 1))
    ref = med[rb]
    ratio = np.divide(p, ref, out=np.zeros_like(p), where=band & (ref > 0))
    i = np.unravel_index(int(np.argmax(ratio)), p.shape)
    if ratio[i] < GRATING_PEAK:
        return None
    # The peak may be a harmonic of a sharp-edged ruling: the fundamental is the lowest
    # sub-harmonic (f/m, same direction) that stands out of its ring too and is stronger
    # (a ruling's harmonics are weaker than its fundamental, the blur weakens them more).
    for m in (5, 4, 3, 2):
        j = (int(np.rint(fy[i[0], 0] / m * n_r)) % n_r, int(np.rint(fx[0, i[1]] / m * n_c)))
        if band[j] and ratio[j] >= GRATING_PEAK and p[j] >= p[i]:
            i = j
            break
    if p[i] < GRATING_SHARE * float(p[band].sum()):
        return None
    # An edge's (a shadow's) power falls off from zero frequency along its normal: its
    # strongest frequency in the band stands out of its ring, but the same direction two
    # bins further in is stronger still; a grating's peak stands above it (a Hann window's
    # leakage is nil two bins from a peak).
    s = max(0.0, 1 - 2 / (float(f[i]) * min(n_r, n_c)))
    j = (int(np.rint(fy[i[0], 0] * s * n_r)) % n_r, int(np.rint(fx[0, i[1]] * s * n_c)))
    if j != i and p[j] > p[i]:
        return None
    # Refine the peak's frequency by the power-weighted mean of its 3 x 3 neighbourhood.
    rr = np.clip(np.arange(i[0] - 1, i[0] + 2), 0, n_r - 1)
    cc = np.clip(np.arange(i[1] - 1, i[1] + 2), 0, p.shape[1] - 1)
    wgt = p[np.ix_(rr, cc)]
    vx = float(np.sum(wgt * fx[0, cc][None, :]) / wgt.sum())
    vy = float(np.sum(wgt * fy[rr, 0][:, None]) / wgt.sum())
    # The lines run across the frequency vector (x right, y down; angles counter-clockwise).
    return 1 / float(np.hypot(vx, vy)), wrap_angle(float(np.arctan2(-vx, -vy)))


def grating_note(image: np.ndarray, size: int = 512) -> str | None:
    """What to say when an image holds a grating: None, or "a grating of pitch p px, lines at
    a deg: ..." from the power spectrum of its central ``size`` x ``size`` pixels
    (:func:`spectral_grating`, pitches up to :data:`GRATING_MAX_PITCH_PX`).

    Parameters
    ----------
    image : (H, W) array
        The image [DN].
    size : int
        Side of the central square examined [px].

    Returns
    -------
    str or None
        The sentence naming the grating (pitch [px], direction [deg]) and why it is not
        measured; None when the spectrum shows no grating.
    """
    h, w = image.shape
    r0, c0 = max(0, (h - size) // 2), max(0, (w - size) // 2)
    got = spectral_grating(image[r0:r0 + size, c0:c0 + size], GRATING_MAX_PITCH_PX)
    if got is None:
        return None
    pitch, angle = got
    return (f"a grating (identical parallel lines, none standing out) of pitch {pitch:.1f} px, "
            f"lines at {np.rad2deg(angle):.1f}°: gratings are not measured (the search reads "
            "a row of identical lines as a surface's lay, and the groove model needs each "
            "line alone in its window); give a ruling whose lines differ (a scale's long and "
            "short graduations) or measure single marks")


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


RULING_HARMONICS = 5
"""A measured ruling's spectrum holds its harmonics up to this order (pitch / m): a tile
whose search window is shorter than the ruling's pitch (:data:`TILE` / 4) shows the
ruling's second harmonic as the strongest peak; it is the measured ruling's profile, not
another grating."""


def explained_by_ruling(pitch_px: float, angle_rad: float, ruling_pitch_px: float,
                        ruling_angle_rad: float) -> bool:
    """Whether a grating of this pitch [px] and line direction [rad] is a measured ruling's
    own spectrum: its direction (within :data:`SAME_ANGLE`, or a tile's spectral bin,
    pitch / :data:`TILE` rad, when wider) and its pitch or one of its
    harmonics ruling / m, m = 1 .. :data:`RULING_HARMONICS` (ruling / pitch within
    :data:`SAME_PITCH` of m: frequencies within that fraction of the fundamental's)."""
    # (A tile's direction is one spectral bin wide at most, pitch / TILE [rad]: 6.4° for a
    # 28.8 px harmonic, whose direction came 3.4° off its measured ruling's.)
    tol = max(SAME_ANGLE, pitch_px / TILE)
    if abs((angle_rad - ruling_angle_rad + np.pi / 2) % np.pi - np.pi / 2) >= tol:
        return False
    # Frequencies within SAME_PITCH of the ruling's fundamental of m times it: a harmonic's
    # relative tolerance does not widen with m (at 10 % of m / pitch, 20 px would pass as
    # a 65.6 px ruling's third harmonic).
    ratio = ruling_pitch_px / pitch_px
    return any(abs(ratio - m) < SAME_PITCH for m in range(1, RULING_HARMONICS + 1))


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
        Rulings already measured (a family's pitch and direction): not named again, nor
        their harmonics (:func:`explained_by_ruling`).

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
        if any(explained_by_ruling(pitch, ang, p, a) for p, a in known):
            continue
        boxes = np.array([f[2] for f in g])
        out.append(GratingRegion(pitch, ang, (int(boxes[:, 0].min()), int(boxes[:, 1].min()),
                                              int(boxes[:, 2].max()), int(boxes[:, 3].max())),
                                 len(g)))
    return sorted(out, key=lambda r: -r.tiles)
