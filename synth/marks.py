"""Synthetic camera images of housing faces with engraved scribe marks, with known truth.

The image is rendered as physics, not drawn: each mark is a finite straight groove with a
depth profile (``box``, ``v`` or ``round``) that changes the surface reflectance; the optics
blur the irradiance with an isotropic Gaussian point-spread function; each pixel integrates
the irradiance over its area (supersampled); the sensor adds Poisson shot noise and Gaussian
read noise and quantises to 8, 12 or 16 bits, clipping at full scale (saturation). Optional
clutter: machined-surface streaks, an illumination gradient and vignetting, dust specks,
scratches, printed labels, zero padding along the edges. Optional camera effects: OpenCV
radial distortion, camera roll, non-square pixels (see :mod:`synth.optics`); a defocus
gradient (the PSF's width changing across the field: a tilted or curved object plane); row and
column fixed-pattern noise (per-row / per-column offsets of the read-out, fixed for the
sensor); JPEG compression of 8-bit images (the camera's encoder, with its 8x8 blocks).

Every image comes with an :class:`ImageTruth` that records the marks and the Cramér–Rao bound
on each mark's angle, computed from the noise-free render by numerical differentiation.

Units: lengths in pixels, angles in radians, signal in electrons (e-) or digital numbers (DN).
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from scipy.special import erf

from axisbase.interp import interp_uniform
from synth.optics import wrap_half_turn
from synth.profiles import along_profile, blurred_profile
from synth.specs import PROFILES, ImageSpec, ImageTruth, MarkSpec, MarkTruth, SynthImage

__all__ = ["PROFILES", "ImageSpec", "ImageTruth", "MarkSpec", "MarkTruth", "SynthImage", "crlb",
           "full_well_for_snr", "mark_coverage", "render_marks", "write_image", "write_synth"]

# ----------------------------------------------------------------------------- rendering

def _pixel_grid(spec: ImageSpec) -> tuple[np.ndarray, np.ndarray]:
    cx, cy = (spec.width - 1) / 2, (spec.height - 1) / 2
    xs = np.arange(spec.width, dtype=float) - cx
    ys = np.arange(spec.height, dtype=float) - cy
    return xs, ys


def _mark_band(spec: ImageSpec, mark: MarkSpec, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (rows, cols) of the pixels the mark can touch.

    Only the mark's bounding box (mapped to the sensor, with room for distortion) is examined,
    in strips of rows, so a 12 MP frame never needs full-frame coordinate arrays.
    """
    xs, ys = _pixel_grid(spec)
    a = mark.angle_rad
    u = np.array([np.cos(a), -np.sin(a)])
    n = np.array([np.sin(a), np.cos(a)])
    mid = np.array(mark.centre_xy())
    reach = mark.width_px / 2 + margin + abs(mark.bow_px)
    ends = [mid + su * (mark.length_px / 2 + margin) * u + sn * reach * n
            for su in (-1, 1) for sn in (-1, 1)]
    ex, ey = spec.camera.distort(*spec.camera.scene_to_ideal(
        np.array([p[0] for p in ends]), np.array([p[1] for p in ends])))
    # Distortion bends straight edges by at most a few % of the frame: widen the box by that.
    slack = 0.05 * max(spec.width, spec.height) if not spec.camera.is_identity else 2.0
    cols = np.flatnonzero((xs >= np.min(ex) - slack) & (xs <= np.max(ex) + slack))
    rows_all = np.flatnonzero((ys >= np.min(ey) - slack) & (ys <= np.max(ey) + slack))
    out_r, out_c = [], []
    for k in range(0, rows_all.size, 256):
        rows = rows_all[k:k + 256]
        X, Y = np.meshgrid(xs[cols], ys[rows])
        sx, sy = spec.camera.sensor_to_scene(X, Y)
        e = sx * np.sin(a) + sy * np.cos(a) - mark.offset_px
        t = sx * np.cos(a) - sy * np.sin(a) - mark.centre_t_px
        # Distortion stretches the sensor by at most a few %; the margin covers it.
        r, c = np.nonzero((np.abs(e - mark.bow(t)) < mark.width_px / 2 + margin)
                          & (np.abs(t) < mark.length_px / 2 + margin))
        out_r.append(rows[r])
        out_c.append(cols[c])
    if not out_r:
        return np.empty(0, int), np.empty(0, int)
    return np.concatenate(out_r), np.concatenate(out_c)


