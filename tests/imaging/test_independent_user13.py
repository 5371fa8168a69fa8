"""Independent user 13: an optical metrology engineer runs `align marks` as a user would.

Renderer: tests/imaging/user13_inputs.py (own physics, written from the docs only). The lens
is the real one of ../shared/data/real/opencv-chessboard (left*.jpg), calibrated here with
plain cv2.calibrateCamera, and the images are rendered through it (each sensor sample mapped
back through the distortion to the object). Truth: the mark's angle on the object plane.

Right behaviour passes; each defect found is a strict xfail whose reason holds the figures.
The default run holds 2 tests (< 3 s CPU: the CLI's start costs ~0.8 s a call); the rest is
``-m slow``.

Speed (timed outside the tests, which do not time; the benchmarks do): my first figures were
a real photograph (left03.jpg) 10.7 s CPU and a 5 MP image (900 px mark, --camera) 0.72 s CPU
marginal per image, both with OpenBLAS's default threads spinning on the shared 2-core host.
Since `align` runs its BLAS on one thread (docs/performance.md, "Threads"): left03.jpg
0.7-0.9 s CPU, the 5 MP image 0.02-0.05 s marginal (1 -> 3 images in one call).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
ui = pytest.importorskip("tests.imaging.user13_inputs")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HAVE_REAL = os.path.isdir(ui.CHESS)
needs_real = pytest.mark.skipif(not HAVE_REAL, reason=f"real data not found at {ui.CHESS}")


def _env():
    return dict(os.environ, PYTHONPATH=ROOT, PYTHONDONTWRITEBYTECODE="1")


def align(*args):
    """Run the CLI as a user does; returns (exit status, stdout, stderr)."""
    r = subprocess.run([sys.executable, "-m", "align", *map(str, args)], capture_output=True,
                       text=True, env=_env(), cwd=ROOT, timeout=600)
    return r.returncode, r.stdout, r.stderr


def marks_json(files, *extra):
    rc, out, err = align("marks", *files, "--json", "-", "-q", *extra)
    assert "Traceback" not in err, err[-2000:]
    return rc, json.loads(out), err


def angle_crlb_arcsec(length, width, sigma, background, depth, bits=8, full_well=20000.0,
                      read_e=8.0):
    """The smallest u [″] a straight groove's angle can have from this noise (Fisher).

    Info per px of length on the offset: J = ∫ (dI/dd)² / var(I) dd, the pixel's box taken
    as extra blur (1/12 px²); angle var = 12 / (J L³) for centres spread over L.
    """
    full = 2 ** bits - 1
    s_eff = np.sqrt(sigma ** 2 + 1 / 12)
    d = np.linspace(-10 * (width + s_eff), 10 * (width + s_eff), 20001)
    band = ui._band(d, width, s_eff)
    sig = background * (1 - depth * band) * full                 # DN
    dI = np.gradient(sig, d)
    var = (sig / full * full_well + read_e ** 2) * (full / full_well) ** 2 + 1 / 12
    J = np.trapezoid(dI ** 2 / var, d)
    return float(np.sqrt(12.0 / (J * length ** 3)) * 180 / np.pi * 3600)


# ------------------------------------- the default run: 2 tests (each CLI call ~0.8 s CPU)

@needs_real
def test_mark_through_real_lens_with_its_camera(tmp_path):
    """One groove through the real chessboard lens, the exact model given with --camera."""
    K, dist, size, rms = ui.real_lens("left")
    assert rms < 0.3                                        # the calibration itself is sane
    rng = np.random.default_rng(13)
    ang, L = 23.0, 260.0
    img = ui.mark_image((K, dist, size), rng, (400.0, 170.0), np.radians(ang), length=L,
                        width=3.0, sigma=1.0, background=0.55, depth=0.3)
    f = tmp_path / "m.png"
    cv2.imwrite(str(f), img)
    cam = ui.camera_json(K, dist, size, tmp_path / "cam.json")
    rc, doc, err = marks_json([f], "--camera", cam)
    m = doc["marks"][0]
    assert rc == 0 and doc["ok"] and m["found"], err
    e = (m["angle_deg"] - ang) * 3600
    u = m["angle_u_deg"] * 3600
    crlb = angle_crlb_arcsec(0.9 * L, 3.0, 1.0, 0.55, 0.3)
    assert abs(e) <= 3 * u, (e, u)
    # u no smaller than physics allows, and not so inflated it says nothing
    assert 0.8 * crlb <= u <= 4 * crlb, (u, crlb)


@pytest.mark.slow
def test_corrupt_and_missing_images_fail_cleanly(tmp_path):
    good = tmp_path / "trunc.png"
    ok, buf = cv2.imencode(".png", np.full((64, 64), 100, np.uint8))
    good.write_bytes(buf.tobytes()[:200])                  # truncated PNG
    text = tmp_path / "text.png"
    text.write_text("not an image\n")
    rc, doc, err = marks_json([good, text, tmp_path / "absent.png"])
    assert rc == 2 and doc["ok"] is False
    assert [m["found"] for m in doc["marks"]] == [False, False, False]
    for m in doc["marks"]:
        assert m["error"] and "internal error" not in m["error"], m


def test_opencv_yaml_camera_file_named_as_such(tmp_path):
    """Was: 'not a usable camera file: Expecting value: line 1 column 1 (char 0)' (a PNG
    given as the camera: 'utf-8'); now named an OpenCV FileStorage file, with what to give."""
    yml = os.path.join(ui.LINES, "tutorial_camera_charuco.yml")
    if not os.path.exists(yml):
        pytest.skip("opencv-lines not found")
    img = tmp_path / "m.png"
    cv2.imwrite(str(img), np.full((64, 64), 100, np.uint8))
    rc, out, err = align("marks", img, "--camera", yml)
    assert rc == 2 and "Traceback" not in err
    msg = err.replace(yml, "FILE").lower()
    assert "yaml" in msg or "opencv" in msg, err


@pytest.mark.slow
def test_unsupported_bit_depths_named(tmp_path):
    """Was: an int32 TIFF (0-255000) and a 1-bit PNG refused as 'clipped ... over-exposed,
    expose less'; now each refused by its depth (imaging/io.py)."""
    tifffile = pytest.importorskip("tifffile")
    PIL = pytest.importorskip("PIL.Image")
    rng = np.random.default_rng(5)
    K = np.array([[500.0, 0, 159.5], [0, 500.0, 119.5], [0, 0, 1]])
    img = ui.mark_image((K, np.zeros(5), (320, 240)), rng, (160, 120), 0.2, length=200)
    f32 = tmp_path / "i32.tif"
    tifffile.imwrite(f32, img.astype(np.int32) * 1000)
    f1 = tmp_path / "bilevel.png"
    PIL.fromarray(img < 140).save(f1)
    rc, doc, err = marks_json([f32, f1])
    assert rc == 2
    for m in doc["marks"]:
        assert "expose less" not in (m["error"] or ""), m["error"]


