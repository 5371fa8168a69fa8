"""Synthetic microscope images of a ruled scale (a stage micrometer), with known truth.

A stage micrometer is a row of engraved graduations: parallel straight grooves at a uniform
pitch, all starting on one baseline, every 5th one longer ("medium") and every 10th longer
still ("long"), with printed numerals beyond the long ones' ends. The image is rendered as
physics, by the same machinery as :mod:`synth.marks`: each graduation is a groove (depth
profile integrated over the pixel area, seen through a Gaussian PSF); numerals and a maker's
logo are printed strokes through the same blur; dust specks (some on the graduations);
vignetting; shot + read noise; 8, 12 or 16-bit quantisation (12-bit data in 16-bit words).

Truth: every graduation's angle and position (as the ideal pinhole camera sees it), its
length and kind, and the pitch. Lengths in pixels, angles in radians (from +x towards -y).
Nothing here comes from the measurement packages.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from synth.marks import (
    ImageSpec,
    MarkSpec,
    _clutter,
    _digitise,
    _illumination,
    _mark_band,
    _stroke,
    full_well_for_snr,
    mark_coverage,
)
from synth.occlusion import Occluder, disk, occlude, strokes
from synth.optics import CameraGeometry, wrap_half_turn

KINDS = ("short", "medium", "long")


@dataclass(frozen=True)
class RuledSpec:
    """One ruled-scale image (all randomness from ``seed``).

    Attributes
    ----------
    width, height : int
        Frame [px].
    pitch_px : float
        Distance between neighbouring graduations [px].
    n_lines : int
        Number of graduations (0: as many as fit in 90 % of the frame along the scale).
    line_angle_rad : float
        Direction of the graduations [rad] (the scale runs across them).
    lengths_px : (short, medium, long)
        Graduation lengths [px]; medium every 5th, long every 10th.
    line_width_px : float
        Groove width at the surface [px].
    contrast : float
        Reflectance change at full depth (negative: dark grooves).
    snr : float
        Groove contrast / background noise at full depth (sets the full well).
    pitch_error_px : float
        RMS ruling error of each graduation's position [px] (0: a perfect ruling).
    tilt : (k, angle_rad) or None
        One graduation (the k-th from the middle of the frame out) turned by this angle
        about its middle (a faulty member).
    offset_px : float
        Scale's middle graduation, along the scale from the frame centre [px].
    numerals, dust, dust_on_lines, logo, vignetting, blur_px, bits, camera :
        Clutter and optics as in :class:`synth.marks.ImageSpec`; numerals beyond each long
        graduation's end, ``dust_on_lines`` specks on random graduations.
    dust_on_ends : int
        Opaque particles (:mod:`synth.occlusion`) each over one end of a random graduation
        (centred within half its radius of the end): the end is hidden under it.
    dust_end_radius_px : (min, max)
        Radius range of those particles [px]; dark (absorbing) or bright (scattering).
    numerals_over_lines : bool
        Print the numerals in opaque ink across the long graduations themselves (at 3/4 of
        their length, reading across them) instead of beyond their ends.
    """

    width: int = 1600
    height: int = 1200
    pitch_px: float = 60.0
    n_lines: int = 0
    line_angle_rad: float = np.pi / 2
    lengths_px: tuple[float, float, float] = (150.0, 200.0, 250.0)
    line_width_px: float = 4.0
    contrast: float = -0.6
    snr: float = 30.0
    pitch_error_px: float = 0.0
    tilt: tuple[int, float] | None = None
    offset_px: float = 0.0
    baseline_px: float = -60.0
    numerals: bool = True
    dust: int = 20
    dust_on_lines: int = 4
    logo: bool = True
    vignetting: float = 0.15
    blur_px: float = 1.5
    bits: int = 16
    supersample: int = 4
    camera: CameraGeometry = field(default_factory=CameraGeometry)
    seed: int = 0
    dust_on_ends: int = 0
    dust_end_radius_px: tuple[float, float] = (3.0, 7.0)
    numerals_over_lines: bool = False


@dataclass(frozen=True)
class GraduationTruth:
    """One graduation as the ideal camera sees it: angle [rad], offset from the frame centre
    along the normal (sin a, cos a) [px], middle (x, y) relative to the centre [px], length
    [px], kind (short/medium/long) and its index along the scale; ``hidden``: what covers
    part of it (``start``/``end``: that end under an opaque particle — ``start`` at the
    baseline; ``ink``: a numeral printed across it; empty: nothing but ordinary dust)."""

    index: int
    kind: str
    angle_rad: float
    offset_px: float
    centre_xy_px: tuple[float, float]
    length_px: float
    hidden: str = ""


@dataclass(frozen=True)
class RuledTruth:
    width: int
    height: int
    pitch_px: float
    line_angle_rad: float
    bits: int
    noise_dn_background: float
    lines: tuple[GraduationTruth, ...]
    tilted: int | None  # the tilted graduation's index, if any
    seed: int

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2)


@dataclass(frozen=True)
class RuledImage:
    image: np.ndarray
    truth: RuledTruth
    mean_e: np.ndarray


def random_ruled(seed: int, width: int = 1600, height: int = 1200, **over) -> RuledSpec:
    """A random scale that fits the frame: pitch 40-140 px, lengths 100-250 px (short),
    any direction (a third within 1 deg of an axis), SNR 15-60, 8/12/16 bits."""
    rng = np.random.default_rng(seed)
    u = rng.uniform()
    if u < 1 / 3:
        angle = np.pi / 2 + np.deg2rad(rng.uniform(-1, 1))
    else:
        angle = rng.uniform(-np.pi / 2, np.pi / 2)
    short = rng.uniform(100, 180)
    spec = RuledSpec(
        width=width, height=height, pitch_px=float(rng.uniform(40, 140)),
        line_angle_rad=wrap_half_turn(float(angle)),
        lengths_px=(short, 1.3 * short, 1.6 * short),
        line_width_px=float(rng.uniform(2.5, 6.0)), snr=float(rng.uniform(15, 60)),
        bits=int(rng.choice([8, 12, 16])), seed=seed)
    return replace(spec, **over)


def _digit_strokes(ch: str) -> list[tuple[int, int]]:
    """Seven-segment strokes of a digit between corners 0..5 of a 1 x 2 box
    (0 top-left, 1 top-right, 2 mid-left, 3 mid-right, 4 bottom-left, 5 bottom-right)."""
    seg = {"a": (0, 1), "b": (1, 3), "c": (3, 5), "d": (4, 5), "e": (2, 4), "f": (0, 2),
           "g": (2, 3)}
    on = {"0": "abcdef", "1": "bc", "2": "abged", "3": "abgcd", "4": "fgbc", "5": "afgcd",
          "6": "afgedc", "7": "abc", "8": "abcdefg", "9": "abcdfg"}[ch]
    return [seg[s] for s in on]


def _text_segments(text: str, org: np.ndarray, size: float, ux: np.ndarray, uy: np.ndarray
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Seven-segment strokes (p0, p1) of ``text`` at ``org``, glyph height ``size`` [px],
    reading along ``ux`` with glyph 'down' along ``uy``."""
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2]]) * size / 2
    out = []
    for k, ch in enumerate(text):
        o = org + k * 0.8 * size * ux
        for i, j in _digit_strokes(ch):
            out.append((o + corners[i][0] * ux + corners[i][1] * uy,
                        o + corners[j][0] * ux + corners[j][1] * uy))
    return out


