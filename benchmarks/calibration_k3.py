"""Undeclared cubic non-linearity K3 (issue 19): coverage of k and the cost on clean tumbles.

Run:  python3 benchmarks/calibration_k3.py [--seeds 12] [--control 100]
      (before: ``PYTHONPATH=<main checkout> python3 benchmarks/calibration_k3.py …``)

User 8's triad (``tests/align/user8_inputs.py``: 200 samples a pose at 100 Hz, 0.3 mg a
sample) through ``align calibrate``'s file route, nothing declared. Per design (26 cube
poses; the paper's 14: 6 faces + 8 corners; the 6 labelled faces) and K3 = ±30, ±100,
±300 µg/g³ (sign patterns (+,-,+) and (-,+,-), seeds 0..N-1 each): |err|/u of the scale
factors against the linear coefficient (RMS, max), how often the loop added K3, how often
``k3_not_excluded`` carried it, how often the result was flagged (a warning or not ok) and
how many runs left a k beyond 3 u unflagged; the last column: max |err|/u against the 1 g
chord k (1 + K3) instead (what k is where the poses cannot separate K3). Clean (seeds
1000..): the same, flagged being a false warning, and the cost of the K3 term: u of k over
u without that term (median, max).
Then the real recordings (``../shared/data/real``, skipped when absent): u of k and the
biases over u without the term, the effects, the nonlinearity statement.
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

from align.calibration import StaticSettings, calibrate  # noqa: E402
from align.calibration import formats as F  # noqa: E402
from align.calibration.files import calibrate_files  # noqa: E402
from align.calibration.stability import chosen_ppm  # noqa: E402
from tests.align import user8_inputs as ui  # noqa: E402
from tests.align.test_real_calibration import _poses  # noqa: E402

TERM = "k3_not_excluded"
C26 = ui.cube26()
DESIGNS = {"26 cube poses": (C26, None),
           "paper's 14": (C26[np.count_nonzero(C26, axis=1) != 2], None),
           "6 faces": (C26[np.count_nonzero(C26, axis=1) == 1],
                       [("+" if f.sum() > 0 else "-") + "xyz"[int(np.argmax(np.abs(f)))]
                        for f in C26[np.count_nonzero(C26, axis=1) == 1]])}


def cost(cal, names: list[str]) -> np.ndarray:
    """u over u without the K3 term, per parameter name of ``u_widening`` (1: no term)."""
    w = None if cal.widening is None else cal.widening.to_dict()["parameters"]
    out = []
    for n in names:
        p = (w or {}).get(n, {})
        u, t = p.get("u"), p.get(TERM) or 0.0
        out.append(1.0 if not u else u / np.sqrt(max(u * u - t * t, 1e-300)))
    return np.array(out)


def one(tr: ui.Triad, seed: int, ups, labels, folder: Path) -> tuple:
    p = ui.write_tumble(ui.tumble_rows(tr, ups, seed, labels=labels), folder / f"t{seed}.csv")
    run = calibrate_files(p, None, "g", None, StaticSettings())
    m = run.cal.model
    z = (m.sensitivity() - np.array(tr.k)) / m.sensitivity_u()
    zc = (m.sensitivity() - np.array(tr.k) * (1 + np.array(tr.k3))) / m.sensitivity_u()
    added = "nonlinearity_k3" in [e.name for e in run.cal.loop.effects]
    terms = [] if run.cal.widening is None else [t for t, _ in run.cal.widening.reasons]
    flagged = (not run.ok) or bool(run.warnings)
    return (z, added, TERM in terms, flagged, cost(run.cal, [f"scale_factor_{a}" for a in "xyz"]),
            zc)


def row(name: str, out: list[tuple]) -> str:
    z = np.array([o[0] for o in out])
    r = np.array([o[4] for o in out])
    bad = sum(1 for o in out if not o[3] and np.abs(o[0]).max() > 3.0)
    return (f"| {name} | {len(out)} | {np.sqrt(np.mean(z**2)):.2f} | {np.abs(z).max():.2f} | "
            f"{np.mean([o[1] for o in out]):.0%} | {np.mean([o[2] for o in out]):.0%} | "
            f"{np.mean([o[3] for o in out]):.0%} | {bad} | {np.median(r):.2f} | {r.max():.2f} | "
            f"{np.abs([o[5] for o in out]).max():.2f} |")


REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _real_cases() -> dict:
    """The recordings' poses as tests/align/test_real_calibration.py reads them."""
    oa = REAL / "openaxes-imu9" / "log_imu9_2022-06-22_22-13-55.csv"
    st = StaticSettings()
    return {
        "MPU-6050": lambda: _poses(*F.mpu6050(REAL / "mpu6050-tomisuarez"
                                              / "example_data_calibration.csv"), st),
        "OpenAXES ADXL355": lambda: _poses(*F.openaxes(oa, "ADXL355"), st),
        "OpenAXES BMI160": lambda: _poses(*F.openaxes(oa, "BMI160"), st),
        "imucal six faces": lambda: F.ferraris_session(REAL / "imucal-ferraris")[0],
        "imu_tk Xsens": lambda: _poses(*F.xsens_text(REAL / "imu_tk-xsens" / "xsens_acc.mat"),
                                       st),
    }


def real() -> None:
    if not REAL.is_dir():
        print(f"real recordings skipped: {REAL} is absent")
        return
    print("\n| recording | poses | method | effects | u(k) / u without the K3 term | "
          "u(bias) / without | ok | nonlinearity statement |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, f in _real_cases().items():
        p = f()
        ppm, default = chosen_ppm(None, p.temp is not None)
        cal = calibrate(p, scale_stability_ppm=ppm, stability_default=default)
        rk = cost(cal, [f"scale_factor_{a}" for a in "xyz"])
        rb = cost(cal, [f"bias_{a}" for a in "xyz"])
        st = (cal.nonlinearity or {}).get("statement", "")
        print(f"| {name} | {len(p.u)} | {cal.method} | "
              f"{', '.join(e.name for e in cal.loop.effects) or '-'} | {rk.max():.2f} | "
              f"{rb.max():.2f} | {cal.ok} | {st[:90]}{'…' if st[90:] else ''} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--control", type=int, default=100)
    a = ap.parse_args()
    print("| design, K3 [µg/g³] | runs | RMS | max | K3 added | carried | flagged | "
          "k > 3 u unflagged | u(k)/u without term: median | max | max vs 1 g chord |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for design, (ups, labels) in DESIGNS.items():
            for k3 in (30e-6, 100e-6, 300e-6):
                out = [one(ui.Triad(k3=(sg * k3, -sg * k3, sg * k3)), s, ups, labels,
                           Path(tmp)) for sg in (1, -1) for s in range(a.seeds)]
                print(row(f"{design}, ±{k3 * 1e6:.0f}", out), flush=True)
            out = [one(ui.Triad(), s, ups, labels, Path(tmp))
                   for s in range(1000, 1000 + a.control)]
            print(row(f"{design}, clean", out), flush=True)
    real()


if __name__ == "__main__":
    benchpage.run(main, "Calibration: undeclared cubic non-linearity K3")
