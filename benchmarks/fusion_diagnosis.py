"""The fusion's diagnosis on synthetic sessions with an undeclared disagreement.

``level``: the platform ~30″ out of level in a random direction (cameras and goniometer see
the true E) — is the `platform_level` effect found, and E within its u?
``creep``: the triad turned ±30″ about Y between the camera images and the static readings —
are the camera images and the static poses named, in E_xZ and E_zX?

Run: ``python3 benchmarks/fusion_diagnosis.py level 8`` (~15 s a session), ``… creep 8``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import benchpage
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from align.fusion import E_INDEX  # noqa: E402
from align.session import load_session, run_session  # noqa: E402
from synth.session import SessionSpec, write_session  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("kind", choices=("level", "creep"))
    ap.add_argument("sessions", type=int, nargs="?", default=8)
    ap.add_argument("--seed0", type=int, default=700)
    a = ap.parse_args()
    zs, found = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.sessions):
            seed = a.seed0 + k
            rng = np.random.default_rng(seed)
            if a.kind == "level":
                ang = rng.uniform(0, 2 * np.pi)
                eff = {"platform_level_x": 30 * np.cos(ang), "platform_level_y": 30 * np.sin(ang)}
            else:
                eff = {"creep_y": 30.0 * rng.choice([-1, 1])}
            d = Path(tmp) / f"s{seed}"
            truth = write_session(d, SessionSpec(seed=seed, effects=eff,
                                                 undeclared=frozenset(eff)))
            f = run_session(load_session(d)).fusion
            E = np.array(truth["misalignment_rad"])
            z = np.array([(f.E[i, j] - E[i, j]) / f.E_u[i, j] for i, j in E_INDEX])
            zs.append(z)
            dis = f.disagreement
            if a.kind == "level":
                ok = [e.name for e in f.loop.effects] == ["platform_level"]
            else:
                ok = (dis is not None and {dis.source, *dis.also} == {"camera", "platform static"}
                      and {n for n, _, _ in dis.angles} == {"E_xZ", "E_zX"})
            found += ok
            print(seed, {k: round(float(v), 1) for k, v in eff.items()}, "found" if ok else
                  "NOT found", "effects", [e.name for e in f.loop.effects], "named",
                  None if dis is None else (dis.source, *dis.also), flush=True)
    zs = np.array(zs)
    print(f"{a.kind}: found {found}/{a.sessions}; E |error|/u RMS "
          f"{np.sqrt(np.mean(zs**2)):.2f}, max {np.abs(zs).max():.2f}")


if __name__ == "__main__":
    benchpage.run(main, "Fusion: diagnosis of an undeclared disagreement")
