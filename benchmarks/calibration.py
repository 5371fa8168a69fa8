"""Triad calibration: the seed paper reproduced, ML vs algebraic vs the CRLB, and peers.

Run:  python3 benchmarks/calibration.py [--datasets 200] [--only paper|detection|known|runaway]

1. The paper's setting (Table 1, 14 cube poses, per-pose noise ~1e-6 g): parameters against
   their stated uncertainties, check-pose Δg.
2. Over N seeded datasets: RMS error of each parameter for the algebraic (Li–Griffiths) fit and
   the ML refinement, their ratio, the ratio to the Cramér–Rao bound, bias/sigma.
3. Peers on the same data: an imu_tk-style norm-residual Gauss–Newton fit (upper-triangular
   matrix + bias from a nominal start), and imucal's Ferraris six-position method (needs
   exactly known orientations; optional dependency: `pip install imucal`) under fixture
   placement errors of 0-500 µrad, Δg on random check poses.
4. Static detection: synthetic hand-held recordings (10-1000 Hz, 1-3 s poses, 10 µg-10 mg)
   and the real recordings, poses found by the default detector against the previous one
   (fixed 1 s window, 10th-percentile floor, 2 s minimum, 0.5 s margins), with timings.
5. Six-position: the known-pose fit against imucal's FerrarisCalibration, synthetic (Δg on
   check poses under fixture error) and on imucal's own session (matrix K R, offsets).
6. The run-away loop: six faces + chunks of turns as poses, 20 seeds, guard off and on.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import benchpage
import numpy as np

from align.calibration import (
    CalibrationStage,
    Poses,
    algebraic,
    calibrate,
    delta_g,
    poses_from_samples,
)
from synth.tumble import Triad, TumbleSpec, fisher_crlb, tumble

NOISE_V = 4.8e-5  # per sample (2e-5 g); 200 samples per pose
NAMES = [f"{p}_{a}" for p in ("k", "beta", "bias") for a in "xyz"]


def poses_of(d, check=False) -> Poses:
    """Calibration (or check) poses of a synthetic tumble as per-pose means."""
    sel = (d.pose >= d.n_cal) if check else (d.pose < d.n_cal)
    return poses_from_samples(d.pose[sel], d.u[sel], d.t[sel])


def imu_tk_style(p: Poses, k_nominal: np.ndarray) -> tuple[np.ndarray, float]:
    """Norm-residual Gauss–Newton on a = T (u - o), T upper triangular, from a nominal start.

    Returns the calibrated |a| residual function's parameters and the time taken.
    """
    t0 = time.perf_counter()
    theta = np.concatenate([1 / k_nominal, np.zeros(3), np.zeros(3)])  # diag, off-diag, offset

    def parts(th):
        T = np.diag(th[:3])
        T[0, 1], T[0, 2], T[1, 2] = th[3:6]
        return T, th[6:9]

    for _ in range(30):
        T, o = parts(theta)
        a = (p.u - o) @ T.T
        n = np.linalg.norm(a, axis=1)
        r = n - 1
        J = np.empty((len(r), 9))
        h = 1e-9
        for j in range(9):
            tp = theta.copy()
            tp[j] += h * max(1.0, abs(theta[j]))
            Tp, op = parts(tp)
            J[:, j] = (np.linalg.norm((p.u - op) @ Tp.T, axis=1) - n) / (tp[j] - theta[j])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        theta = theta + step
        if np.max(np.abs(step) / np.maximum(np.abs(theta), 1e-12)) < 1e-13:
            break
    return theta, time.perf_counter() - t0


def imu_tk_dg(theta: np.ndarray, p: Poses) -> np.ndarray:
    T = np.diag(theta[:3])
    T[0, 1], T[0, 2], T[1, 2] = theta[3:6]
    return np.linalg.norm((p.u - theta[6:9]) @ T.T, axis=1) - 1


def imucal_dg(d, check: Poses) -> np.ndarray | None:
    """imucal's Ferraris accelerometer calibration from the six face poses (faces 0-5 are
    +x, +y, +z, -x, -y, -z up); gyro inputs are placeholders (not evaluated)."""
    try:
        from imucal import FerrarisCalibration, FerrarisSignalRegions
    except ImportError:
        return None
    acc = {i: d.u[d.pose == i] for i in range(6)}
    z = np.zeros((len(acc[0]), 3))
    rot = np.zeros((10, 3))
    regions = FerrarisSignalRegions(
        acc_x_p=acc[0], acc_x_a=acc[3], acc_y_p=acc[1], acc_y_a=acc[4], acc_z_p=acc[2],
        acc_z_a=acc[5], gyr_x_p=z, gyr_x_a=z, gyr_y_p=z, gyr_y_a=z, gyr_z_p=z, gyr_z_a=z,
        acc_x_rot=rot, acc_y_rot=rot, acc_z_rot=rot, gyr_x_rot=rot + [1, 0, 0],
        gyr_y_rot=rot + [0, 1, 0], gyr_z_rot=rot + [0, 0, 1])
    cal = FerrarisCalibration(grav=1.0).compute(regions, 20.0, "V", "V")
    a = (np.linalg.inv(cal.R_a) @ np.linalg.inv(cal.K_a) @ (check.u - cal.b_a).T).T
    return np.linalg.norm(a, axis=1) - 1


def old_find_static(t: np.ndarray, u: np.ndarray) -> list[tuple[float, float]]:
    """The previous detector at its defaults (the alternative section 4 compares with)."""
    from scipy.ndimage import uniform_filter1d

    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(1.0 / dt)))
    m = uniform_filter1d(u, w, axis=0, mode="nearest")
    m2 = uniform_filter1d(u * u, w, axis=0, mode="nearest")
    sd = np.sqrt(np.maximum(m2 - m * m, 0)).max(axis=1)
    quiet = sd <= 3.0 * max(float(np.percentile(sd, 10)), 1e-12)
    edges = np.diff(np.concatenate([[0], quiet.astype(int), [0]]))
    out = []
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True):
        ta, tb = t[a] + 0.5 + dt * w / 2, t[b] - 0.5 - dt * w / 2
        if tb - ta >= 2.0:
            out.append((float(ta), float(tb)))
    return out


def _found(rec, intervals) -> tuple[int, int]:
    """(poses found, intervals spanning two poses) of a hand-held recording."""
    dt = 1 / rec.spec.rate_hz
    hit, span = set(), 0
    for a, b in intervals:
        inside = [min(b, pb) - max(a, pa) + dt for pa, pb in rec.poses]
        over = [i for i, x in enumerate(inside) if x > dt / 2]
        if len(over) > 1:
            span += 1
        elif over and inside[over[0]] >= 0.5 * (b - a + dt):
            hit.add(over[0])
    return len(hit), span


def detection() -> None:
    from align.calibration import detect_static, find_static
    from align.calibration import formats as F
    from synth.handheld import HandheldSpec, handheld

    print("== 4. static detection: poses found / true (intervals spanning two poses) ==")
    print("  synthetic hand-held, 30 poses x 3 seeds each, slow min-jerk handling between")
    print(f"  {'rate':>6s} {'noise':>7s} {'default (this)':>16s} {'previous':>12s} "
          f"{'t this':>8s} {'t prev':>8s}")
    for rate in (10.0, 50.0, 200.0, 1000.0):
        for noise in (1e-5, 1e-4, 1e-3, 1e-2):
            f_new = f_old = s_new = s_old = n = 0
            tn, to = [], []
            for seed in range(3):
                rec = handheld(HandheldSpec(rate_hz=rate, noise_g=noise, seed=seed))
                t0 = time.perf_counter()
                det = detect_static(rec.t, rec.u)
                tn.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                old = old_find_static(rec.t, rec.u)
                to.append(time.perf_counter() - t0)
                a, b = _found(rec, [(x.start_s, x.end_s) for x in det.intervals])
                c, d = _found(rec, old)
                f_new, s_new, f_old, s_old = f_new + a, s_new + b, f_old + c, s_old + d
                n += len(rec.poses)
            print(f"  {rate:6.0f} {noise:7.0e} {f'{f_new}/{n} ({s_new})':>16s} "
                  f"{f'{f_old}/{n} ({s_old})':>12s} {1e3 * np.median(tn):6.1f}ms "
                  f"{1e3 * np.median(to):6.1f}ms")
    import json
    from pathlib import Path

    real = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
    if not real.is_dir():
        print("  (real recordings absent)")
        return
    print("  real recordings (true counts from each folder's README)")
    fer = np.genfromtxt(real / "imucal-ferraris" / "example_ferraris_session.csv",
                        delimiter=",", names=True)
    sec = json.loads((real / "imucal-ferraris" / "example_ferraris_session_list.json")
                     .read_text())
    rows = [
        ("imu_tk-xsens", *F.xsens_text(real / "imu_tk-xsens" / "xsens_acc.mat"),
         "1 + 37 poses"),
        ("openaxes ADXL355", *F.openaxes(real / "openaxes-imu9"
                                         / "log_imu9_2022-06-22_22-13-55.csv", "ADXL355"),
         "1 + ~38 placements"),
        ("openaxes BMI160", *F.openaxes(real / "openaxes-imu9"
                                        / "log_imu9_2022-06-22_22-13-55.csv", "BMI160"),
         "1 + ~38 placements"),
        ("mpu6050", *F.mpu6050(real / "mpu6050-tomisuarez" / "example_data_calibration.csv"),
         "1 + ~10 poses"),
        ("imucal-ferraris", np.arange(len(fer)) / 102.4,
         np.column_stack([fer["acc_x"], fer["acc_y"], fer["acc_z"]]),
         "6 faces + 7 rests between turns"),
    ]
    for name, t, u, truth in rows:
        new = find_static(t, u)
        old = old_find_static(t, u)
        extra = ""
        if name == "imucal-ferraris":
            faces = 0
            for k in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"):
                a, b = sec[k]["start"] / 102.4, sec[k]["end"] / 102.4
                faces += any(min(x.end_s, b) - max(x.start_s, a) > 0.7 * (b - a) for x in new)
            turns = sum(any(x.start_s < sec[k]["end"] / 102.4 and x.end_s > sec[k]["start"]
                            / 102.4 for x in new) for k in ("x_rot", "y_rot", "z_rot"))
            extra = f"; annotated faces covered {faces}/6, intervals inside a turn {turns}"
        print(f"  {name:17s} this {len(new):3d}, previous {len(old):3d}  (README: {truth})"
              f"{extra}")


def known_pose() -> None:
    from align.calibration.known import fit_known

    tr = Triad(noise_v=NOISE_V)
    print("== 5a. six faces: known-pose fit vs imucal Ferraris (Δg RMS, 5 check poses, µg; "
          "50 seeds) ==")
    for err in (0.0, 50e-6, 200e-6, 500e-6):
        ours, theirs = [], []
        for s in range(50):
            d = tumble(TumbleSpec(triad=tr, poses="six", seed=3000 + s, fixture_error_rad=err))
            sel = d.pose < 6
            p = poses_from_samples(d.pose[sel], d.u[sel], d.t[sel],
                                   ("+x", "+y", "+z", "-x", "-y", "-z"))
            c = poses_of(d, True)
            kf = fit_known(p, p.labels, np.sign(tr.k), err / np.sqrt(2))
            ours.append(delta_g(kf.model, c))
            dgi = imucal_dg(d, c)
            if dgi is not None:
                theirs.append(dgi)
        r = [f"{np.sqrt(np.mean(np.square(x))) * 1e6:.2f}" if x else "not installed"
             for x in (ours, theirs)]
        print(f"  fixture {err * 1e6:5.0f} µrad: this tool {r[0]:>8s}   imucal {r[1]:>8s}")
    from pathlib import Path

    from align.calibration.formats import ferraris_session, imucal_ferraris

    folder = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "imucal-ferraris"
    try:
        import imucal  # noqa: F401
        import pandas  # noqa: F401
    except ImportError:
        print("  imucal not installed: pip install '.[bench]'")
        return
    if not folder.is_dir():
        return
    p, d, sec = ferraris_session(folder)
    t0 = time.perf_counter()
    cal = calibrate(p)
    t_ours = time.perf_counter() - t0
    t0 = time.perf_counter()
    info, grav = imucal_ferraris(d, sec)
    t_im = time.perf_counter() - t0
    ours = cal.known.M / grav
    um = np.sqrt(np.diag(cal.known.cov_mo))[:9].reshape(3, 3) / grav
    theirs = info.K_a @ info.R_a
    uo = np.sqrt(np.diag(cal.known.cov_mo))[9:]
    print("== 5b. imucal's own Ferraris session (accelerometer; the turns are not used) ==")
    print(f"  K R: max |this - imucal| {np.abs(ours - theirs).max():.2e} (max "
          f"{np.max(np.abs(ours - theirs) / um):.2f} of our u); row norms this "
          f"{np.round(np.linalg.norm(ours, axis=1), 5)} imucal {np.round(np.diag(info.K_a), 5)}")
    print(f"  offsets [m/s²] this {np.round(cal.known.offset, 5)} ± {np.round(uo, 5)}, "
          f"imucal {np.round(info.b_a, 5)}")
    print(f"  k [(m/s²)/g] this {np.round(cal.model.k, 4)} ± "
          f"{np.round([cal.model.u_of(f'k_{a}') for a in 'xyz'], 4)}; chi2 "
          f"{cal.known.chi2:.2f} on {cal.known.dof} dof; time this {1e3 * t_ours:.1f} ms, "
          f"imucal (acc + gyro) {1e3 * t_im:.1f} ms")


def runaway() -> None:
    from align.calibration import CANDIDATES, NONLIN
    from align.loop import run_loop
    from tests.align.test_calibration_guard import faces_and_turn_chunks

    print("== 6. six faces + 1 s chunks of three turns as poses (20 seeds) ==")
    wild, refused, kept = [], 0, 0
    for s in range(20):
        _, p = faces_and_turn_chunks(s)
        rep = run_loop(CalibrationStage(p, (1, 1, 1)), CANDIDATES)
        if NONLIN in [e.name for e in rep.effects]:
            wild.append(np.max(rep.after.payload.k / rep.before.payload.k))
        cal = calibrate(p)
        refused += NONLIN in [r.name for r in cal.loop.refused]
        kept += NONLIN in [e.name for e in cal.loop.effects]
    print(f"  guard off: K2 accepted in {len(wild)}/20, k moved by up to x{max(wild):.0f}")
    print(f"  guard on : K2 refused in {refused}/20, accepted in {kept}/20")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--datasets", type=int, default=200)
    ap.add_argument("--only", choices=["paper", "detection", "known", "runaway"])
    args = ap.parse_args()
    if args.only == "detection":
        return detection()
    if args.only == "known":
        return known_pose()
    if args.only == "runaway":
        return runaway()
    tr = Triad(noise_v=NOISE_V)
    truth = np.concatenate([tr.k, tr.beta, tr.bias])

    print("== 1. the seed paper's setting: Table 1, 14 cube poses, 200 samples/pose ==")
    d = tumble(TumbleSpec(triad=tr, seed=2024))
    cal = calibrate(poses_of(d), np.sign(tr.k))
    est = np.concatenate([cal.model.k, cal.model.beta, cal.model.bias])
    u = np.sqrt(np.diag(cal.model.cov))[:9]
    scale = np.array([1] * 3 + [1e6] * 6)
    unit = ["V/g"] * 3 + ["µrad"] * 3 + ["µg"] * 3
    for i, n in enumerate(NAMES):
        print(f"  {n:7s} truth {truth[i] * scale[i]:+14.6f} fit {est[i] * scale[i]:+14.6f} "
              f"± {u[i] * scale[i]:.2g} {unit[i]}  (error/u {(est[i] - truth[i]) / u[i]:+.2f})")
    dg = delta_g(cal.model, poses_of(d, True))
    print("  check poses Δg [1e-5 g]: " + " ".join(f"{v * 1e5:+.3f}" for v in dg)
          + "  (the paper: -1.218 1.685 -2.989 0.929 -2.070)")

    for label, noise in (("paper's noise", NOISE_V), ("30x the noise", 30 * NOISE_V)):
        trn = replace(tr, noise_v=noise)
        print(f"\n== 2. {args.datasets} seeded datasets, {label}: algebraic vs ML vs CRLB ==")
        err_alg, err_ml, t_alg, t_ml, false = [], [], [], [], 0
        for s in range(args.datasets):
            d = tumble(TumbleSpec(triad=trn, seed=s))
            p = poses_of(d)
            t0 = time.perf_counter()
            a = algebraic(p, np.sign(tr.k))
            t_alg.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            m = CalibrationStage(p, np.sign(tr.k)).refine([])[0]
            t_ml.append(time.perf_counter() - t0)
            if noise == NOISE_V:
                false += bool(calibrate(p, np.sign(tr.k)).loop.effects)
            err_alg.append(np.concatenate([a.k, a.beta, a.bias]) - truth)
            err_ml.append(np.concatenate([m.k, m.beta, m.bias]) - truth)
        ea, em = np.array(err_alg), np.array(err_ml)
        crlb = np.sqrt(np.diag(fisher_crlb(trn, d.up[:d.n_cal], noise / np.sqrt(200))))
        print(f"  {'param':7s} {'RMS alg':>10s} {'RMS ML':>10s} {'alg/ML':>7s} "
              f"{'ML/CRLB':>8s} {'bias/σ':>7s}  ({unit[0]}, µrad, µg)")
        for i, n in enumerate(NAMES):
            ra, rm = np.sqrt(np.mean(ea[:, i] ** 2)), np.sqrt(np.mean(em[:, i] ** 2))
            print(f"  {n:7s} {ra * scale[i]:10.4g} {rm * scale[i]:10.4g} {ra / rm:7.2f} "
                  f"{rm / crlb[i]:8.3f} {em[:, i].mean() / em[:, i].std(ddof=1):+7.3f}")
        print(f"  time per dataset: algebraic {1e3 * np.median(t_alg):.2f} ms, ML refinement "
              f"{1e3 * np.median(t_ml):.1f} ms (sampling spread of ML/CRLB "
              f"±{1 / np.sqrt(2 * args.datasets):.2f})")
        if noise == NOISE_V:
            print(f"  residual loop on these clean datasets added an effect in {false} of "
                  f"{args.datasets}")

    print("\n== 3. peers under fixture placement error (Δg RMS on 5 random check poses, µg) ==")
    print(f"  {'fixture':>9s} {'this tool (14)':>15s} {'imu_tk-style (14)':>18s} "
          f"{'imucal Ferraris (6 faces)':>26s}")
    for err in (0.0, 50e-6, 200e-6, 500e-6):
        rows = {"ours": [], "tk": [], "imucal": []}
        for s in range(50):
            d = tumble(TumbleSpec(triad=tr, seed=1000 + s, fixture_error_rad=err))
            p, c = poses_of(d), poses_of(d, True)
            rows["ours"].append(delta_g(calibrate(p, np.sign(tr.k)).model, c))
            th, _ = imu_tk_style(p, np.array(tr.k))
            rows["tk"].append(imu_tk_dg(th, c))
            dgi = imucal_dg(d, c)
            if dgi is not None:
                rows["imucal"].append(dgi)

        def rms(x):
            return f"{np.sqrt(np.mean(np.square(x))) * 1e6:.2f}" if x else "not installed"

        print(f"  {err * 1e6:6.0f} µrad {rms(rows['ours']):>15s} {rms(rows['tk']):>18s} "
              f"{rms(rows['imucal']):>26s}")
    print("  (this tool and the imu_tk-style fit use only |a| = 1: placement does not matter;"
          " the six-position method takes the fixture's orientation as truth)")
    if args.only is None:
        detection()
        known_pose()
        runaway()


if __name__ == "__main__":
    benchpage.run(main, "Triad calibration: the seed paper, ML vs algebraic vs the CRLB, peers")
