"""The scale wander the poses' own slopes show (issue 19): user6's HVAC cycle through
`align calibrate` with nothing declared, k against k at the mean time.

Run:  python3 benchmarks/calibration_wander.py [--seeds 8] [--ppm 100]

user6's renderer (tests/align/user6_inputs.py: the paper's 14 poses, 60 s at 20 Hz, 30 s
turns, a scale factor 1 + X sin(2 pi t / 900 s + phase), no temperature column); per seed the
exit status, ok, |err|/u of the three scale factors and whether the wander was found; then
RMS and max over all. ``--ppm 0``: the clean control. Against another checkout (the tool
before): ``PYTHONPATH=/path/to/other python3 benchmarks/calibration_wander.py``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import benchpage
import numpy as np

from tests.align import user6_inputs as U
from tests.align.test_independent_user6 import cal_json, k_z, triad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--ppm", type=float, default=100.0)
    a = ap.parse_args()
    zs, found, nok = [], 0, 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(a.seeds):
            tri, rng = triad(seed)
            ph = rng.uniform(0, 2 * np.pi)

            def sf(t, ph=ph):
                return 1 + a.ppm * 1e-6 * np.sin(2 * np.pi * t / 900.0 + ph)

            rows = U.tumble_rows(tri, U.cube14(), rng, n=1200, scale_of_t=sf, t_gap=30.0)
            ts = np.array([r[1] for r in rows])
            rc, js, err = cal_json(U.write_tumble(Path(tmp) / f"t{seed}.csv", rows))
            z = k_z(js, tri.k * sf(np.array([ts.mean()]))[0])
            w = (js.get("scale_stability") or {}).get("wander")
            hit = bool(w and w["found"])
            zs.append(z)
            found += hit
            nok += not js["ok"]
            print(f"| {seed} | {rc} | {js['ok']} | {' '.join(f'{v:+.2f}' for v in z)} | "
                  f"{'found' if hit else 'no' if w else '-'} |", flush=True)
    z = np.array(zs)
    print(f"±{a.ppm:g} ppm, seeds 0-{a.seeds - 1}: k |err|/u RMS {np.sqrt(np.mean(z**2)):.2f}, "
          f"max {np.abs(z).max():.2f}; wander found {found}/{a.seeds}; not ok {nok}/{a.seeds}")


if __name__ == "__main__":
    benchpage.run(main, "Calibration: the scale wander from the poses' slopes")
