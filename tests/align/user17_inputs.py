"""Independent user 17's own generators (written from the docs only, no project code).

Each generator renders an instrument's physics with one effect the tool is not told
about, at a chosen strength, and returns the file it wrote with the truth.

* ``gonio_log``: a ring-laser goniometer counter log (``count,counter,ref,t``, docs/
  commands/gonio.md): a table turning at ``rev_s`` rev/s, a speed ripple locked to the table
  (an eccentric / wobbling table), four faces whose pulses fire at the face angle plus the
  autocollimator's jitter (and an unknown latency), a ring laser whose phase advances
  K/2π per radian turned; each row's count is floor(Φ(t_k)) − floor(Φ(t_k−1)). Effects:
  ``dead_time_s`` (counter 2 starts this late after each switch: counts lost),
  ``double_p`` (probability a row's counter adds a spurious count),
  ``scale_drift_ppm`` (the ring laser's scale drifts linearly by this over the log:
  temperature), ``latency_s`` with ``ripple`` (autocollimator latency on a table whose speed
  ripples once a revolution), ``glint_counts``/``glint_p`` (the reference face seen twice).
* ``tumble``: a static tumble test ``pose,ux,uy,uz,t`` of an orthogonal triad
  (u_i = k_i (g_i + b_i) + noise, 14 poses: six faces and eight corners, each slightly
  mis-levelled at random). Effects: ``bias_step_g`` (the x bias jumps by this half-way
  through the run), ``saturate_g`` (every axis clips at this many g), ``pickup_g``
  (50 Hz mains pickup sampled at 20 Hz: aliases to 10 Hz, a few cycles in each pose),
  ``scale_temp_ppm`` (the scale factors follow a warm-up of this size, no temp column).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

ARCSEC = np.pi / (180 * 3600)


def _theta(t, w, ripple, psi):
    """Table angle (rad) at time t: steady rate w (rad/s) with a once-a-revolution ripple."""
    return w * t + ripple * np.sin(w * t + psi) - ripple * np.sin(psi)


def _invert(target, w, ripple, psi):
    """Times at which the table angle reaches ``target`` (Newton; ripple << 1)."""
    t = target / w
    for _ in range(30):
        f = _theta(t, w, ripple, psi) - target
        t = t - f / (w * (1 + ripple * np.cos(w * t + psi)))
    return t


def gonio_log(path, seed, *, n_rev=100, dead_time_s=0.0, double_p=0.0,
              scale_drift_ppm=0.0, latency_s=0.0, ripple=0.0, jitter_arcsec=1.0,
              glint_counts=0, glint_p=0.0):
    """Write a counter log; return the true face angles (deg, ref->y, y->x, x->z, z->ref)."""
    rng = np.random.default_rng(seed)
    rev_s = rng.uniform(0.8, 1.2)
    w = 2 * np.pi * rev_s
    k_rev = rng.uniform(7.0e5, 8.0e5)              # counts per revolution
    psi = rng.uniform(0, 2 * np.pi)
    dev = rng.uniform(-300, 300, 3) * ARCSEC
    faces = np.concatenate([[0.0], np.cumsum(np.pi / 2 + dev)])   # azimuths of the 4 faces
    truth = np.diff(np.concatenate([faces, [2 * np.pi]]))
    # pulses: face 0 of rev 0 arms the counter; rows end at faces 1,2,3,0(next),...
    idx = np.arange(1, 4 * n_rev + 1)
    target = 2 * np.pi * (idx // 4) + faces[idx % 4]
    target = np.concatenate([[0.0], target])
    target = target + rng.normal(0, jitter_arcsec * ARCSEC, target.size)
    t_face = _invert(target, w, ripple, psi)
    t_pulse = t_face + latency_s
    t_span = t_pulse[-1] - t_pulse[0]
    c = scale_drift_ppm * 1e-6 / t_span           # relative scale change per second

    def phase(t):
        th = _theta(t, w, ripple, psi)
        # ∫ (1 + c t) dθ = θ + c ∫ t dθ, closed form for the rippled table
        int_t_dtheta = (w * t ** 2 / 2 + ripple * (t * np.sin(w * t + psi)
                        + np.cos(w * t + psi) / w - np.cos(psi) / w))
        return k_rev / (2 * np.pi) * (th + c * int_t_dtheta)

    phi0 = rng.uniform(0, 1)
    ph = phase(t_pulse) + phi0
    counter = np.where(np.arange(idx.size) % 2 == 0, 1, 2)
    start = ph[:-1].copy()
    # counter 2 opens dead_time_s late: the ring-laser periods in that gap are lost
    late = counter == 2
    start[late] = phase(t_pulse[:-1][late] + dead_time_s) + phi0
    counts = np.floor(ph[1:]) - np.floor(start)
    counts = counts + (rng.random(counts.size) < double_p)
    ref = (idx % 4 == 0).astype(int)
    t = t_pulse[1:] - t_pulse[0] + 0.25 / rev_s
    if glint_p > 0:
        # the reference face seen twice: a second reflection glint_counts after it in a
        # fraction glint_p of revolutions; a real counter switches on every pulse
        c_out, r_out, t_out = [], [], []
        split = np.zeros(counts.size, bool)
        split[1:] = (ref[:-1] == 1) & (rng.random(counts.size - 1) < glint_p)
        for i in range(counts.size):
            if split[i]:
                frac = glint_counts / counts[i]
                c_out += [glint_counts, counts[i] - glint_counts]
                r_out += [0, ref[i]]
                t_out += [t[i - 1] + frac * (t[i] - t[i - 1]), t[i]]
            else:
                c_out.append(counts[i])
                r_out.append(ref[i])
                t_out.append(t[i])
        counts, ref, t = np.array(c_out), np.array(r_out), np.array(t_out)
        counter = np.where(np.arange(counts.size) % 2 == 0, 1, 2)
    with open(path, "w") as f:
        f.write("count,counter,ref,t\n")
        for cnt, ctr, r, tt in zip(counts.astype(np.int64), counter, ref, t, strict=True):
            f.write(f"{cnt},{ctr},{r},{tt:.9f}\n")
    return np.degrees(truth)


CUBE14 = np.array(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    + [[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)], float)


def tumble(path, seed, *, bias_step_g=0.0, saturate_g=np.inf, pickup_g=0.0,
           scale_temp_ppm=0.0, n_per_pose=200, rate_hz=20.0, noise_g=2e-5):
    """Write a tumble test; return the truth {k_v_per_g, bias_g}."""
    rng = np.random.default_rng(seed)
    k = -rng.uniform(2.3, 2.5, 3)                   # V/g
    b = rng.uniform(-1e-3, 1e-3, 3)                 # g
    rows = []
    t0 = 0.0
    n_pose = len(CUBE14)
    t_total = n_pose * (n_per_pose / rate_hz + 5.0)
    for p, g in enumerate(CUBE14):
        g = g / np.linalg.norm(g)
        # the fixture is levelled to ~0.5°: a small random rotation of gravity
        g = g + rng.normal(0, 0.009, 3)
        g = g / np.linalg.norm(g)
        t = t0 + np.arange(n_per_pose) / rate_hz
        bias = np.tile(b, (n_per_pose, 1))
        bias[:, 0] += np.where(t > t_total / 2, bias_step_g, 0.0)
        # warm-up: scale follows 1 - e^{-t/300 s}, reaching scale_temp_ppm
        scale = 1 + scale_temp_ppm * 1e-6 * (1 - np.exp(-t / 300.0))
        acc = g[None, :] + bias + rng.normal(0, noise_g, (n_per_pose, 3))
        acc = acc + pickup_g * np.sin(2 * np.pi * 50.0 * t + rng.uniform(0, 2 * np.pi))[:, None]
        acc = np.clip(acc, -saturate_g, saturate_g)
        u = k[None, :] * scale[:, None] * acc
        for tt, uu in zip(t, u, strict=True):
            rows.append((p, *uu, tt))
        t0 = t[-1] + 5.0
    with open(path, "w") as f:
        f.write("pose,ux,uy,uz,t\n")
        for r in rows:
            f.write(f"{r[0]},{r[1]:.9e},{r[2]:.9e},{r[3]:.9e},{r[4]:.4f}\n")
    truth = {"k_v_per_g": k.tolist(), "bias_g": b.tolist(), "t_step_s": t_total / 2}
    Path(str(path) + ".truth.json").write_text(json.dumps(truth))
    return truth


def mark_image(path, seed, *, angle_deg=None, chip_px=0.0, fpn_dn=0.0, blob=0.0,
               vignette=0.0, width_px=4.0, length_px=380.0, ss=4):
    """Write a 640x480 16-bit image of one dark scribe mark; return its true angle (deg).

    The mark is a bar ``width_px`` wide and ``length_px`` long through the centre at
    ``angle_deg`` (counter-clockwise as seen, image y down), blurred by the optics
    (Gaussian σ 1.2 px, exact for a rectangle) before sampling, the blurred intensity
    integrated over each pixel's area (mean of ``ss``² sub-samples), then shot noise (gain
    1 DN per electron, background 40 000 e⁻) and 20 DN read noise. Effects: ``chip_px`` (a chip
    this long bitten out of one edge of the mark at one end, half the mark's width deep),
    ``fpn_dn`` (row + column fixed-pattern offsets of this RMS in all), ``blob`` (a
    dirty-lens smudge of this fractional depth, σ 25 px, over the mark's left half),
    ``vignette`` (the corners this fraction darker, cos⁴-like radial fall-off).
    """
    import cv2
    from scipy.special import ndtr

    rng = np.random.default_rng(seed)
    if angle_deg is None:
        angle_deg = rng.uniform(-2, 2)
    h, w = 480, 640
    ys, xs = np.mgrid[0:h * ss, 0:w * ss]
    x = (xs + 0.5) / ss - w / 2 + rng.uniform(-3, 3)
    y = (ys + 0.5) / ss - h / 2 + rng.uniform(-3, 3)
    a = np.radians(angle_deg)
    along = x * np.cos(a) - y * np.sin(a)          # y down: ccw as seen
    across = x * np.sin(a) + y * np.cos(a)
    sig = 1.2                                       # optics blur, px

    def rect(a0, a1, c0, c1):
        """A unit rectangle (along a0..a1, across c0..c1) blurred by the isotropic
        Gaussian: separable in the rotated coordinates, exact."""
        return ((ndtr((a1 - along) / sig) - ndtr((a0 - along) / sig))
                * (ndtr((c1 - across) / sig) - ndtr((c0 - across) / sig)))

    half_l, half_w = length_px / 2, width_px / 2
    dark = rect(-half_l, half_l, -half_w, half_w)
    if chip_px > 0:
        dark = dark - rect(half_l - chip_px, half_l, 0.0, half_w)
    fine = 1.0 - 0.6 * dark
    img = fine.reshape(h, ss, w, ss).mean(axis=(1, 3))
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
    img = img * (1 - vignette * r2)
    if blob > 0:
        cx, cy = w / 2 - length_px / 4, h / 2
        img = img * (1 - blob * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * 25.0 ** 2)))
    full = 40000.0                                   # DN of the background
    electrons = img * full                           # gain 1 e-/DN
    dn = rng.poisson(electrons).astype(np.float64) + rng.normal(0, 20.0, img.shape)
    if fpn_dn > 0:                                  # row and column offsets (readout)
        fpn = rng.normal(0, fpn_dn, w)[None, :] + rng.normal(0, fpn_dn, h)[:, None]
        dn = dn + fpn / np.sqrt(2)
    cv2.imwrite(str(path), np.clip(np.round(dn), 0, 65535).astype(np.uint16))
    return angle_deg
