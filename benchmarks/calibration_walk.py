"""A bias that random-walks (issue 19): |err|/u of the scale factors and beta, effects taken.

Run:  python3 benchmarks/calibration_walk.py [--seeds 20]

Classes: the independent user's renderer (tests/align/user5_inputs.py: a walk per sample at
100 Hz, frozen while the unit is turned; its CSV read by ``read_poses`` as ``align calibrate``
reads it) at 1e-7, 3e-7, 1e-6 g per sample and clean; synth's Wiener bias
(``Triad.bias_walk_g``, 20 Hz, 10 s dwell, 5 s turns) at 1e-6, 3e-6, 1e-5 g/√s and clean on the
paper's 14 poses and the plan's 28; the scale drift of 100 ppm over the run on both. Seeds
200 onwards. To measure another version of the calibration (e.g. main's), put its ``align``
first on PYTHONPATH (this tree's synth and tests are used either way: main's synth has no
walk).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import benchpage
import numpy as np

sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

from align.calibration import calibrate  # noqa: E402
from align.calibration.plan import plan  # noqa: E402
from align.calibration.static import read_poses  # noqa: E402
from synth.tumble import TumbleSpec, tumble  # noqa: E402
from tests.align import effects_cases as E  # noqa: E402
from tests.align import user5_inputs as U  # noqa: E402


def user5(level: float, seed: int):
    triad = U.Triad()
    rows, _ = U.tumble(triad, seed=seed, rw_g=level)
    with tempfile.TemporaryDirectory() as d:
        poses, _ = read_poses(U.write_tumble(Path(d) / "t.csv", rows))
    cal = calibrate(poses)
    m = cal.model
    return np.r_[(m.sensitivity() - np.asarray(triad.k)) / m.sensitivity_u(),
                 m.beta / m.u_per_axis("beta")], cal


def synth(level: float, seed: int, cls: str = "clean", up=None):
    tr = replace(E.triad_of(cls), bias_walk_g=(level,) * 3)
    d = tumble(TumbleSpec(triad=tr, seed=seed, up=up))
    cal = calibrate(E.poses_of(d), np.sign(tr.k))
    m = cal.model
    truth = E.truth_at(tr, m.t_ref)
    return np.r_[(m.sensitivity() - truth[:3]) / m.sensitivity_u(),
                 (m.beta - truth[3:6]) / m.u_per_axis("beta")], cal


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    n = ap.parse_args().seeds
    p28 = tuple(map(tuple, plan(28).up))
    rows = [("user5 walk 1e-7 g/sample", lambda s: user5(1e-7, s), None),
            ("user5 walk 3e-7 g/sample", lambda s: user5(3e-7, s), None),
            ("user5 walk 1e-6 g/sample", lambda s: user5(1e-6, s), None),
            ("user5 clean", lambda s: user5(0.0, s), None),
            ("synth walk 1e-6 g/rt(s)", lambda s: synth(1e-6, s), None),
            ("synth walk 3e-6 g/rt(s)", lambda s: synth(3e-6, s), None),
            ("synth walk 1e-5 g/rt(s)", lambda s: synth(1e-5, s), None),
            ("synth clean", lambda s: synth(0.0, s), None),
            ("synth clean, plan 28", lambda s: synth(0.0, s, up=p28), None),
            ("scale drift 100 ppm, plan 28", lambda s: synth(0.0, s, "scale_drift", p28),
             "scale_drift"),
            ("scale drift 100 ppm", lambda s: synth(0.0, s, "scale_drift"), "scale_drift")]
    print("| class | RMS / max of |err|/u (k, beta) | effects |")
    print("| --- | --- | --- |")
    for name, run, effect in rows:
        z, found, any_effect = [], 0, 0
        for s in range(200, 200 + n):
            zs, cal = run(s)
            z.append(zs)
            names = [e.name for e in cal.loop.effects]
            found += bool(effect) and effect in names
            any_effect += bool(names)
        z = np.array(z)
        what = f"found {found / n:.0%}" if effect else f"any {any_effect / n:.0%}"
        print(f"| {name} | {np.sqrt(np.mean(z ** 2)):.2f} / {np.abs(z).max():.2f} | {what} |",
              flush=True)


if __name__ == "__main__":
    benchpage.run(main, "Calibration: a bias that random-walks")