def _text(out: np.ndarray, text: str, org: np.ndarray, size: float, ux: np.ndarray,
          uy: np.ndarray, amp: float, blur: float) -> None:
    """Printed seven-segment text at ``org`` (frame pixels), glyph height ``size`` [px],
    reading along ``ux`` with glyph 'down' along ``uy`` (additive, as a faint print)."""
    for p0, p1 in _text_segments(text, org, size, ux, uy):
        _stroke(out, p0, p1, 0.12 * size, amp, blur)


def _logo(out: np.ndarray, spec: RuledSpec, grads: list) -> None:
    """A maker's logo in a corner: a printed ring with a bar and a short word of strokes."""
    h, w = out.shape
    r = 0.04 * min(w, h)
    # In the corner farthest from the graduations (a maker prints it clear of the scale).
    mids = np.array([m.centre_xy() for m, _, _ in grads]) + [(w - 1) / 2, (h - 1) / 2]
    corners = [(fx * w, fy * h) for fx in (0.12, 0.88) for fy in (0.12, 0.88)]
    cx, cy = max(corners, key=lambda p: np.min(np.hypot(*(mids - p).T)))
    s = max(spec.blur_px, 0.3)
    r0, c0 = int(max(0, cy - r - 6 * s)), int(max(0, cx - r - 6 * s))
    yy, xx = np.mgrid[r0:int(min(h, cy + r + 6 * s + 1)), c0:int(min(w, cx + r + 6 * s + 1))]
    d = np.hypot(xx - cx, yy - cy)
    from scipy.special import erf

    # A ring of width 0.2 r: the difference of two blurred edges (a box profile in radius).
    ring = 0.5 * (erf((d - 0.8 * r) / (np.sqrt(2) * s)) - erf((d - r) / (np.sqrt(2) * s)))
    out[yy, xx] -= 0.5 * ring
    _stroke(out, np.array([cx - 0.7 * r, cy]), np.array([cx + 0.7 * r, cy]), 0.15 * r, -0.5,
            spec.blur_px)
    _text(out, "10", np.array([cx + 1.3 * r, cy - 0.5 * r]), r, np.array([1.0, 0.0]),
          np.array([0.0, 1.0]), -0.5, spec.blur_px)


