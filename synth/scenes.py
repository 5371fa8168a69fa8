"""Random scenes that cover what users bring: any frame size, bit depth, mark and clutter.

:func:`random_scene` draws one :class:`~synth.marks.ImageSpec` from a seed:

* frames from 0.3 to 12 MP (``sizes``), 8, 12 or 16 bits;
* 0-3 marks, each 100 px long up to the longest that fits the frame at its angle (lengths
  log-uniform), anywhere in the frame (a quarter of them hugging an edge, a few px inside),
  at any angle with extra weight within +-1 deg of 0 and 90 deg; widths 2-8 px, SNR 8-100
  (contrast of the groove at full depth over the background noise; at most 0.75 dark or 0.6
  bright, so that no groove clips), dark or bright, any groove profile; marks do not touch
  each other;
* clutter: dust, thin scratches up to 60 % of ``MIN_MARK_PX`` long, printed labels (numeral-like
  glyphs), border darkening (vignetting), sometimes an illumination gradient and a few rows
  and columns of zero padding along the edges.

All of it is rendered by :func:`synth.marks.render_marks` (physics: groove profile integrated
over the pixel area, blur, shot + read noise, quantisation). Lengths in pixels, angles in
radians.
"""

from __future__ import annotations

import numpy as np

from synth.marks import ImageSpec, MarkSpec, full_well_for_snr

MIN_MARK_PX = 100.0
SIZES: tuple[tuple[int, int], ...] = ((640, 480), (800, 600), (1024, 768), (1280, 1024),
                                      (1600, 1200), (2448, 2048), (4000, 3000))
# Most scenes are small so a few hundred render in a minute; large ones are still drawn.
SIZE_WEIGHTS = (0.25, 0.2, 0.2, 0.17, 0.1, 0.05, 0.03)
PROFILES = ("box", "v", "round")


def _angle(rng: np.random.Generator) -> float:
    """Direction [rad]: 30 % within +-1 deg of 0 deg, 20 % of 90 deg, else uniform."""
    u = rng.uniform()
    if u < 0.3:
        return float(np.deg2rad(rng.uniform(-1, 1)))
    if u < 0.5:
        return float(np.deg2rad(90 + rng.uniform(-1, 1)))
    return float(rng.uniform(-np.pi / 2, np.pi / 2))


def _segment_distance(p: tuple[np.ndarray, np.ndarray], q: tuple[np.ndarray, np.ndarray]
                      ) -> float:
    """Shortest distance between two segments (end points) [px] (sampled: enough here)."""
    s = np.linspace(0, 1, 64)[:, None]
    a = p[0] + s * (p[1] - p[0])
    b = q[0] + s * (q[1] - q[0])
    return float(np.min(np.hypot(*(a[:, None, :] - b[None, :, :]).transpose(2, 0, 1))))


def _place(rng: np.random.Generator, w: int, h: int, angle: float, width: float, blur: float
           ) -> tuple[float, float, float] | None:
    """(length, offset, centre_t) of a mark wholly inside the frame, or None if none fits."""
    u = np.array([np.cos(angle), -np.sin(angle)])
    n = np.array([np.sin(angle), np.cos(angle)])
    edge = width / 2 + 3 * blur + rng.uniform(3, 15)  # room between the groove and the edge
    hugging = rng.uniform() < 0.25
    # Longest length that fits at this angle with ``edge`` of room on every side.
    lim = []
    for half_side, uc, nc in (((w - 1) / 2, abs(u[0]), abs(n[0])),
                              ((h - 1) / 2, abs(u[1]), abs(n[1]))):
        if uc > 1e-9:
            lim.append(2 * (half_side - edge - nc * width / 2) / uc)
    longest = min(lim) if lim else float(max(w, h))
    if longest < MIN_MARK_PX:
        return None
    length = float(np.exp(rng.uniform(np.log(MIN_MARK_PX), np.log(longest))))
    ext = np.abs(u) * length / 2 + np.abs(n) * width / 2  # half extents of the mark's box
    room = np.array([(w - 1) / 2, (h - 1) / 2]) - edge - ext
    room = np.maximum(room, 0.0)
    mid = rng.uniform(-room, room)
    if hugging:
        k = int(rng.integers(2))
        mid[k] = np.sign(rng.uniform(-1, 1)) * room[k]
    return length, float(mid @ n), float(mid @ u)


