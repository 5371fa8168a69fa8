"""Two real triads on one board (OpenAXES imu9: ADXL355 + BMI160) put in one frame.

Run:  python3 benchmarks/real_relative.py   (needs ../shared/data/real/openaxes-imu9)

Calibrates each triad by the ellipsoid over the same static placements, finds the rotation
between their frames (Wahba / scipy align_vectors) with its uncertainty, and prints the
disagreement between the two triads' gravity directions before (frames taken as one — all
the seed paper can do) and after, against the pose means' noise.
"""

from __future__ import annotations

from pathlib import Path

import benchpage
import numpy as np

from align.calibration import StaticSettings, calibrate
from align.calibration import formats as F
from align.relative import calibrated_directions, relative_orientation, shared_poses

PATH = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "openaxes-imu9"
        / "log_imu9_2022-06-22_22-13-55.csv")


def main() -> None:
    if not PATH.is_file():
        print(f"{PATH} is absent: nothing to do")
        return
    t, ua = F.openaxes(PATH, "ADXL355")
    _, ub = F.openaxes(PATH, "BMI160")
    pa, pb = shared_poses(t, ua, ub, StaticSettings(window_s=0.5, threshold=4.0,
                                                    min_duration_s=1.0, margin_s=0.3))
    out = []
    for name, p in (("ADXL355", pa), ("BMI160", pb)):
        cal = calibrate(p)
        lp = cal.loop
        print(f"{name}: {len(p.u)} placements, effects "
              f"{[e.name for e in lp.effects] or 'none'}, chi2/dof "
              f"{lp.before.chi2 / lp.before.dof:.1f} -> {lp.after.chi2 / lp.after.dof:.1f}"
              + (", unexplained structure" if lp.unexplained_structure else ""))
        out.append(calibrated_directions(cal.model, p))
    (a, sa), (b, sb) = out
    r = relative_orientation(a, b, np.sqrt(sa**2 + sb**2))
    rv, u = np.rad2deg(r.rotvec), np.rad2deg(r.u_rad)
    print("rotation BMI160 -> ADXL355 frame (rotation vector) [deg]: "
          + ", ".join(f"{v:+.4f} ± {e:.4f}" for v, e in zip(rv, u, strict=True))
          + f"; angle {np.rad2deg(r.angle_rad):.4f}°")
    rb, ra = (np.sqrt(np.mean(x**2)) * 1e3 for x in (r.residual_before, r.residual_after))
    noise = float(np.median(np.sqrt(sa**2 + sb**2))) * 1e3
    print(f"direction disagreement RMS: frames taken as one {rb:.2f} mrad -> one frame "
          f"{ra:.3f} mrad (x{rb / ra:.0f} smaller); pose-mean noise {noise:.3f} mrad")
    where = "well above" if r.p_value < 1e-3 else "at"
    print(f"chi2/dof {r.chi2_dof:.1f} (p {r.p_value:.2g}): the residual is {where} the noise; "
          f"uncertainty inflated x{r.inflation:.1f}")
    worst = np.argsort(r.residual_after)[-3:][::-1]
    print("largest residuals: " + ", ".join(f"{pa.labels[k]} {r.residual_after[k] * 1e3:.2f} mrad"
                                              for k in worst))


if __name__ == "__main__":
    benchpage.run(main, "Two real triads on one board")
