"""Drop-outs without times: how far each moves the angles' |error|/u from its twin's.

The 12 logs of the independent user's test (``tests/align/user6_inputs.py``: 100
revolutions, 0.5-2 rev/s, 1 % ripple, no ``t`` column, ``--latitude``), one drop-out of 3-20
rows each, run through the CLI with their drop-out-free twins. Prints per log the rows lost,
the drop-out's line when named, the type A method, u [″] and z - z_twin per angle; then
the largest |z - z_twin| (the docs' bound, docs/goniometer-dropouts.md).

Run: ``python3 benchmarks/gonio_dropouts_twins.py``
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import benchpage
import numpy as np

from tests.align import user6_inputs as U

FACES = ("--faces", "ref,y,x,z", "--latitude", "50.45")


def _run(path: Path) -> dict:
    p = subprocess.run([sys.executable, "-m", "align", "gonio", str(path), *FACES, "--json",
                        "-", "-q"], cwd=benchpage.ROOT, capture_output=True, text=True)
    return json.loads(p.stdout)


def main() -> None:
    worst = 0.0
    print("| seed | rows lost | named at | method | u [″] | z - z_twin |")
    print("| --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for seed in range(12):  # (the test's own draws, in its order)
            rng = np.random.default_rng(1000 + seed)
            g = U.Gonio(seed=seed, rev_per_s=float(rng.uniform(0.5, 2.0)))
            rows = list(g.rows())
            n = int(rng.integers(3, 21))
            at = int(rng.integers(0, len(rows) - n))
            js = _run(U.write_gonio(tmp / f"g{seed}.csv", rows[:at] + rows[at + n:], False))
            tw = _run(U.write_gonio(tmp / f"t{seed}.csv", rows, False))
            z = [(np.asarray(j["angles_deg"]) - g.truth_deg()) * 3600.0
                 / np.asarray(j["angles_u_arcsec"]) for j in (js, tw)]
            moved = z[0] - z[1]
            worst = max(worst, float(np.abs(moved).max()))
            named = [v["lines"] for k, v in js["exclusions"].items() if "drop-out" in k]
            print(f"| {seed} | {n} | {named or '-'} | {js['type_a_method']} | "
                  f"{np.round(js['angles_u_arcsec'], 3).tolist()} | "
                  f"{np.round(moved, 2).tolist()} |")
    print(f"largest |z - z_twin|: {worst:.2f}")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: drop-outs without times against their twins")
