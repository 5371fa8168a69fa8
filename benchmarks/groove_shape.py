"""The groove's own cross-profile (issue 18): z with and without its u term, and what it costs.

Run:  python3 benchmarks/groove_shape.py [--what nh edge fresh synth] [--off]

``nh``: user6's rounded grooves within 0.3 deg of horizontal (16-bit, 8x8 sub-pixel samples,
seeds 100-129, its test's scene); ``edge``: user6's mark 6 px from the bottom edge under 35 %
vignetting (12-bit, seeds 0-15: its test's); ``fresh``: the same at seeds 16-47; ``synth``:
synth's own clean marks (round and box profiles, 33 each: a third within 0.3 deg of 0 deg, a
third of 90 deg, a third at any angle), u with the Type B term ``groove_profile`` over u
without it (median). ``--off`` measures without the groove's own profile
(``imaging.centres.fit_shape`` -> None: no ``groove_profile`` term); the frame-edge
symmetric window stays. Each mark through ``align marks`` in process, lens
declared absent, as the tests call it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

import imaging.centres  # noqa: E402
from synth.marks import render_marks, write_image  # noqa: E402
from synth.specs import ImageSpec, MarkSpec  # noqa: E402
from tests.align import user6_inputs as U  # noqa: E402
from tests.cli import run_cli  # noqa: E402

NO_LENS = ("--lens", "k1=0,k2=0,p=0,aspect=0,pp_px=0")


def _mark(path: Path) -> dict:
    rc, out, err = run_cli("marks", str(path), *NO_LENS, "--json", "-", "-q")
    return [m for m in json.loads(out)["marks"] if m.get("found", True)][0]


def user6(which: str, seeds: range, tmp: Path) -> np.ndarray:
    zs = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        a = rng.uniform(-0.3, 0.3)
        if which == "nh":
            sc = U.Scene(640, 480, (U.Mark(320 + rng.uniform(-20, 20), 240 + rng.uniform(-20, 20),
                                           a, 300),), seed=seed, bits=16, vignetting=0.0, ss=8)
        else:
            sc = U.Scene(640, 480, (U.Mark(320 + rng.uniform(-20, 20), 473, a, 300),),
                         seed=seed, bits=12, vignetting=0.35)
        m = _mark(U.write_image(tmp / f"{which}{seed}.png", U.render(sc)))
        zs.append(U.wrap_deg(m["angle_deg"] - a) * 3600 / m["angle_u_arcsec"])
    return np.asarray(zs)


def synth_marks(profile: str, tmp: Path) -> tuple[np.ndarray, np.ndarray]:
    us, zs = [], []
    for seed in range(33):
        rng = np.random.default_rng(1000 + seed)
        a = (np.deg2rad(rng.uniform(-0.3, 0.3) + 90 * (seed % 3 == 1)) if seed % 3 < 2
             else rng.uniform(-np.pi / 2, np.pi / 2))
        spec = ImageSpec(marks=(MarkSpec(a, rng.uniform(-20, 20), 300.0, profile=profile),),
                         width=640, height=480, seed=seed)
        path = tmp / f"s{profile}{seed}.png"
        if not path.exists():
            write_image(path, render_marks(spec, with_crlb=False).image)
        m = _mark(path)
        d = (m["angle_deg"] - np.rad2deg(a) + 90) % 180 - 90
        us.append(m["angle_u_arcsec"])
        zs.append(d * 3600 / m["angle_u_arcsec"])
    return np.asarray(us), np.asarray(zs)


def _line(name: str, z: np.ndarray) -> str:
    return f"{name}: RMS z {np.sqrt(np.mean(z ** 2)):.2f}, max |z| {np.abs(z).max():.2f} ({len(z)})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--what", nargs="+", default=["nh", "edge", "fresh", "synth"])
    ap.add_argument("--off", action="store_true", help="without the groove_profile term")
    args = ap.parse_args()
    real_fit = imaging.centres.fit_shape
    if args.off:
        imaging.centres.fit_shape = lambda *a: None
    tmp = Path(tempfile.mkdtemp())
    for what in args.what:
        if what == "nh":
            print(_line("user6 near-horizontal", user6("nh", range(100, 130), tmp)))
        elif what in ("edge", "fresh"):
            seeds = range(16) if what == "edge" else range(16, 48)
            print(_line(f"user6 frame edge seeds {seeds.start}-{seeds.stop - 1}",
                        user6("edge", seeds, tmp)))
        elif what == "synth":
            for profile in ("round", "box"):
                imaging.centres.fit_shape = lambda *a: None
                u0, z0 = synth_marks(profile, tmp)
                imaging.centres.fit_shape = real_fit
                u1, z1 = synth_marks(profile, tmp)
                r = u1 / u0
                print(f"synth {profile}: u ratio median {np.median(r):.3f} (near 0 deg "
                      f"{np.median(r[0::3]):.3f}, near 90 {np.median(r[1::3]):.3f}, any "
                      f"{np.median(r[2::3]):.3f}), max {r.max():.2f}; "
                      + _line("without", z0) + "; " + _line("with", z1))


if __name__ == "__main__":
    main()