def mark_coverage(spec: ImageSpec, mark: MarkSpec, rows: np.ndarray, cols: np.ndarray
                  ) -> np.ndarray:
    """Area-integrated, blurred groove depth (0..1) at the given pixels."""
    return _coverage(spec, mark, _scene_points(spec, rows, cols))


Points = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""The supersampled points of some pixels: sensor x, y and scene x, y [px], (pixels, ss^2)."""


def _scene_points(spec: ImageSpec, rows: np.ndarray, cols: np.ndarray) -> Points:
    """The pixels' supersampled points on the sensor and in the scene (they depend on the
    frame, the supersampling and the camera alone: the CRLB's 13 renders of a mark share
    them)."""
    cx, cy = (spec.width - 1) / 2, (spec.height - 1) / 2
    ss = spec.supersample
    off = (np.arange(ss) + 0.5) / ss - 0.5
    ox, oy = np.meshgrid(off, off)
    px = (cols[:, None] - cx) + ox.ravel()[None, :]
    py = (rows[:, None] - cy) + oy.ravel()[None, :]
    sx, sy = spec.camera.sensor_to_scene(px, py)
    return px, py, sx, sy


def _coverage(spec: ImageSpec, mark: MarkSpec, points: Points) -> np.ndarray:
    """:func:`mark_coverage` at the pixels' :func:`_scene_points`."""
    px, py, sx, sy = points
    a = mark.angle_rad
    e = sx * np.sin(a) + sy * np.cos(a) - mark.offset_px
    t = sx * np.cos(a) - sy * np.sin(a) - mark.centre_t_px
    e = e - mark.bow(t)
    if tuple(spec.blur_gradient) == (0.0, 0.0):
        across = blurred_profile(mark.profile, mark.width_px, spec.blur_px)
        along = along_profile(mark.length_px, spec.blur_px)
        return (across(e) * along(t)).mean(axis=1)
    return (_across_varying(mark, e, spec.blur_at(px, py))
            * along_profile(mark.length_px, spec.blur_at(px, py))(t)).mean(axis=1)


def _max_blur(spec: ImageSpec) -> float:
    """The widest PSF sigma anywhere in the frame [px]."""
    gx, gy = spec.blur_gradient
    return float(spec.blur_px + abs(gx) * spec.width / 2 + abs(gy) * spec.height / 2)


