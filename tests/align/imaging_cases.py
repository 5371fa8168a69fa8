"""Imaging effects the groove model lacks (issue 18 item 4), rendered by synth's physics.

Each *class* is one 640x480 image with one 400 px mark and one effect: a defocus gradient
along the mark (blur 1 -> 3 px), column / row fixed-pattern noise of 1-2 % of the mark's
contrast on a near-vertical / near-horizontal mark, JPEG at quality 50-90; and clean
controls (16-bit, textured with dust, 8-bit). :func:`run` measures one seed through
``align.marks.measure_image`` (no lens: declared flat) and returns the normalised error and
the notes; :data:`FLAG` says which words in a note name each effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from align.lens import LensRanges
from align.marks import measure_image
from synth import ImageSpec, MarkSpec, full_well_for_snr, render_marks

CONTRAST = 0.6
CLASSES: dict[str, dict] = {
    "clean": {},
    "clean textured": {"texture": 0.01, "texture_angle_rad": np.deg2rad(17.0), "dust": 4},
    "clean 8-bit": {"bits": 8, "exposure": 0.4},
    "defocus 1->3 px": {"defocus": 2.0},
    "column FPN 1 %": {"column_fpn": 0.01 * CONTRAST, "vertical": True},
    "column FPN 2 %": {"column_fpn": 0.02 * CONTRAST, "vertical": True},
    "row FPN 1.5 %": {"row_fpn": 0.015 * CONTRAST},
    "JPEG q50": {"bits": 8, "exposure": 0.4, "jpeg_quality": 50, "vertical": True},
    "JPEG q70": {"bits": 8, "exposure": 0.4, "jpeg_quality": 70, "vertical": True},
    "JPEG q90": {"bits": 8, "exposure": 0.4, "jpeg_quality": 90, "vertical": True},
}
FLAG = {"defocus": "defocus gradient", "column_fpn": "column stripes",
        "row_fpn": "row stripes", "jpeg_quality": "JPEG compression"}
"""The words of the note that names each effect."""
NEW_FLAGS = tuple(FLAG.values())


@dataclass(frozen=True)
class Outcome:
    """One seed: ``z`` the angle's error / u, ``err_arcsec``, ``u_arcsec``, ``flagged``
    whether a note names the class's effect (controls: whether any note names one of
    :data:`NEW_FLAGS`), ``notes``."""

    z: float
    err_arcsec: float
    u_arcsec: float
    flagged: bool
    notes: tuple[str, ...]


def render(name: str, seed: int):
    """The class's image for ``seed`` (angle and offset drawn from the seed)."""
    kw = dict(CLASSES[name])
    rng = np.random.default_rng([seed, 18])
    vertical = kw.pop("vertical", False)
    a = np.deg2rad((90.0 if vertical else 0.0) + rng.uniform(0.05, 0.5) * rng.choice([-1, 1]))
    mark = MarkSpec(a, rng.uniform(-40, 40), 400.0, 4.0, contrast=-CONTRAST)
    if "defocus" in kw:
        g = kw.pop("defocus") / mark.length_px  # blur 1 -> 3 px end to end
        kw.update(blur_px=2.0, blur_gradient=(g * np.cos(a), -g * np.sin(a)), supersample=3)
    exposure = kw.pop("exposure", 0.5)
    spec = ImageSpec(marks=(mark,), width=640, height=480, exposure=exposure,
                     full_well_e=full_well_for_snr(40, -CONTRAST, exposure), seed=seed, **kw)
    return render_marks(spec, with_crlb=False)


def run(name: str, seed: int) -> Outcome:
    s = render(name, seed)
    (r,) = measure_image(s.image, ranges=LensRanges.none())
    err = float((r.angle_rad - s.truth.marks[0].image_angle_rad + np.pi / 2) % np.pi
                - np.pi / 2)
    words = [w for k, w in FLAG.items() if k in CLASSES[name]] or list(NEW_FLAGS)
    flagged = any(w in n for n in r.notes for w in words)
    arcsec = 180 / np.pi * 3600
    return Outcome(err / r.angle_u_rad, err * arcsec, r.angle_u_rad * arcsec, flagged,
                   tuple(r.notes))


def table(seeds: int = 10) -> dict[str, tuple[float, float, int, int]]:
    """Per class: (RMS z, max |z|, flagged, seeds)."""
    out = {}
    for name in CLASSES:
        res = [run(name, s) for s in range(seeds)]
        z = np.array([o.z for o in res])
        out[name] = (float(np.sqrt(np.mean(z**2))), float(np.max(np.abs(z))),
                     sum(o.flagged for o in res), seeds)
    return out


if __name__ == "__main__":
    import sys

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    print(f"{'class':18s} {'RMS z':>6s} {'max|z|':>7s} {'flagged':>8s}")
    for name, (rms, mx, fl, k) in table(n).items():
        print(f"{name:18s} {rms:6.2f} {mx:7.2f} {fl:4d}/{k}")
