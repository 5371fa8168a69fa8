"""End to end against truth for ``align camera``'s lens-model choice (imaging/camera_k3.py):
chessboard photographs rendered through a known lens (:mod:`tests.align.chessboard_render`),
calibrated by the tool (k3 fitted only when the views determine it), then straight marks
rendered through the same lens (user 11's renderer) 100-250 px from the centre and measured
with the model, as ``align marks --camera`` does. The lenses: the real chessboard camera as
OpenCV calibrates it (k3 free, 7 real views: k3 −0.071, which those views do not determine)
and, as the negative control, the same lens with k3 0.8 (which 7 views do determine)."""

from __future__ import annotations

import numpy as np
import pytest

from align.marks import measure_image
from imaging import calibrate_chessboard
from tests.align import user11_inputs as ui
from tests.align.chessboard_render import board_photos, ray_grid

K_REAL = np.array([[533.50, 0.0, 340.28], [0.0, 533.75, 234.72], [0.0, 0.0, 1.0]])
D_REAL = np.array([-0.29865, 0.14847, 0.00149, -0.00014, -0.07125])
"""The real chessboard camera (``../shared/data/real/opencv-chessboard``, left01-07) as
OpenCV calibrates it with k3 free (``align camera left0*.jpg --free-k3``)."""
D_K3 = np.r_[D_REAL[:4], 0.8]
ARCSEC = np.pi / 180 / 3600


NOISE_DN = 18.0
"""The boards' sensor noise [DN]: 7 rendered views then reproject at 0.16-0.2 px RMS, as the
real photographs do (0.19 px); with 2 DN (0.07 px) the views determine the real lens's k3."""


def _run(D: np.ndarray, seeds: range, noise_dn: float, marks: int = 2, views: int = 7
         ) -> dict:
    """Per mark: error / u through the chosen model, u through it and through the k3-free
    model [″]; and per calibration whether k3 was fitted."""
    lens = {"K": K_REAL, "dist": D, "size": (640, 480)}
    rays = ray_grid(K_REAL, D, (640, 480))
    z, u_auto, u_free, fitted = [], [], [], []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        photos = board_photos(rng, views, rays, K_REAL, D, noise_dn=noise_dn)
        # (The rendered boards are exact: their print tolerance declared 0, as a certified
        # board's would be; the default 0.1 % is carried as a Type B term, and on these
        # square boards it left RMS z 0.56, the k3 choice not being what it tests.)
        cam, _ = calibrate_chessboard(photos, (9, 6), board_tolerance=0.0)
        free, _ = calibrate_chessboard(photos, (9, 6), k3="free", board_tolerance=0.0)
        fitted.append(cam.lens_choice["k3"] == "fitted")
        for k in range(marks):
            a = rng.uniform(-np.pi / 2, np.pi / 2)
            r, phi = rng.uniform(100, 250), rng.uniform(0, 2 * np.pi)
            off = np.clip(r * np.array([np.cos(phi), np.sin(phi)]), [-230, -150], [230, 150])
            img = ui.render_mark(lens, np.array([np.cos(a), np.sin(a)]),
                                 tuple(np.array([319.5, 239.5]) + off), 10 * seed + k,
                                 length_px=150.0)
            row = []
            for m in (cam, free):
                (res,) = [x for x in measure_image(img, "m.png", m) if x.found][:1]
                row.append(res)
            err = (row[0].angle_rad - a + np.pi / 2) % np.pi - np.pi / 2
            z.append(err / row[0].angle_u_rad)
            u_auto.append(row[0].angle_u_rad / ARCSEC)
            u_free.append(row[1].angle_u_rad / ARCSEC)
    return {"z": np.array(z), "u_auto": np.array(u_auto), "u_free": np.array(u_free),
            "fitted": np.array(fitted)}


@pytest.mark.slow  # ~90 s: 2 lenses x 8 seeds: 7 boards rendered, calibrated twice, 2 marks
def test_rendered_boards_and_marks_through_the_real_lens_and_a_k3_lens():
    """Over 8 seeds per lens: every |error| / u ≤ 3 and RMS z within 0.6-1.2. The real
    lens on boards as noisy as the real photographs (its k3 left out or kept as the views
    say: both branches run); the control on clean boards (2 DN: 0.07 px), where 7 views
    determine its k3, always kept (on 18 DN boards they determine it in 5 of 8, and the
    angles stay covered: RMS z 0.72, max 2.27). Prints the median u of the marks
    through the chosen model and through the k3-free one (the issue's before/after).
    Default twin: tests/imaging/test_camera_k3.py (the same choice on projected corners)."""
    for name, D, noise, kept in (("real", D_REAL, NOISE_DN, False), ("k3 0.8", D_K3, 2.0, True)):
        out = _run(D, range(8), noise)
        z = out["z"]
        rms = float(np.sqrt(np.mean(z**2)))
        print(f"{name}: k3 fitted in {out['fitted'].mean():.2f} of calibrations; RMS z "
              f"{rms:.2f}, max |z| {np.abs(z).max():.2f}; median u {np.median(out['u_auto']):.0f}″ "
              f"(k3 free: {np.median(out['u_free']):.0f}″)")
        assert np.abs(z).max() <= 3.0, z
        assert 0.6 <= rms <= 1.2, rms
        if kept:
            assert out["fitted"].all()
