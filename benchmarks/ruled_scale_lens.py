"""A dense ruled scale through a lens with its exact model, as user 15 photographed it (the
figures of docs/changelog.md, 2026-11-27, user 15).

Run:  PYTHONPATH=. python3 benchmarks/ruled_scale_lens.py [--seeds N]

Renders (tests/imaging/user15_inputs.py) 20 lines at a 22 px pitch, 140/196 px long, 640 x
480, through k1 -0.15 (k2 0.02, p 5e-4, principal point (12, -8) px) and lens-free, with and
without numerals and dust; runs `align marks IMAGE --camera MODEL --max-marks 30 --json -`
as the user does, and prints per seed the lines found, the family's chi2/dof and angle z,
the largest member u and the members ok beyond 3 u; then a summary per case.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import runpy
import sys
import tempfile

import numpy as np

from tests.imaging import user15_inputs as gen

LENS = dict(k1h=-0.15, k2h=0.02, p1h=5e-4, p2h=-5e-4, pp=(12.0, -8.0), aspect=0.003)
SIZE = (640, 480)
COV = np.diag([0.1, 0.1, 0.1, 0.1, 3e-4, 1e-3, 2e-5, 2e-5, 1e-6]) ** 2


def _marks(*args):
    out, old = io.StringIO(), sys.argv
    sys.argv = ["align", "marks", *args, "--json", "-"]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            runpy.run_module("align", run_name="__main__", alter_sys=False)
    except SystemExit:
        pass
    finally:
        sys.argv = old
    return json.loads(out.getvalue())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=8)
    seeds = ap.parse_args().seeds
    tmp = tempfile.mkdtemp()
    for lens in (LENS, {}):
        for clean in (False, True):
            K, d = gen.lens_cv(SIZE, **lens)
            cam = gen.camera_json_from_cv(K, d, SIZE, os.path.join(tmp, "cam.json"), cov=COV)
            rows = []
            for seed in range(seeds):
                img, truth = gen.render_scale(SIZE, K, d, n_lines=20, pitch_px=22,
                                              angle_deg=3.0, length_px=140, seed=seed,
                                              **(dict(dust=0, numerals=False) if clean else {}))
                f = gen.write_png(os.path.join(tmp, "scale.png"), img)
                doc = _marks(f, "--camera", cam, "--max-marks", "30")
                found = [m for m in doc["marks"] if m.get("found")]
                fam = next((m["family"] for m in found if m.get("family")), None)
                z = (gen.angle_diff_arcsec(fam["angle_deg"], truth) / fam["angle_u_arcsec"]
                     if fam else float("nan"))
                u = [m["angle_u_deg"] * 3600 for m in found]
                wrong = sum(not m.get("lens_limited") and abs(gen.angle_diff_arcsec(
                    m["angle_deg"], truth)) > 3 * m["angle_u_deg"] * 3600 for m in found)
                chi = fam["chi2_dof"] if fam else float("nan")
                rows.append((len(found), chi, z, wrong))
                print(f"lens {bool(lens)} clean {clean} seed {seed}: {len(found)} of 20, "
                      f"chi2/dof {chi:.2f}, family z {z:+.2f}, largest member u "
                      f"{max(u, default=0):.0f}″, ok beyond 3 u {wrong}")
            n = np.array([r[0] for r in rows])
            print(f"== lens {bool(lens)} clean {clean}: all 20 in {int(np.sum(n == 20))} of "
                  f"{len(n)}, chi2/dof {min(r[1] for r in rows):.2f}-"
                  f"{max(r[1] for r in rows):.2f}, |family z| max "
                  f"{max(abs(r[2]) for r in rows):.2f}, ok beyond 3 u {sum(r[3] for r in rows)}")


if __name__ == "__main__":
    main()
