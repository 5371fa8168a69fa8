"""Independent user 12's image generators (numpy, scipy, OpenCV only: nothing from the project).

A scribe mark is a straight groove in the scene (the ideal, undistorted pixel frame of a pinhole
camera K): a box of width ``w`` [px] and relative depth ``c``, blurred by the optics (Gaussian
sigma ``s`` [px]), its ends blurred the same way. Each sensor pixel integrates the scene over its
area (``ss`` x ``ss`` sub-samples) at the points the lens maps it from: OpenCV's
``undistortPoints`` (iterated to 1e-12, checked against ``projectPoints``, the forward model)
gives the scene point of each sub-sample. Shot noise (Poisson on ``full_well`` electrons at the
background), then quantised to ``bits``.

A groove's ``angle_deg`` is its direction in the ideal pixel frame, from +x towards +y (rows
down). Its truth as the tool states angles (:func:`truth_deg`) is the direction in the camera's
normalised frame (x/fx, y/fy: the scene, square), counter-clockwise on the screen positive (a
centre mark drawn at +30 deg is read at -30 deg on a lens-free camera).
"""

from __future__ import annotations

import glob
import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.special import ndtr


def calibrate_chessboard(folder: Path, pattern: str = "*.jpg"
                         ) -> tuple[np.ndarray, np.ndarray, float, int]:
    """My own calibration of the chessboard camera: cv2.calibrateCamera (k1 k2 p1 p2 k3)
    of the photographs ``pattern`` in ``folder``.

    Returns K, dist (5,), RMS reprojection [px], views used.
    """
    objp = np.zeros((54, 3), np.float32)
    objp[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    obj, img, shape = [], [], None
    for f in sorted(glob.glob(str(folder / pattern))):
        g = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(g, (9, 6))
        if not ok:
            continue
        c = cv2.cornerSubPix(g, c, (5, 5), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-3))
        obj.append(objp)
        img.append(c)
        shape = g.shape[::-1]
    rms, k, d, _, _ = cv2.calibrateCamera(obj, img, shape, None, None)
    return k, d.ravel()[:5], float(rms), len(obj)


@dataclass(frozen=True)
class Groove:
    """A straight groove in the ideal pixel frame."""

    x: float          # middle, ideal pixel column
    y: float          # middle, ideal pixel row
    angle_deg: float  # direction, from +x towards +y (image rows down)
    length: float     # [px]
    width: float = 4.0
    depth: float = 0.5


def truth_deg(g: Groove, k: np.ndarray | None) -> float:
    """The groove's direction as the tool reports it [deg]: normalised frame, y up."""
    fx, fy = (1.0, 1.0) if k is None else (k[0, 0], k[1, 1])
    th = np.deg2rad(g.angle_deg)
    return float(-np.rad2deg(np.arctan2(np.sin(th) / fy, np.cos(th) / fx)))


def angle_err_arcsec(measured_deg: float, truth: float) -> float:
    """Difference of two line directions, wrapped to (-90, 90] deg, in arc-seconds."""
    return ((measured_deg - truth + 90.0) % 180.0 - 90.0) * 3600.0