def _across_varying(mark: MarkSpec, e: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The blurred groove profile at ``e`` seen through a PSF of local width ``sigma`` [px].

    A defocus gradient changes the PSF over tens of px, the groove's profile over a few: the
    PSF is locally the Gaussian of the local sigma. Profiles are tabulated on a grid of sigma
    0.02 px apart and interpolated linearly between them (error ~1e-5 of the depth).
    """
    step = 0.02
    lo = float(np.floor(sigma.min() / step)) * step
    idx = (sigma - lo) / step
    out = np.zeros_like(e)
    for i in range(int(np.floor(idx.max())) + 2):
        w = np.clip(1 - np.abs(idx - i), 0, None)
        sel = w > 0
        if sel.any():
            out[sel] += w[sel] * blurred_profile(mark.profile, mark.width_px,
                                                  lo + i * step)(e[sel])
    return out


def _illumination(spec: ImageSpec) -> np.ndarray:
    xs, ys = _pixel_grid(spec)
    gx, gy = spec.gradient
    if gx == 0 and gy == 0 and spec.vignetting == 0:
        light = np.ones((spec.height, spec.width))  # (the expression below's 1.0, exactly)
    else:
        X, Y = np.meshgrid(xs / max(xs.max(), 1), ys / max(ys.max(), 1))
        r2 = (X**2 + Y**2) / 2
        light = (1 + gx * X + gy * Y) * (1 - spec.vignetting * r2)
    a, offset, width, depth = spec.shadow
    if depth:
        # Something between the lamp and the face: its shadow multiplies the light, with a
        # penumbra (the lamp's extent) across the edge.
        gx_px, gy_px = np.meshgrid(xs, ys)
        dist = gx_px * np.sin(a) + gy_px * np.cos(a) - offset
        light = light * (1 - depth * 0.5 * (1 + erf(dist / (np.sqrt(2) * max(width, 1e-6)))))
    return light


def _texture(spec: ImageSpec, rng: np.random.Generator) -> np.ndarray:
    """Directional machining streaks: a random 1-D profile across the lay, stretched along it."""
    xs, ys = _pixel_grid(spec)
    X, Y = np.meshgrid(xs, ys)
    phi = spec.texture_angle_rad
    q = X * np.sin(phi) + Y * np.cos(phi)
    step = 0.25
    grid = np.arange(q.min() - 10, q.max() + 10, step)
    from scipy.ndimage import gaussian_filter1d

    fine = gaussian_filter1d(rng.standard_normal(grid.size), spec.texture_scale_px / step)
    broad = gaussian_filter1d(rng.standard_normal(grid.size), 8 * spec.texture_scale_px / step)
    prof = fine / fine.std() + 0.5 * broad / broad.std()
    # (np.interp's values: q lies inside the grid, 10 px from either end)
    return spec.texture * interp_uniform(q, grid, (prof / prof.std(),))[0]


def _stripes(spec: ImageSpec) -> np.ndarray:
    """The lay's reflectance factor over the frame (blurred by the optics like the rest)."""
    xs, ys = _pixel_grid(spec)
    X, Y = np.meshgrid(xs, ys)
    a = spec.stripes_angle_rad
    q = X * np.sin(a) + Y * np.cos(a)  # across crests that run along (cos a, -sin a)
    ph = 2 * np.pi * q / spec.stripes_period_px + spec.stripes_phase
    # A sinusoid through a Gaussian PSF keeps its shape, its amplitude x exp(-2 pi^2 s^2 f^2).
    s2 = 2 * (np.pi * spec.blur_px / spec.stripes_period_px) ** 2
    return 1 + spec.stripes * (np.exp(-s2) * np.sin(ph)
                               + spec.stripes_second * np.exp(-4 * s2) * np.sin(2 * ph))


def _clutter(spec: ImageSpec, rng: np.random.Generator) -> np.ndarray:
    """Dust specks (blobs) and scratches (thin short lines), already blurred by the optics."""
    h, w = spec.height, spec.width
    out = np.zeros((h, w))
    centres = [(rng.uniform(0, w - 1), rng.uniform(0, h - 1)) for _ in range(spec.dust)]
    for k in range(spec.dust_on_mark):
        m = spec.marks[k % len(spec.marks)]
        t = rng.uniform(-0.4, 0.4) * m.length_px
        a = m.angle_rad
        x = m.offset_px * np.sin(a) + (m.centre_t_px + t) * np.cos(a)
        y = m.offset_px * np.cos(a) - (m.centre_t_px + t) * np.sin(a)
        xi, yi = spec.camera.distort(*spec.camera.scene_to_ideal(np.array(x), np.array(y)))
        centres.append((float(xi) + (w - 1) / 2, float(yi) + (h - 1) / 2))
    for x0, y0 in centres:
        r = rng.uniform(1.0, 3.5)
        amp = rng.choice([-1, 1]) * rng.uniform(0.3, 0.9)
        s = np.hypot(r, spec.blur_px)
        r0, r1 = int(max(0, y0 - 5 * s)), int(min(h, y0 + 5 * s + 1))
        c0, c1 = int(max(0, x0 - 5 * s)), int(min(w, x0 + 5 * s + 1))
        yy, xx = np.mgrid[r0:r1, c0:c1]
        out[r0:r1, c0:c1] += amp * np.exp(-((xx - x0) ** 2 + (yy - y0) ** 2) / (2 * s * s))
    for _ in range(spec.scratches):
        x0, y0 = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
        ang = rng.uniform(0, np.pi)
        length = rng.uniform(20, spec.scratch_max_px or 0.15 * min(w, h))
        amp = rng.choice([-1, 1]) * rng.uniform(0.1, 0.4)
        s = np.hypot(rng.uniform(0.3, 0.8), spec.blur_px)
        ux, uy = np.cos(ang), np.sin(ang)
        pad = length / 2 + 5 * s
        r0, r1 = int(max(0, y0 - pad)), int(min(h, y0 + pad + 1))
        c0, c1 = int(max(0, x0 - pad)), int(min(w, x0 + pad + 1))
        yy, xx = np.mgrid[r0:r1, c0:c1]
        t = (xx - x0) * ux + (yy - y0) * uy
        e = -(xx - x0) * uy + (yy - y0) * ux
        inside = along_profile(length, s)(t)
        out[r0:r1, c0:c1] += amp * inside * np.exp(-e * e / (2 * s * s))
    for _ in range(spec.text):
        _label(out, spec, rng)
    return out


def _stroke(out: np.ndarray, p0: np.ndarray, p1: np.ndarray, width: float, amp: float,
            blur: float) -> None:
    """Add a straight printed stroke (box profile of ``width`` [px] seen through the blur)."""
    h, w = out.shape
    d = p1 - p0
    length = float(np.hypot(*d))
    if length == 0:
        return
    ux, uy = d / length
    mid = (p0 + p1) / 2
    s = max(blur, 0.3)
    pad = length / 2 + width + 5 * s
    r0, r1 = int(max(0, mid[1] - pad)), int(min(h, mid[1] + pad + 1))
    c0, c1 = int(max(0, mid[0] - pad)), int(min(w, mid[0] + pad + 1))
    if r1 <= r0 or c1 <= c0:
        return
    yy, xx = np.mgrid[r0:r1, c0:c1]
    t = (xx - mid[0]) * ux + (yy - mid[1]) * uy
    e = -(xx - mid[0]) * uy + (yy - mid[1]) * ux
    out[r0:r1, c0:c1] += amp * along_profile(length, s)(t) * blurred_profile(
        "box", width, s)(e)


def _label(out: np.ndarray, spec: ImageSpec, rng: np.random.Generator) -> None:
    """A printed label: 2-4 numeral-like glyphs of 2-4 short strokes each (text clutter)."""
    h, w = out.shape
    size = rng.uniform(10, 30)  # glyph height [px]
    n = int(rng.integers(2, 5))
    x0 = rng.uniform(0, max(1.0, w - n * 0.8 * size))
    y0 = rng.uniform(0, max(1.0, h - size))
    amp = rng.choice([-1, 1]) * rng.uniform(0.2, 0.8)
    width = rng.uniform(0.08, 0.15) * size
    # Strokes of a seven-segment-like glyph: corners of a size/2 x size box.
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0, 2], [1, 2]]) * size / 2
    for k in range(n):
        org = np.array([x0 + k * 0.8 * size, y0])
        for _ in range(int(rng.integers(2, 5))):
            i, j = rng.choice(6, 2, replace=False)
            _stroke(out, org + corners[i], org + corners[j], width, amp, spec.blur_px)


