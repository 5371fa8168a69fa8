"""User 8's static tumbles (issue 19): cubic non-linearity, settling creep, clean control.

Run:  python3 benchmarks/calibration_user8.py [--seeds 12] [--control 100] [--k3-bound 100]
      [--poses 14]
      (before: ``PYTHONPATH=<main checkout> python3 benchmarks/calibration_user8.py``)

User 8's triad (``tests/align/user8_inputs.py``: 26 cube poses of 200 samples at 100 Hz,
0.3 mg a sample) through ``align calibrate``'s file route, per class over seeds: |err|/u RMS
and max of the scale factors and biases (truth: k and the zero-input bias), how often the
class's effect was handled (K3: added, or carried in u by ``plausible_effect``; creep: the
settling found), how often the result was flagged (a warning or not ok) and how many seeds
were beyond 3.5 u without any flag; on the clean control the same counts are false alarms.
``--k3-bound UG``: K3 declared to ±UG µg/g³ (``--nonlinearity-bound ,UG``; found then also
counts K3 carried by the bound); ``--poses 14``: the 6 faces and 8 corners of the cube.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import benchpage
import numpy as np

sys.path.insert(1 + len([e for e in os.environ.get("PYTHONPATH", "").split(os.pathsep) if e]),
                str(Path(__file__).resolve().parents[1]))

from align.calibration import StaticSettings  # noqa: E402
from align.calibration.files import calibrate_files  # noqa: E402
from tests.align import user8_inputs as ui  # noqa: E402

CLASSES = {"k3": ui.Triad(k3=(1e-4, -1e-4, 1e-4)), "creep": ui.Triad(creep=3e-4),
           "clean": ui.Triad()}


def one(tr: ui.Triad, seed: int, name: str, folder: Path, k3_bound: float | None = None,
        ups: np.ndarray | None = None) -> tuple:
    ups = ui.cube26() if ups is None else ups
    p = ui.write_tumble(ui.tumble_rows(tr, ups, seed), folder / f"{name}{seed}.csv")
    bound = None if k3_bound is None else (None, k3_bound * 1e-6)
    run = calibrate_files(p, None, "g", None, StaticSettings(), nonlinearity_bound=bound)
    m = run.cal.model
    z = np.r_[(m.sensitivity() - np.array(tr.k)) / m.sensitivity_u(),
              (m.bias - np.array(tr.o) / np.array(tr.k)) / m.u_per_axis("bias")]
    w = run.cal.widening
    why = dict(w.reasons).get("plausible_effect", "") if w is not None else ""
    carried = "nonlinearity_k3" in (run.cal.nonlinearity or {}).get("carried", [])
    st = getattr(run.poses, "settling", None)
    settled = bool(st is not None and st.found)
    found = {"k3": "nonlinearity_k3" in [e.name for e in run.cal.loop.effects]
             or "nonlinearity_k3" in why or carried, "creep": settled,
             "clean": bool(why) or settled}
    return z, found[name], (not run.ok) or bool(run.warnings)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--control", type=int, default=100)
    ap.add_argument("--k3-bound", type=float, default=None, help="declared K3 bound [µg/g³]")
    ap.add_argument("--poses", type=int, choices=(26, 14), default=26)
    a = ap.parse_args()
    c26 = ui.cube26()
    ups = c26 if a.poses == 26 else c26[np.count_nonzero(c26, axis=1) != 2]
    print(f"{'class':6s} {'n':>4s} {'RMS':>6s} {'max':>6s} {'found':>6s} {'flagged':>8s} "
          "beyond 3.5 u unflagged   (clean: found = plausible_effect or settling, false)")
    with tempfile.TemporaryDirectory() as tmp:
        for name, tr in CLASSES.items():
            seeds = range(1000, 1000 + a.control) if name == "clean" else range(a.seeds)
            out = [one(tr, s, name, Path(tmp), a.k3_bound, ups) for s in seeds]
            z = np.array([o[0] for o in out])
            bad = sum(1 for o in out if not o[2] and np.abs(o[0]).max() > 3.5)
            print(f"{name:6s} {len(out):4d} {np.sqrt(np.mean(z**2)):6.2f} {np.abs(z).max():6.2f} "
                  f"{np.mean([o[1] for o in out]):6.0%} {np.mean([o[2] for o in out]):8.0%} "
                  f"{bad:4d}", flush=True)


if __name__ == "__main__":
    benchpage.run(main, "Calibration: user 8's cubic non-linearity and settling creep")