# ---------------------------------------------------------------- -m slow: sweeps and figures

EFFECTS = {
    "base": {},
    "tangential": dict(lens=dict(tangential=(1e-3, -1e-3))),
    "aspect": dict(lens=dict(aspect=0.004)),
    "pp20": dict(lens=dict(pp_shift=(20.0, -20.0))),
    "defocus": dict(mark=dict(sigma=0.8, sigma_end=2.5)),
    "fpn2": dict(noise=dict(fpn=0.02)),
    "vignette": dict(noise=dict(vignette=0.5)),
    "jpeg75": dict(noise=dict(jpeg_quality=75)),
    "bits12": dict(noise=dict(bits=12)),
}


def _render_marks(tmp_path, name, seed, n=4):
    K0, d0, size0, _ = ui.real_lens("left")
    sc = EFFECTS[name]
    K, d, size = ui.scaled_lens(K0, d0, size0, 1.0, **sc.get("lens", {}))
    cam = ui.camera_json(K, d, size, tmp_path / f"cam_{name}.json")
    rng = np.random.default_rng(seed)
    files, truth = [], {}
    for i in range(n):
        ang = rng.uniform(-85, 85)
        c = (rng.uniform(170, 470), rng.uniform(150, 330))
        noise = dict(sc.get("noise", {}))
        if "vignette" in noise:
            noise["vignette"] = (K, noise["vignette"])
        img = ui.mark_image((K, d, size), rng, c, np.radians(ang), length=rng.uniform(180, 300),
                            width=3.0, **sc.get("mark", {}), **noise)
        f = tmp_path / f"{name}_{seed}_{i}.png"
        cv2.imwrite(str(f), img)
        files.append(f)
        truth[str(f)] = ang
    return files, truth, cam