def graduations(spec: RuledSpec, rng: np.random.Generator) -> list[tuple[MarkSpec, str, int]]:
    """The graduations as grooves in the scene (mark, kind, index along the scale): every
    one whose ends (and numeral) lie at least 20 px inside the frame, or the first
    ``n_lines`` of them from the middle out."""
    a = spec.line_angle_rad
    u = np.array([np.cos(a), -np.sin(a)])
    nrm = np.array([np.sin(a), np.cos(a)])
    half = np.array([(spec.width - 1) / 2, (spec.height - 1) / 2]) - 20.0
    reach = int(np.hypot(spec.width, spec.height) // spec.pitch_px) + 1
    first = int(rng.integers(0, 10))  # where the decade falls on the visible stretch
    errors = spec.pitch_error_px * rng.standard_normal(2 * reach + 1)
    out = []
    for k in sorted(range(-reach, reach + 1), key=abs):
        j = first + k
        kind = "long" if j % 10 == 0 else "medium" if j % 5 == 0 else "short"
        length = spec.lengths_px[KINDS.index(kind)]
        pos = spec.offset_px + k * spec.pitch_px + errors[k + reach]
        extra = min(0.35 * spec.pitch_px, 40.0) * 1.6 if spec.numerals and kind == "long" else 0
        ends = [pos * nrm + t * u for t in (spec.baseline_px, spec.baseline_px + length + extra)]
        if any(np.any(np.abs(e) > half) for e in ends):
            continue
        if spec.n_lines and len(out) >= spec.n_lines:
            break
        ang = a
        if spec.tilt is not None and spec.tilt[0] == len(out):  # counted from the middle
            ang = a + spec.tilt[1]
        # All graduations start on the baseline and run along +u; a tilt turns one about its
        # middle.
        mid = pos * nrm + (spec.baseline_px + length / 2) * u
        # Offset and position along it in the frame of the wrapped angle (the one stored):
        # across +-90 deg the normal flips, and with it their signs.
        ang = wrap_half_turn(float(ang))
        off = float(mid @ np.array([np.sin(ang), np.cos(ang)]))
        ct = float(mid @ np.array([np.cos(ang), -np.sin(ang)]))
        out.append((MarkSpec(ang, off, length, spec.line_width_px, ct,
                             "round", spec.contrast), kind, j))
    out.sort(key=lambda g: g[2])
    return out


def render_ruled(spec: RuledSpec) -> RuledImage:
    """Render a ruled-scale image and its truth."""
    if spec.bits not in (8, 12, 16):
        raise ValueError("bits must be 8, 12 or 16")
    rng = np.random.default_rng(spec.seed)
    grads = graduations(spec, rng)
    full_well = full_well_for_snr(spec.snr, spec.contrast)
    base = ImageSpec(marks=tuple(g[0] for g in grads), width=spec.width, height=spec.height,
                     blur_px=spec.blur_px, full_well_e=full_well, bits=spec.bits,
                     supersample=spec.supersample, vignetting=spec.vignetting,
                     dust=spec.dust, dust_on_mark=spec.dust_on_lines, camera=spec.camera,
                     seed=spec.seed)
    refl = np.ones((spec.height, spec.width))
    margin = 7 * spec.blur_px + 3
    for m, _, _ in grads:
        r, c = _mark_band(base, m, margin)
        refl[r, c] += m.contrast * mark_coverage(base, m, r, c)
    # Dust on random graduations (the base's marks), specks elsewhere.
    refl += _clutter(base, rng)
    centre = np.array([(spec.width - 1) / 2, (spec.height - 1) / 2])
    a = spec.line_angle_rad
    u = np.array([np.cos(a), -np.sin(a)])
    nrm = np.array([np.sin(a), np.cos(a)])
    ink: list[Occluder] = []
    hidden: dict[int, str] = {}
    if spec.numerals:
        size = min(0.35 * spec.pitch_px, 40.0)
        for m, kind, j in grads:
            if kind != "long":
                continue
            # Beyond the long graduation's end, a glyph-gap further, reading across the lines.
            x, y = m.centre_xy()
            text = str(abs(j))
            if spec.numerals_over_lines:
                # Across the graduation at 3/4 of its length, in opaque ink: the line
                # runs through the middle of the last glyph (a '0': its top and bottom bars
                # cross it).
                top = np.array([x, y]) + (m.length_px / 4 + size / 2) * u
                start = top - (0.8 * (len(text) - 1) + 0.25) * size * nrm
                ink.append(strokes(_text_segments(text, start, size, nrm, -u), 0.12 * size,
                                   level=0.05))
                hidden[j] = "ink"
                continue
            top = np.array([x, y]) + (m.length_px / 2 + 1.4 * size) * u
            start = centre + top - 0.4 * size * len(text) * nrm
            # Glyphs read across the graduations, their foot towards the line's end.
            _text(refl, text, start, size, nrm, -u, -0.55, spec.blur_px)
    if spec.logo:
        _logo(refl, spec, grads)
    # Opaque particles over graduations' ends (their own stream: the other draws, hence
    # the scales rendered without them, stay as they were).
    rng_end = np.random.default_rng([spec.seed, 1])
    for j in rng_end.permutation(len(grads))[:spec.dust_on_ends]:
        m, _, idx = grads[j]
        r = rng_end.uniform(*spec.dust_end_radius_px)
        side = rng_end.choice(["start", "end"])
        ua = np.array([np.cos(m.angle_rad), -np.sin(m.angle_rad)])
        na = np.array([np.sin(m.angle_rad), np.cos(m.angle_rad)])
        # The graduation runs from the baseline along +u (the tilt aside): 'start' is there.
        sgn = 1.0 if float(ua @ u) > 0 else -1.0
        t_end = m.centre_t_px + sgn * (m.length_px / 2 if side == "end" else -m.length_px / 2)
        t_end += rng_end.uniform(-0.5, 0.5) * r
        p = m.offset_px * na + t_end * ua + rng_end.uniform(-0.3, 0.3) * r * na
        px, py = spec.camera.distort(*spec.camera.scene_to_ideal(p[0], p[1]))
        ink.append(disk(float(px), float(py), r, level=0.05 if rng_end.uniform() < 0.7
                        else 1.6))
        hidden[idx] = str(side)
    occlude(refl, ink, [g[0] for g in grads], spec.blur_px, spec.camera)
    mean_e = np.clip(refl, 0, None) * _illumination(base) * base.exposure * full_well
    img = _digitise(base, mean_e, rng)
    gain = (2**spec.bits - 1) / full_well
    noise_dn = float(np.sqrt(base.exposure * full_well + base.read_noise_e**2) * gain)
    truths = []
    for m, kind, j in grads:
        ia = spec.camera.image_angle(m.angle_rad)
        cx, cy = m.centre_xy()
        ix, iy = spec.camera.scene_to_ideal(np.array(cx), np.array(cy))
        truths.append(GraduationTruth(j, kind, ia, float(ix * np.sin(ia) + iy * np.cos(ia)),
                                      (float(ix), float(iy)), m.length_px, hidden.get(j, "")))
    tilted = next((j for m, _, j in grads if m.angle_rad != wrap_half_turn(a)), None)
    truth = RuledTruth(spec.width, spec.height, spec.pitch_px,
                       spec.camera.image_angle(spec.line_angle_rad), spec.bits, noise_dn,
                       tuple(truths), tilted, spec.seed)
    return RuledImage(img, truth, mean_e)