def _mean_electrons(spec: ImageSpec, rng: np.random.Generator) -> np.ndarray:
    refl = np.ones((spec.height, spec.width))
    if spec.texture:
        from scipy.ndimage import gaussian_filter

        refl += gaussian_filter(_texture(spec, rng), spec.blur_px) if spec.blur_px else 0
    margin = 7 * _max_blur(spec) + 3
    for m in spec.marks:
        r, c = _mark_band(spec, m, margin)
        refl[r, c] += m.contrast * mark_coverage(spec, m, r, c)
    if spec.stripes:  # the surface and its grooves; dust lies on top
        refl *= _stripes(spec)
    refl += _clutter(spec, rng)
    return np.clip(refl, 0, None) * _illumination(spec) * spec.exposure * spec.full_well_e


def _fixed_pattern(spec: ImageSpec) -> np.ndarray:
    """Row and column read-out offsets [e-] (fixed for the sensor: column amplifiers and
    row drivers), from the seed's own stream so they leave every other draw unchanged."""
    fpn = np.random.default_rng([spec.seed, 0xF9]).standard_normal(spec.width + spec.height)
    signal = spec.exposure * spec.full_well_e
    return (spec.column_fpn * signal * fpn[None, :spec.width]
            + spec.row_fpn * signal * fpn[spec.width:, None])