@needs_real
@pytest.mark.slow
def test_marks_through_real_lens_over_seeds(tmp_path):
    """Every effect a user brings, with the exact lens as --camera: no confident wrong angle.

    A reported angle with exit 0 must be within 4 u of truth (about 100 angles: the normal
    chance of one |z| > 4 is 0.6 %), and the z's RMS within [0.5, 1.5].
    """
    zs, bad = [], []
    for name in EFFECTS:
        for seed in (1, 2, 3):
            files, truth, cam = _render_marks(tmp_path, name, seed)
            rc, doc, err = marks_json(files, "--camera", cam)
            for m in doc["marks"]:
                if not m["found"]:
                    continue
                z = (m["angle_deg"] - truth[m["image"]]) / m["angle_u_deg"]
                if rc == 0 or not m["lens_limited"]:
                    zs.append(z)
                if rc == 0 and abs(z) > 4:
                    bad.append((name, seed, m["image"], z))
    assert not bad, bad
    rms = float(np.sqrt(np.mean(np.square(zs))))
    assert 0.5 <= rms <= 1.5, rms


def _scale(tmp_path, seed, i, rng, lens):
    ang = rng.uniform(-30, 30) + rng.choice([0, 90])
    ang = (ang + 90) % 180 - 90
    pitch = rng.uniform(40, 140)
    n = int(min(11, 380 // pitch))
    img, tr = ui.scale_image(lens, rng, np.radians(ang), (rng.uniform(280, 360),
                             rng.uniform(200, 280)), n_lines=n, pitch=pitch,
                             long_len=rng.uniform(210, 250), short_len=rng.uniform(150, 180),
                             dust=6, fpn=0.01)
    f = tmp_path / f"scale_{seed}_{i}.png"
    cv2.imwrite(str(f), img)
    return f, ang, n


def _scale_lens(tmp_path):
    K0, d0, size0, _ = ui.real_lens("left")
    # the real lens plus a user's: tangential 1e-3, aspect 1.003, principal point 16 px off
    K, d, size = ui.scaled_lens(K0, d0, size0, 1.0, tangential=(1e-3, -1e-3), aspect=0.003,
                                pp_shift=(12.0, -10.0))
    return (K, d, size), ui.camera_json(K, d, size, tmp_path / "cam_scale.json")


@needs_real
@pytest.mark.slow
def test_ruled_scale_every_line_through_real_lens(tmp_path):
    """A ruled scale (numerals, dust, FPN) through the real lens with its camera: all lines."""
    lens, cam = _scale_lens(tmp_path)
    for seed in (1, 2, 3):
        rng = np.random.default_rng(seed)
        for i in range(3):
            f, ang, n = _scale(tmp_path, seed, i, rng, lens)
            rc, doc, err = marks_json([f], "--camera", cam, "--max-marks", "20")
            found = [m for m in doc["marks"] if m["found"]]
            assert len(found) == n or rc == 2, (seed, i, len(found), n)
            if rc == 0:
                fam = found[0]["family"]
                assert fam["lines"] == n and not fam["missing_steps"]
                e = (fam["angle_deg"] - ang) * 3600
                assert abs(e) <= 4 * fam["angle_u_arcsec"], (seed, i, e, fam["angle_u_arcsec"])


@needs_real
@pytest.mark.slow
def test_ruled_scale_without_camera_u_covers(tmp_path):
    """No --camera, default --lens ranges: every mark and the family angle within 3 u.

    The lens's principal point is 36 px from the image centre (the real camera's own 20.8 px
    in x plus the user's 16 px): the default range (was 20 px) left it out, and the angles'
    errors (one sign, from k1's bow read about the wrong centre) reached z 3.98. The same
    scales without a lens: no mark called bent, no z beyond 3.
    """
    lens, _ = _scale_lens(tmp_path)
    K, _, size = lens
    flat = (K, np.zeros(5), size)
    worst, flat_z, bent = [], [], []
    for seed in (1, 2, 3):
        for lens_i, zs in ((lens, worst), (flat, flat_z)):
            rng = np.random.default_rng(seed)
            for i in range(4 if lens_i is lens else 2):
                f, ang, n = _scale(tmp_path, seed, i, rng, lens_i)
                rc, doc, err = marks_json([f], "--max-marks", "20")
                fams = set()
                for m in doc["marks"]:
                    if m["found"]:
                        zs.append(abs(m["angle_deg"] - ang) / m["angle_u_deg"])
                        fam = m.get("family")
                        if fam and fam["angle_deg"] not in fams:
                            fams.add(fam["angle_deg"])
                            zs.append(abs(fam["angle_deg"] - ang) * 3600
                                      / fam["angle_u_arcsec"])
                if lens_i is flat:
                    bent += [w for w in doc["warnings"] if "is bent" in w]
    assert max(worst) <= 3.0, worst
    assert max(flat_z) <= 3.0 and not bent, (flat_z, bent)


@needs_real
@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "a mark bowed 0.5 px (sagitta, symmetric: the straight fit is unbiased, ~10″) with the "
    "exact lens given by --camera: NOT OK 'lens-limited (± 1439/1255/2198/551″, mostly "
    "camera_or_bent)', the angle -1886/-946/+72/-308″ off; 4 of 4 (seed 1). Not fixed, on "
    "purpose: one mark's bow cannot tell a bent mark from a lens that is not its calibration. "
    "A k1 change bows a line by a parabola about the foot of the perpendicular from the "
    "principal point, which over the mark is a parabola about its middle plus a tilt (the "
    "angle error): the same shape as a symmetric arc. Fitted both ways (line + arc vs. line + "
    "the change's exact undistortion), the whitened chi2 differ by -1.6..+0.65 on these marks "
    "and a noise-free change's bow misfits an arc by only 0.05-7.4 (critical 10.8 at 1e-3); "
    "on this real lens a 0.5 px bow from an OpenCV k1 change misfits an arc by 1-35, from k2 "
    "or k3 by 200-1150. Reading it as bent (u = chord vs fit, ~17″) would read a changed lens "
    "the same: up to ~1900″ off at ± 17″, ok. Now the advice names both readings and what "
    "tells them apart (straight marks in the same frame: with two, this mark is read bent, ok, "
    "within u: tests/imaging/test_bent_mark_in_frame.py) instead of 'calibrate the "
    "camera and give it with --camera'"))