def ideal_of_pixels(pts: np.ndarray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Scene (ideal pixel) points that the lens images at sensor points ``pts`` (N, 2)."""
    if d is None or not np.any(d):
        return pts.astype(np.float64)
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    und = cv2.undistortPoints(pts.reshape(-1, 1, 2).astype(np.float64), k, d, P=k,
                              criteria=crit).reshape(-1, 2)
    return und


def project(ideal: np.ndarray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Forward model: ideal pixel points -> sensor pixels (cv2.projectPoints)."""
    kinv = np.linalg.inv(k)
    h = np.c_[ideal, np.ones(len(ideal))] @ kinv.T
    out, _ = cv2.projectPoints(h.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k,
                               np.zeros(5) if d is None else d)
    return out.reshape(-1, 2)


def _groove_dark(px: np.ndarray, g: Groove, s: float) -> np.ndarray:
    th = np.deg2rad(g.angle_deg)
    u = np.array([np.cos(th), np.sin(th)])
    n = np.array([-u[1], u[0]])
    rel = px - np.array([g.x, g.y])
    t = rel @ u
    dd = rel @ n
    across = ndtr((dd + g.width / 2) / s) - ndtr((dd - g.width / 2) / s)
    along = ndtr((t + g.length / 2) / s) - ndtr((t - g.length / 2) / s)
    return g.depth * across * along


def render(grooves: list[Groove], k: np.ndarray | None, d: np.ndarray | None,
           size=(640, 480), blur: float = 1.0, full_well: float = 20000.0, bits: int = 8,
           seed: int = 0, ss: int = 5, level: float = 0.75,
           check_forward: bool = True) -> np.ndarray:
    """Render the grooves through the lens (K, dist) as an integer image ``bits`` deep."""
    w, h = size
    if k is None:
        k = np.array([[1000.0, 0, (w - 1) / 2], [0, 1000.0, (h - 1) / 2], [0, 0, 1]])
    yy, xx = np.mgrid[0:h, 0:w]
    centres = np.c_[xx.ravel(), yy.ravel()].astype(np.float64)
    ideal = ideal_of_pixels(centres, k, d)
    dark = np.zeros(len(centres))
    offs = (np.arange(ss) + 0.5) / ss - 0.5
    sub = np.array([(a, b) for b in offs for a in offs])
    for g in grooves:
        # pixels whose scene point is near the groove get the pixel-area integral
        th = np.deg2rad(g.angle_deg)
        u = np.array([np.cos(th), np.sin(th)])
        rel = ideal - np.array([g.x, g.y])
        t = rel @ u
        dd = rel @ np.array([-u[1], u[0]])
        near = (np.abs(dd) < g.width / 2 + 5 * blur + 4) & (np.abs(t) < g.length / 2 + 5 * blur + 4)
        idx = np.nonzero(near)[0]
        if idx.size == 0:
            continue
        pts = (centres[idx][:, None, :] + sub[None, :, :]).reshape(-1, 2)
        sc = ideal_of_pixels(pts, k, d)
        if check_forward and d is not None and np.any(d):
            # the forward model must send each scene point back to its sub-sample (the
            # calibrated polynomial folds in the frame's extreme corners: no groove there)
            back = project(sc[:: max(1, len(sc) // 3000)], k, d)
            err = np.max(np.abs(back - pts[:: max(1, len(sc) // 3000)]))
            assert err < 1e-3, f"lens inversion failed by {err:.3g} px"
        dark[idx] += _groove_dark(sc, g, blur).reshape(idx.size, -1).mean(axis=1)
    signal = level * (1.0 - np.clip(dark, 0, 0.95))
    rng = np.random.default_rng(seed)
    electrons = rng.poisson(signal / level * full_well).astype(np.float64)
    full = (2 ** bits - 1)
    dn = np.round(electrons / full_well * level * full)
    img = np.clip(dn, 0, full).reshape(h, w)
    return img.astype(np.uint8 if bits <= 8 else np.uint16)


def save(path: Path, img: np.ndarray) -> Path:
    ok = cv2.imwrite(str(path), img)
    assert ok, path
    return path


# ---------------------------------------------------------------- ruled scale -----------------

def ruled_scale(seed: int = 0, size=(1600, 1200), n_lines: int = 23, pitch: float = 60.0,
                angle_deg: float = 90.3, long_every: int = 5, short_len: float = 150.0,
                long_len: float = 230.0, width: float = 5.0, blur: float = 1.2,
                full_well: float = 30000.0, k: np.ndarray | None = None,
                d: np.ndarray | None = None, dust_on_lines: int = 3) -> tuple[np.ndarray, dict]:
    """A stage micrometer: ``n_lines`` dark graduation lines at ``pitch`` [px], every
    ``long_every``-th longer, numerals under the long ones, dust, 12-bit data in uint16.

    ``k``, ``d``: a lens (OpenCV) the scale is imaged through; numerals and dust lie on the
    sensor side (drawn after the lens: they are not measured). ``dust_on_lines`` particles sit
    on graduations' middles. Returns the image and the truth (angle of the lines [deg] and
    pitch [px] in the ideal frame, line middles)."""
    w, h = size
    th = np.deg2rad(angle_deg)
    u = np.array([np.cos(th), np.sin(th)])
    nrm = np.array([-u[1], u[0]])
    # lines are short and parallel; their feet march along nrm
    x0 = np.array([w / 2, h / 2]) - nrm * pitch * (n_lines - 1) / 2
    grooves, mids = [], []
    for i in range(n_lines):
        ln = long_len if i % long_every == 0 else short_len
        top = x0 + nrm * pitch * i   # the lines' top ends are aligned
        mid = top + u * ln / 2 - u * long_len / 2
        grooves.append(Groove(mid[0], mid[1], angle_deg, ln, width, 0.55))
        mids.append(mid)
    img = render(grooves, k, d, size, blur, full_well, bits=12, seed=seed, ss=3)
    img = img.astype(np.float64)
    rng = np.random.default_rng(seed + 100)
    lab = np.zeros((h, w), np.uint8)
    for i in range(0, n_lines, long_every):
        m = mids[i] + u * (long_len / 2 + 40)
        cv2.putText(lab, str(i // long_every), (int(m[0]) - 12, int(m[1]) + 12),
                    cv2.FONT_HERSHEY_SIMPLEX, 1.2, 255, 3, cv2.LINE_AA)
    cv2.putText(lab, "0.01 mm", (80, 120), cv2.FONT_HERSHEY_SIMPLEX, 2.0, 255, 4, cv2.LINE_AA)
    for i in rng.choice(n_lines, dust_on_lines, replace=False):  # dust across a line
        c = mids[i] + u * rng.uniform(-40, 40)
        if k is not None and d is not None:
            c = project(c[None, :], k, d)[0]
        cv2.circle(lab, (int(c[0]), int(c[1])), int(rng.uniform(3, 6)), 200, -1, cv2.LINE_AA)
    for _ in range(25):  # dust: small dark blobs
        c = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        cv2.circle(lab, c, int(rng.uniform(2, 6)), 200, -1, cv2.LINE_AA)
    img *= 1 - 0.5 * cv2.GaussianBlur(lab.astype(np.float64) / 255, (0, 0), 1.0)
    truth = {"angle_deg": angle_deg, "pitch_px": pitch, "n_lines": n_lines,
             "mids": np.array(mids)}
    return np.clip(np.round(img), 0, 4095).astype(np.uint16), truth


# ---------------------------------------------------------------- a session -----------------

def lens_session(folder: Path, seed: int, k: np.ndarray, d: np.ndarray,
                 off_px: float = 140.0, length: float = 300.0, roll_arcsec: float = 0.0,
                 cameras_gonio_only: bool = True) -> dict:
    """A session whose camera A looks through the lens (k, d), its lens undeclared.

    The session's goniometer, tumble, platform and camera B come from ``align synth session``
    (the CLI, as a user gets a complete session); camera A's four images are re-rendered here,
    each mark at the angle the synth truth gives it (plus ``roll_arcsec``, a roll of camera A
    about its axis), ``off_px`` from the centre across its direction, through the lens. The
    [cameras.A] table is emptied: the tool gets its default lens ranges. ``cameras_gonio_only``
    drops [calibration] and [platform]: E then rests on the cameras and the goniometer.
    Returns the synth truth (misalignment_rad) and the images' truths.
    """
    subprocess.run([sys.executable, "-m", "align", "synth", "session", str(folder), "--seed",
                    str(seed), "-q"], check=True, capture_output=True)
    truth = json.loads((folder / "truth.json").read_text())
    fx, fy = k[0, 0], k[1, 1]
    roll = np.deg2rad(roll_arcsec / 3600.0)
    for im in truth["images"]:
        if not im["view"].startswith("A"):
            continue
        th = im["image_angle_rad"] + roll          # the tool's convention (y up)
        a = np.rad2deg(np.arctan2(-np.sin(th) * fy, np.cos(th) * fx))  # ideal pixels, y down
        horizontal = im["nominal"] == "horizontal"
        side = 1.0 if (seed + len(im["file"])) % 2 else -1.0
        x, y = (319.5, 239.5 + side * off_px) if horizontal else (319.5 + side * off_px, 239.5)
        g = Groove(x, y, a, length, 4.0, 0.6)
        img = render([g], k, d, (640, 480), 1.2, 6000.0, bits=16, seed=seed * 10 + len(im["file"]))
        save(folder / im["file"], img)
    toml = (folder / "session.toml").read_text()
    toml = re.sub(r"\[cameras\.A\]\n(#[^\n]*\n|lens_[^\n]*\n)*", "[cameras.A]\n", toml)
    if cameras_gonio_only:
        keep, out = True, []
        for line in toml.splitlines():
            if line.startswith("["):
                keep = not line.startswith(("[calibration", "[platform"))
            if keep:
                out.append(line)
        toml = "\n".join(out) + "\n"
    (folder / "session.toml").write_text(toml)
    return truth