def _jpeg(dn: np.ndarray, quality: int) -> np.ndarray:
    """The 8-bit image through a baseline JPEG encoder and decoder (the camera's)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", dn, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise OSError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)


def _digitise(spec: ImageSpec, mean_e: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    e = rng.poisson(mean_e).astype(float) + rng.normal(0.0, spec.read_noise_e, mean_e.shape)
    if spec.column_fpn or spec.row_fpn:
        e += _fixed_pattern(spec)
    full = 2**spec.bits - 1
    dn = np.clip(np.round(e * full / spec.full_well_e), 0, full)
    p = spec.padding_px
    if p:
        # A driver's padding: whole rows/columns of zeros after read-out, not light.
        dn[:p], dn[-p:], dn[:, :p], dn[:, -p:] = 0, 0, 0, 0
    out = dn.astype(np.uint16 if spec.bits > 8 else np.uint8)
    if spec.jpeg_quality:
        if spec.bits != 8:
            raise ValueError("jpeg_quality needs bits = 8 (baseline JPEG is 8-bit)")
        out = _jpeg(out, spec.jpeg_quality)
    return out


# ----------------------------------------------------------------------------- CRLB

def crlb(spec: ImageSpec, index: int = 0, free_k1: bool = False, free_ends: bool = False
         ) -> tuple[float, float]:
    """Cramér–Rao bounds (angle [rad], offset [px]) of mark ``index`` from the noise-free render.

    Fisher information over pixels for (angle about the mark's middle, offset, contrast,
    surface exposure, width, blur), with per-pixel variance shot + read + ADC quantisation.
    Clutter (texture, dust, scratches) is left out: it is not noise.

    Parameters
    ----------
    spec : ImageSpec
        The image.
    index : int
        Which of its marks.
    free_k1 : bool
        Also a nuisance parameter: the camera's k1 (OpenCV, about ``spec.camera.k1``), so the
        bound is that of a line whose lens bow is fitted from its own pixels.
    free_ends : bool
        Also nuisance parameters: the mark's length and its position along its line. A tool is
        never told where a mark ends; with them known, the bound takes k1 from how far the
        lens moves the ends radially (1.4-1.75x lower than with them free, issue 18).

    Returns
    -------
    tuple of float
        The bounds on the angle [rad] and on the offset [px] (standard deviations).
    """
    m = spec.marks[index]
    margin = 7 * _max_blur(spec) + 4
    rows, cols = _mark_band(spec, m, margin)
    gain = (2**spec.bits - 1) / spec.full_well_e
    illum = _illumination(spec)[rows, cols] * spec.exposure * spec.full_well_e
    cx, cy = m.centre_xy()
    points = _scene_points(spec, rows, cols)  # (the same for every render below)

    def mean(angle=m.angle_rad, offset=None, contrast=m.contrast, exposure=1.0,
             width=m.width_px, blur=spec.blur_px, k1=spec.camera.k1, length=m.length_px,
             shift=0.0):
        # Rotating about the mark's middle keeps its centre fixed: recompute offset and t.
        off = cx * np.sin(angle) + cy * np.cos(angle) if offset is None else offset
        tc = cx * np.cos(angle) - cy * np.sin(angle) + shift
        mk = replace(m, angle_rad=angle, offset_px=off, centre_t_px=tc,
                     contrast=contrast, width_px=width, length_px=length)
        s = replace(spec, blur_px=blur)
        # A k1 other than the camera's moves every pixel's scene point: map them again.
        pts = points if k1 == spec.camera.k1 else _scene_points(
            replace(spec, camera=replace(spec.camera, k1=k1)), rows, cols)
        return exposure * illum * (1 + contrast * _coverage(s, mk, pts))

    mu = mean()
    off0 = m.offset_px
    steps = {
        "angle": 2e-5, "offset": 1e-3, "contrast": 1e-3, "exposure": 1e-4,
        "width": 1e-3, "blur": 1e-3,
    }
    if free_k1:
        steps["k1"] = 1e-3
    if free_ends:
        steps.update(length=1e-3, shift=1e-3)
    derivs = []
    for name, h in steps.items():
        if name == "offset":
            # offset moves the line along its normal: shift with the angle fixed.
            plus, minus = mean(offset=off0 + h), mean(offset=off0 - h)
        elif name == "angle":
            plus, minus = mean(angle=m.angle_rad + h), mean(angle=m.angle_rad - h)
        elif name == "blur" and spec.blur_px <= 0:
            continue
        else:
            base = {"contrast": m.contrast, "exposure": 1.0, "width": m.width_px,
                    "blur": spec.blur_px, "k1": spec.camera.k1, "length": m.length_px,
                    "shift": 0.0}[name]
            plus = mean(**{name: base + h})
            minus = mean(**{name: base - h})
        derivs.append((plus - minus) / (2 * h))
    J = np.stack(derivs, axis=1)
    var = mu + spec.read_noise_e**2 + 1 / (12 * gain**2)
    fisher = J.T @ (J / var[:, None])
    cov = np.linalg.inv(fisher)
    return float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1]))


# ----------------------------------------------------------------------------- public

def render_marks(spec: ImageSpec, with_crlb: bool = True) -> SynthImage:
    """Render a synthetic image and its truth.

    Parameters
    ----------
    spec : ImageSpec
        The image to render.
    with_crlb : bool
        Compute each mark's Cramér–Rao bounds (else NaN; they cost a second render).

    Returns
    -------
    SynthImage
        The digitised image [DN], its truth and the noise-free signal [e-].

    Raises
    ------
    ValueError
        ``bits`` not 8, 12 or 16.
    """
    if spec.bits not in (8, 12, 16):
        raise ValueError("bits must be 8, 12 or 16")
    rng = np.random.default_rng(spec.seed)
    mean_e = _mean_electrons(spec, rng)
    img = _digitise(spec, mean_e, rng)
    gain = (2**spec.bits - 1) / spec.full_well_e
    bg_e = spec.exposure * spec.full_well_e
    noise_dn = float(np.sqrt(bg_e + spec.read_noise_e**2) * gain)
    truths = []
    for i, m in enumerate(spec.marks):
        ia = spec.camera.image_angle(m.angle_rad)
        cx, cy = m.centre_xy()
        ix, iy = spec.camera.scene_to_ideal(np.array(cx), np.array(cy))
        ioff = float(ix * np.sin(ia) + iy * np.cos(ia))
        cr = crlb(spec, i) if with_crlb else (float("nan"), float("nan"))
        truths.append(MarkTruth(
            angle_rad=wrap_half_turn(m.angle_rad), offset_px=m.offset_px,
            image_angle_rad=ia, image_offset_px=ioff, length_px=m.length_px,
            width_px=m.width_px, centre_xy_px=(cx, cy), profile=m.profile,
            contrast=m.contrast, crlb_angle_rad=cr[0], crlb_offset_px=cr[1]))
    contrast_dn = tuple(abs(m.contrast) * bg_e * gain for m in spec.marks)
    truth = ImageTruth(
        width=spec.width, height=spec.height, blur_px=spec.blur_px, bits=spec.bits,
        noise_dn_background=noise_dn, contrast_dn=contrast_dn,
        snr=tuple(c / noise_dn for c in contrast_dn), marks=tuple(truths),
        # (k3 only when the lens has one: a truth file of a k3-free lens stays the same bits)
        camera={k: v for k, v in asdict(spec.camera).items() if k != "k3" or v},
        seed=spec.seed)
    return SynthImage(image=img, truth=truth, mean_e=mean_e)


def full_well_for_snr(snr: float, contrast: float, exposure: float = 0.5,
                      read_noise_e: float = 10.0) -> float:
    """Full well [e-] that gives a mark contrast / background noise ratio of ``snr``.

    Parameters
    ----------
    snr : float
        The wanted contrast / noise ratio — dimensionless.
    contrast : float
        The mark's relative contrast (its sign does not matter) — dimensionless.
    exposure : float
        The bare surface's signal as a fraction of the full well.
    read_noise_e : float
        Read noise [e-].

    Returns
    -------
    float
        The full well [e-].
    """
    # snr = |c| B / sqrt(B + r^2)  ->  solve the quadratic for B (background electrons).
    k = (snr / abs(contrast)) ** 2
    b = (k + np.sqrt(k * k + 4 * k * read_noise_e**2)) / 2
    return float(b / exposure)


def write_image(path: str | Path, image: np.ndarray) -> Path:
    """Write an 8/16-bit grayscale image as PNG or TIFF (by suffix); never overwrite.

    Parameters
    ----------
    path : str or Path
        A new file: ``.tif``/``.tiff`` for TIFF, else PNG.
    image : ndarray
        Grayscale pixels [DN], uint8 or uint16.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    FileExistsError
        ``path`` exists.
    OSError
        OpenCV could not write it.
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path}: exists; synth never overwrites files")
    if path.suffix.lower() in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, image)
    else:
        import cv2

        if not cv2.imwrite(str(path), image):
            raise OSError(f"{path}: could not write image")
    return path


def write_synth(sample: SynthImage, path: str | Path) -> tuple[Path, Path]:
    """Write the image and ``<stem>.truth.json`` beside it.

    Parameters
    ----------
    sample : SynthImage
        The rendered image.
    path : str or Path
        The image file (see :func:`write_image`).

    Returns
    -------
    tuple of Path
        The image and the truth file.
    """
    p = write_image(path, sample.image)
    tp = p.with_suffix(".truth.json")
    tp.write_text(sample.truth.to_json())
    return p, tp