def random_scene(seed: int, sizes: tuple[tuple[int, int], ...] = SIZES,
                 weights: tuple[float, ...] = SIZE_WEIGHTS, max_marks: int = 3) -> ImageSpec:
    """One random scene (everything drawn from ``seed``); render it with ``render_marks``."""
    rng = np.random.default_rng(seed)
    w, h = sizes[int(rng.choice(len(sizes), p=np.asarray(weights) / np.sum(weights)))]
    bits = int(rng.choice([8, 12, 16]))
    blur = float(rng.uniform(0.8, 2.0))
    n_marks = int(rng.integers(0, max_marks + 1))
    snr = float(np.exp(rng.uniform(np.log(8), np.log(100))))
    contrast_ref = -0.6
    marks: list[MarkSpec] = []
    segs: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(40 * max(n_marks, 1)):
        if len(marks) >= n_marks:
            break
        a = _angle(rng)
        width = float(rng.uniform(2, 8))
        placed = _place(rng, w, h, a, width, blur)
        if placed is None:
            continue
        length, off, ct = placed
        u = np.array([np.cos(a), -np.sin(a)])
        n = np.array([np.sin(a), np.cos(a)])
        mid = off * n + ct * u
        seg = (mid - length / 2 * u, mid + length / 2 * u)
        if any(_segment_distance(seg, s) < 30 + width for s in segs):
            continue
        # Each mark its own SNR around the scene's (same surface, engraved alike), >= 8.
        # Contrast at most 0.75 dark / 0.6 bright: no groove clipped at black or full scale.
        snr_k = max(8.0, snr * float(np.exp(rng.normal(0, 0.3))))
        dark = rng.uniform() < 0.8
        c = min(abs(contrast_ref) * snr_k / snr, 0.75 if dark else 0.6)
        marks.append(MarkSpec(a, off, length, width, ct, str(rng.choice(PROFILES)),
                              -c if dark else c))
        segs.append(seg)
    read = float(rng.uniform(2, 20))
    return ImageSpec(
        marks=tuple(marks), width=w, height=h, blur_px=blur, bits=bits,
        full_well_e=full_well_for_snr(snr, contrast_ref, read_noise_e=read), read_noise_e=read,
        supersample=4, vignetting=float(rng.uniform(0, 0.6)),
        gradient=(float(rng.normal(0, 0.05)), float(rng.normal(0, 0.05))),
        dust=int(rng.integers(0, 30)), scratches=int(rng.integers(0, 8)),
        scratch_max_px=0.6 * MIN_MARK_PX, text=int(rng.integers(0, 4)),
        padding_px=int(rng.choice([0, 0, 0, 2, 4])), seed=seed)


def kinked_pair(seed: int, kink_deg: float, length_px: float = 200.0
                ) -> tuple[ImageSpec, tuple[float, float]]:
    """Two straight strokes sharing an end point near the centre, at ``kink_deg`` [deg] to
    each other (a "V" / bent-line corner), 640x480, SNR 50; and the strokes' angles [rad].

    Each stroke is its own groove (where they overlap at the joint the reflectance losses
    add, clipped at black, as two scribed passes deepen the groove there).
    """
    rng = np.random.default_rng(seed)
    a1 = float(np.deg2rad(rng.uniform(-20, 20)))
    a2 = a1 + float(np.deg2rad(kink_deg) * rng.choice([-1, 1]))
    joint = rng.uniform(-20, 20, 2)
    marks = []
    for a, side in ((a1, -1), (a2, 1)):
        u, n = np.array([np.cos(a), -np.sin(a)]), np.array([np.sin(a), np.cos(a)])
        mid = joint + side * u * length_px / 2
        marks.append(MarkSpec(a, float(mid @ n), length_px, 4.0, centre_t_px=float(mid @ u)))
    return ImageSpec(marks=tuple(marks), width=640, height=480,
                     full_well_e=full_well_for_snr(50, -0.6), seed=seed), (a1, a2)