def test_slightly_bent_mark_with_exact_camera(tmp_path):
    K, d, size, _ = ui.real_lens("left")
    cam = ui.camera_json(K, d, size, tmp_path / "cam.json")
    rng = np.random.default_rng(1)
    limited = 0
    for i in range(4):
        ang = rng.uniform(-85, 85)
        c = (rng.uniform(170, 470), rng.uniform(150, 330))
        img = ui.mark_image((K, d, size), rng, c, np.radians(ang), length=250.0, sagitta=0.5)
        f = tmp_path / f"bent{i}.png"
        cv2.imwrite(str(f), img)
        rc, doc, err = marks_json([f], "--camera", cam)
        limited += bool(doc["marks"][0].get("lens_limited"))
    assert limited == 0, limited


@needs_real
@pytest.mark.slow
def test_defocus_gradient_is_not_an_obstruction(tmp_path):
    """A clean mark blurred 0.8 -> 2.5 px along it: no end under an obstruction (before:
    'both ends under an obstruction ... 261 px seen, up to 783 px hidden'; each hidden end is
    now checked at its own blur, imaging/ends_blur.py)."""
    files, truth, cam = _render_marks(tmp_path, "defocus", 1, n=6)
    rc, doc, err = marks_json(files, "--camera", cam)
    assert not [w for w in doc["warnings"] if "obstruction" in w], doc["warnings"]
