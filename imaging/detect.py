"""Finding scribe marks in a full, cluttered image without being told where they are.

A coarse search on a downsampled copy: a Hessian ridge filter (both polarities), a threshold
at a multiple of the response's robust noise, connected components that are long and thin,
and merging of collinear pieces (a mark broken by dust is one mark). The result only seeds
the sub-pixel measurement in :mod:`imaging.profile`.

Geometry convention (whole package): x = column, y = row (down), pixel centres at integers,
coordinates relative to the image centre ((W-1)/2, (H-1)/2). A line has angle a in
(-pi/2, pi/2] from +x towards -y, direction u = (cos a, -sin a), normal n = (sin a, cos a),
offset d = n . p, position along it t = u . p.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy import special

from imaging.crossing import crossing_stretch, double_groove, fused_crossing, split_two_lines
from imaging.errors import ImageInputError
from imaging.io import full_scale


@dataclass(frozen=True)
class MarkCandidate:
    """A coarse mark: line (angle [rad], offset [px]), extent along it [px], polarity,
    strength (contrast x length) and mean ridge contrast (in units of the response noise).

    ``fused``: (t [px], separation [px]) where the line is seen to be two grooves that part
    on either side of it (two marks crossing at a shallow angle, fused into one ridge along
    their bisector; :func:`imaging.crossing.fused_crossing`); None: one groove."""

    angle_rad: float
    offset_px: float
    t_start_px: float
    t_end_px: float
    dark: bool
    thickness_px: float
    strength: float
    contrast: float = float("inf")
    fused: tuple[float, float] | None = None

    @property
    def length_px(self) -> float:
        return self.t_end_px - self.t_start_px


def line_frame(angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction u and normal n of a line at ``angle_rad`` in (x right, y down) pixels."""
    return (np.array([np.cos(angle_rad), -np.sin(angle_rad)]),
            np.array([np.sin(angle_rad), np.cos(angle_rad)]))


def wrap_angle(angle_rad: float) -> float:
    """Wrap a line direction to (-pi/2, pi/2]."""
    a = float((angle_rad + np.pi / 2) % np.pi - np.pi / 2)
    # np.isclose(a, -pi/2, atol=0) written out: the scalar test is ~50x cheaper, and this
    # runs in every line fit.
    return np.pi / 2 if abs(a + np.pi / 2) <= 1e-5 * (np.pi / 2) else a


def same_line(a1: float, d1: float, a2: float, d2: float, tol_angle: float,
              tol_offset: float) -> bool:
    """Whether two lines (angle [rad], offset [px]) coincide within tolerances.

    Across the +-90 deg wrap the normal flips, and with it the sign of the offset.
    """
    if abs(wrap_angle(a1 - a2)) >= tol_angle:
        return False
    flipped = abs(a1 - a2) > np.pi / 2
    return abs(d1 - (-d2 if flipped else d2)) < tol_offset


# Steger's condition: the extremum across the line, |grad| / |lambda| px from the pixel centre,
# lies within FLAT px of it (a little over half a pixel, so that a thin line running between
# two rows of the block-averaged image still marks one of them). Beside a strong step edge (a
# padded or saturated band) the profile also curves, at |grad| / |lambda| = sigma^2 / d from
# the step: those false ridges are told apart later by the two-sided contrast (_peak).
FLAT = 0.6


def _ridge(img: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Largest Hessian eigenvalue (scale-normalised): > 0 on dark lines, < 0 on bright ones.

    Also returns where the gradient is not steep compared with the curvature: the flanks of a line
    (and edges) curve too, but only the line's centre is flat (Steger's condition, see FLAT).
    """
    g = cv2.GaussianBlur(img, (0, 0), sigma)
    # Derivative scales folded into the filters (each array pass counts at 5 MP).
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
    dxx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3, scale=1 / 4)
    dyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3, scale=1 / 4)
    dxy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3, scale=1 / 16)
    tr = (dxx + dyy) * 0.5
    disc = cv2.magnitude((dxx - dyy) * 0.5, dxy)
    # The eigenvalue of larger magnitude is tr + sign(tr) disc (disc >= 0), and its magnitude
    # |tr| + disc; Steger's test on squares (no square root of the gradient).
    lam = np.where(tr >= 0, tr + disc, tr - disc)
    flat = gx * gx + gy * gy < (FLAT * FLAT) * (lam * lam)
    return (sigma**2) * lam, flat


def pixel_noise(img: np.ndarray) -> float:
    """Immerkær's fast estimate of white-noise sigma (insensitive to smooth structure) [DN]."""
    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    conv = cv2.filter2D(img.astype(np.float32), -1, k, borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2) * np.mean(np.abs(conv)) / 6)


@functools.cache
def _ridge_gain(sigma: float) -> float:
    """Standard deviation of the ridge response to unit white noise (seeded, computed once)."""
    noise = np.random.default_rng(0).standard_normal((256, 256)).astype(np.float32)
    r, _ = _ridge(noise, sigma)
    return float(np.std(r[16:-16, 16:-16]))


def _components(mask: np.ndarray, min_len: float) -> list[np.ndarray]:
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = [i for i in range(1, n)
            if np.hypot(stats[i, cv2.CC_STAT_WIDTH], stats[i, cv2.CC_STAT_HEIGHT]) >= min_len]
    if not keep:
        return []
    ys, xs = np.nonzero(np.isin(labels, keep))
    lab = labels[ys, xs]
    order = np.argsort(lab, kind="stable")
    ys, xs, lab = ys[order], xs[order], lab[order]
    cuts = np.flatnonzero(np.diff(lab)) + 1
    return [np.column_stack([x, y]).astype(float)
            for x, y in zip(np.split(xs, cuts), np.split(ys, cuts), strict=True)]


def _pca_line(pts: np.ndarray, centre: np.ndarray) -> tuple[float, float, np.ndarray, float]:
    m = pts.mean(axis=0)
    cov = np.cov((pts - m).T)
    w, v = np.linalg.eigh(cov)
    u = v[:, 1]
    a = wrap_angle(np.arctan2(-u[1], u[0]))
    uu, nn = line_frame(a)
    t = (pts - centre) @ uu
    thick = np.sqrt(max(w[0], 0)) * np.sqrt(12)
    return a, float((m - centre) @ nn), t, float(thick)


MIN_LENGTH_PX = 100.0
"""Default shortest mark [px]: scratches, printed strokes and dust are shorter."""
LENGTH_SLACK = 0.8
"""A ridge this fraction of the shortest mark's length still counts (its ends fade)."""


def default_min_length(shape: tuple[int, int]) -> float:
    """The shortest mark searched for in an image (or roi) of this shape [px]:
    :data:`MIN_LENGTH_PX`, at most 80 % of the smaller side."""
    return min(MIN_LENGTH_PX, 0.8 * min(shape))


def _odd_pad(img: np.ndarray, pad: int) -> np.ndarray:
    """Pad by point reflection about the edge pixels (2 v0 - v_k).

    The filters then see a ramp (vignetting, border darkening) continue straight through the
    frame edge, and a dark or saturated band touching the edge as a step: neither is a ridge.
    Even reflection (OpenCV's default) folds a ramp into a V at the edge, i.e. a line.
    """
    pad = int(min(pad, min(img.shape) - 1))
    return np.pad(img, pad, mode="reflect", reflect_type="odd")


def _across(image: np.ndarray, c: MarkCandidate, reach: int, n_along: int, top: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Profiles across a candidate at ``n_along`` places, nearest-pixel sampled at 1 px steps
    (NaN off the image and where clipped at 0 or ``top``): (values (n_along, E), e, t [px])."""
    h, w = image.shape
    u, n = line_frame(c.angle_rad)
    e = np.arange(-reach, reach + 1, dtype=float)
    t = np.linspace(c.t_start_px, c.t_end_px, n_along + 2)[1:-1]
    p = (np.array([(w - 1) / 2, (h - 1) / 2]) + c.offset_px * n)[None, None, :] + \
        t[:, None, None] * u + e[None, :, None] * n
    xi, yi = np.rint(p[..., 0]).astype(int), np.rint(p[..., 1]).astype(int)
    inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    vals = image[np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1)]
    # Off the image and clipped pixels (a padded border, a saturated patch) say nothing.
    vals = np.where(inside & (vals > 0) & (vals < top), vals, np.nan)
    return vals, e, t


def _column_median(vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's median over its finite values (nan where it has none) and which columns
    have any. np.median when nothing is missing (the same values, in about half the time of
    np.nanmedian, which sorts column by column)."""
    finite = np.isfinite(vals)
    cols = finite.any(axis=0)
    prof = np.full(vals.shape[1], np.nan)
    sub = vals[:, cols]
    prof[cols] = np.median(sub, axis=0) if finite.all() else np.nanmedian(sub, axis=0)
    return prof, cols


def _peak(vals: np.ndarray, e: np.ndarray, dark: bool, half: float, search: float,
          median: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[float, float]:
    """Median profile's extreme within ``search`` of the line: (position [px], contrast [DN]).

    The contrast is against the background on each side separately (the median of up to 6 px
    just beyond the flank), and the smaller of the two counts: a mark stands out from both
    sides, whereas an edge, or the strip of background between a mark and a dark padded
    border, stands out from one side only. No valid pixel beyond one flank: contrast 0.
    ``median``: :func:`_column_median` of ``vals`` when the caller has it already.
    """
    prof, cols = median if median is not None else _column_median(vals)
    if cols.sum() < 5:
        return 0.0, 0.0
    sign = -1.0 if dark else 1.0
    score = np.where(np.abs(e) <= search, sign * prof, np.nan)
    if not np.isfinite(score).any():
        return 0.0, 0.0
    k = int(np.nanargmax(score))
    sides = []
    for side in (-1, 1):
        d = side * (e - e[k])
        pick = cols & (d > half + 1) & (d <= half + 7)
        if pick.sum() < 2:
            return float(e[k]), 0.0
        sides.append(float(np.median(prof[pick])))
    contrast = min(sign * (prof[k] - b) for b in sides)
    bg = max(sides) if dark else min(sides)
    near = (np.abs(e - e[k]) <= half) & cols
    wgt = np.clip(sign * (prof - bg), 0, None) * near
    pos = float((wgt * e).sum() / wgt.sum()) if wgt.sum() > 0 else float(e[k])
    return pos, float(contrast)


def _full_res(image: np.ndarray, c: MarkCandidate, noise: float, f: int, top: float,
              n_along: int = 48) -> tuple[MarkCandidate, float]:
    """The candidate re-centred on the full-resolution image, and its contrast / pixel noise.

    The block-averaged search places a mark only to a block or so, and near the frame edge
    the padding pulls its ridge inwards; profiles across the mark (the median over places is
    robust to dust) put it back, each half of its length separately to correct the angle.
    The contrast is what one pixel shows: a line-shaped filter integrates a long faint
    streak into a strong response, a mark stands out pixel by pixel.
    """
    reach = int(np.ceil(c.thickness_px + 8 + 3 * f))
    half = max(1.0, c.thickness_px / 2 + 1)
    vals, e, t = _across(image, c, reach, n_along, top)
    search = half + 1 + 2 * f
    pos, contrast = _peak(vals, e, c.dark, half, search)
    m = n_along // 2
    p1, c1 = _peak(vals[:m], e, c.dark, half, search)
    p2, c2 = _peak(vals[m:], e, c.dark, half, search)
    u, n = line_frame(c.angle_rad)
    if c1 > 0 and c2 > 0 and abs(p1 - pos) < half + 2 and abs(p2 - pos) < half + 2:
        q1 = c.offset_px * n + t[:m].mean() * u + p1 * n
        q2 = c.offset_px * n + t[m:].mean() * u + p2 * n
        v = q2 - q1
        a = wrap_angle(float(np.arctan2(-v[1], v[0])))
        if abs(wrap_angle(a - c.angle_rad)) < np.deg2rad(3):
            u2, n2 = line_frame(a)
            ends = sorted(float((c.offset_px * n + tk * u) @ u2)
                          for tk in (c.t_start_px, c.t_end_px))
            return replace(c, angle_rad=a, offset_px=float(q1 @ n2), t_start_px=ends[0],
                           t_end_px=ends[1]), contrast / max(noise, 1e-12)
    return replace(c, offset_px=c.offset_px + pos), contrast / max(noise, 1e-12)


def distinctness(image: np.ndarray, c: MarkCandidate, top: float, reach: float = 60.0,
                 alpha: float = 1e-3) -> tuple[float, float]:
    """How far a candidate stands out of the background's own relief across it, averaged
    along it, and how far the relief alone could reach by chance: (contrast / spread, limit).

    The median along the candidate's length averages pixel noise and isotropic texture away,
    but not a machining lay running the same way: there the profile beside the candidate is
    as rough as the candidate itself (one of many similar ridges), whereas a mark is one
    deep groove on a background that averages flat. ``spread`` is the robust (MAD) spread of
    that profile beside the candidate (up to ``reach`` px each side), a quadratic trend
    (vignetting, a gradient) removed.

    ``limit``: the relief's largest value in the search at level ``alpha``: the normal
    quantile at alpha / (2 M), M ~ the image diagonal in px (the across positions searched,
    one per px, both polarities), widened by 3 standard errors of the MAD spread (relative
    1.16 / sqrt(n_eff); n_eff from the profile's lag-1 correlation r, n (1 - r) / (1 + r)).
    (inf, 0): too little background beside it to judge; left to the other tests.
    """
    half = max(1.0, c.thickness_px / 2 + 1)
    n_along = int(np.clip(c.length_px, 16, 2000))
    vals, e, _ = _across(image, c, int(np.ceil(reach + half)), n_along, top)
    cols = np.isfinite(vals).sum(axis=0) >= max(5, n_along // 4)
    med = _column_median(vals)  # one median profile for both uses (each column's own)
    prof = np.where(cols, med[0], np.nan)
    bg = cols & (np.abs(e) > 2 * half + 2)
    if bg.sum() < 20:
        return float("inf"), 0.0
    _, contrast = _peak(vals, e, c.dark, half, half + 1, med)
    x, y = e[bg], prof[bg]
    res = y - np.polyval(np.polyfit(x, y, 2), x)
    spread = 1.4826 * float(np.median(np.abs(res - np.median(res))))
    if spread <= 0:
        return float("inf"), 0.0
    adjacent = np.diff(x) == 1
    rc = res - res.mean()
    r1 = float(np.clip((rc[1:] * rc[:-1])[adjacent].mean() / max(np.mean(rc * rc), 1e-300),
                       0.0, 0.95)) if adjacent.any() else 0.0
    n_eff = max(len(res) * (1 - r1) / (1 + r1), 4.0)
    m = 2 * np.hypot(*image.shape)
    limit = float(-special.ndtri(alpha / (2 * m)) * (1 + 3 * 1.16 / np.sqrt(n_eff)))
    return float(contrast / spread), limit


Roi = tuple[int, int, int, int]


def check_roi(values: object, where: str = "roi") -> Roi:
    """A region of interest (x, y, w, h) [px] from 4 numbers, or an ImageInputError naming
    ``where``: x = column and y = row of the top-left corner, w x h at least 16 x 16 px."""
    try:
        parts = [float(v) for v in values]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        parts = []
    if len(parts) != 4 or any(v != int(v) for v in parts) or min(parts[:2]) < 0 or \
            min(parts[2:]) < 16:
        text = ",".join(map(str, values)) if isinstance(values, list | tuple) else values
        raise ImageInputError(f"{where} = {text!r}: expected four whole numbers X,Y,W,H "
                              "(top-left column and row, width and height >= 16 px)")
    x, y, w, h = (int(v) for v in parts)
    return x, y, w, h


def detect_marks(image: np.ndarray, min_length_px: float | None = None,
                 max_marks: int = 8, snr_threshold: float = 8.0,
                 roi: Roi | None = None,
                 min_fill: float = 0.5, min_pixel_snr: float = 2.4,
                 top: float | None = None) -> list[MarkCandidate]:
    """Find long straight dark or bright thin marks.

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN].
    min_length_px : float, optional
        Shortest mark to report [px] (default :data:`MIN_LENGTH_PX`, at most 80 % of the
        smaller image side); lines from LENGTH_SLACK of it are reported.
    max_marks : int
        At most this many candidates, strongest (contrast x length) first.
    snr_threshold : float
        Ridge response threshold in units of the pixel noise carried through the filter.
    roi : (x, y, w, h), optional
        Search only this rectangle [px, x = column, y = row of its top-left corner].
    min_pixel_snr : float
        Least contrast of a mark over the pixel noise, in one full-resolution pixel, against
        the background on either side. Blur and pixel area leave a 2 px groove at SNR 8
        (full-depth contrast / noise) only ~2.5 in its best pixel; machining streaks of a
        third of the noise per pixel, long and straight, reach ~2.2 (the ridge filter
        integrates them along their length into a strong response). The two overlap: use
        ``roi`` on heavily textured surfaces.
    min_fill : float
        Fraction of a candidate's length its ridge pixels must cover: pieces of machining
        streaks that happen to line up are mostly gaps; a mark broken by dust is mostly mark.
        A candidate must also stand out of the background's relief averaged along it
        (:func:`distinctness`): a machining lay's streak is one of many alike.
    top : float, optional
        The image's full-scale DN when the caller already knows it (else from the image).

    Returns
    -------
    list of MarkCandidate (coordinates of the whole image), strongest first; empty when
    nothing qualifies. Every mark that is long and significant enough is reported, whatever
    the others' strength: a short faint mark beside a long strong one is still a mark.
    """
    return detect_lines_once(image, min_length_px, snr_threshold, roi, min_fill, min_pixel_snr,
                             top).marks[:max_marks]


@dataclass(frozen=True)
class Search:
    """One coarse search of an image (or roi), kept so that a second pass for shorter lines
    of a known direction (:mod:`imaging.families`) reuses its ridge masks.

    ``marks``: confirmed candidates in whole-image coordinates, strongest first (deduplicated,
    not capped); the rest is the search's state (block factor ``f``, thresholded ridge masks
    per scale and polarity, the noise and full scale used to confirm).
    """

    marks: list[MarkCandidate]
    image: np.ndarray
    shift: np.ndarray
    f: int
    layers: list[tuple[float, bool, np.ndarray, np.ndarray, float]]
    centre_small: np.ndarray
    noise_full: float
    top: float
    min_fill: float
    min_pixel_snr: float

    def candidates(self, min_length_px: float, keep=None) -> list[MarkCandidate]:
        """Coarse candidates at least ``min_length_px`` long (whole-image coordinates are
        applied by :meth:`confirm`), those ``keep(c)`` accepts, strongest first."""
        return _candidates(self.layers, min_length_px, self.f, self.centre_small,
                           self.image.shape, self.min_fill, keep)

    def confirm(self, cands: list[MarkCandidate], reach: float = 60.0) -> list[MarkCandidate]:
        """Full-resolution checks (pixel SNR, distinctness within ``reach`` px beside each
        candidate), in whole-image coordinates."""
        out = _confirm(self.image, cands, self.noise_full, self.f, self.top,
                       self.min_pixel_snr, reach)
        return [_shift(c, self.shift) for c in out] if self.shift.any() else out


def detect_lines_once(image: np.ndarray, min_length_px: float | None = None,
                      snr_threshold: float = 8.0, roi: Roi | None = None,
                      min_fill: float = 0.5, min_pixel_snr: float = 2.4,
                      top: float | None = None) -> Search:
    """The search of :func:`detect_marks` (same parameters), every confirmed line kept."""
    h_full, w_full = image.shape
    x0 = y0 = 0
    if roi is not None:
        x0, y0, rw, rh = check_roi(roi)
        if x0 + rw > w_full or y0 + rh > h_full:
            raise ImageInputError(f"roi {x0},{y0},{rw},{rh}: reaches outside the "
                                  f"{w_full}x{h_full} image")
        image = image[y0:y0 + rh, x0:x0 + rw]
    h, w = image.shape
    if min_length_px is None:
        min_length_px = default_min_length((h, w))
    # The search only seeds the sub-pixel fit, so it runs on a block-averaged copy; the
    # shortest mark must stay >= ~25 blocks long there, or short marks in large frames drown.
    # Frames under 1000 px are averaged 2 x 2 from 640 px on (a 640 x 480 frame searched
    # at full resolution cost more than a 5 MP one at f = 5).
    side = max(h, w)
    f = max(1, min(int(side // 500 if side >= 1000 else side // 320), int(min_length_px // 25)))
    hs, ws = h // f, w // f
    small = image[:hs * f, :ws * f].astype(np.float32)
    if f > 1:
        # INTER_AREA with an integer factor on an exactly divisible crop is the f x f block
        # mean (OpenCV's is ~10x faster than numpy's reshape-mean here).
        small = cv2.resize(small, (ws, hs), interpolation=cv2.INTER_AREA)
    centre_small = np.array([(ws - 1) / 2, (hs - 1) / 2])
    noise = pixel_noise(small)
    layers = []
    for sigma in (1.5, 3.0):
        pad = int(np.ceil(4 * sigma)) + 2
        r, flat = _ridge(_odd_pad(small, pad), sigma)
        r, flat = r[pad:pad + hs, pad:pad + ws], flat[pad:pad + hs, pad:pad + ws]
        # Threshold against the pixel noise carried through the filter, not the spread of
        # the response (which clutter dominates in a busy scene); the MAD is the fallback
        # and a floor relative to the strongest response keeps noise-free images workable.
        sub = r[::3, ::3]  # the spread needs no more than a ninth of the pixels
        mad = min(float(np.median(np.abs(sub - np.median(sub)))) * 1.4826,
                  noise * _ridge_gain(sigma))
        mad = max(mad, 1e-3 * float(np.abs(r).max()))
        if mad <= 0:
            continue
        for dark in (True, False):
            resp = r if dark else -r
            layers.append((sigma, dark, resp, (resp > snr_threshold * mad) & flat, mad))
    noise_full = pixel_noise(_central(image, 1024))
    top = full_scale(image) if top is None else top
    shift = np.zeros(2)
    if roi is not None:
        shift = np.array([x0 + (w - 1) / 2 - (w_full - 1) / 2, y0 + (h - 1) / 2 - (h_full - 1) / 2])
    search = Search([], image, shift, f, layers, centre_small, noise_full, top, min_fill,
                    min_pixel_snr)
    return replace(search, marks=search.confirm(search.candidates(min_length_px)))


def _candidates(layers, min_length_px: float, f: int, centre_small: np.ndarray,
                shape: tuple[int, int], min_fill: float, keep=None) -> list[MarkCandidate]:
    """Long thin components of the ridge masks, as coarse candidates, strongest first."""
    h, w = shape
    best: list[MarkCandidate] = []
    for sigma, dark, resp, mask, mad in layers:
        # Pieces down to an eighth of the shortest mark: a wide or dusty mark breaks up.
        piece = max(3.0, min_length_px / f / 8)
        for pts in _merge(_split_crossings(_components(mask, piece), piece), centre_small,
                          resp):
            a, d, t, thick = _pca_line(pts, centre_small)
            length = (t.max() - t.min()) * f
            # The response fades below the threshold about a filter width before each
            # end of a faint, blurred mark: judge the length with that back, and with
            # LENGTH_SLACK (a 100 px mark at SNR 8 keeps ~85 px of ridge).
            if (length + 2 * sigma * f < LENGTH_SLACK * min_length_px
                    or thick * f > 0.25 * length):
                continue
            fill = np.unique(np.floor(t)).size / (np.floor(t.max()) - np.floor(t.min()) + 1)
            if fill < min_fill:
                continue
            contrast = float(resp[pts[:, 1].astype(int), pts[:, 0].astype(int)].mean() / mad)
            c = _to_full(a, d, t, dark, thick, contrast * length, f, centre_small,
                         np.array([(w - 1) / 2, (h - 1) / 2]), contrast)
            if keep is None or keep(c):
                best.append(c)
    return _dedupe(_drop_fused(sorted(best, key=lambda c: -c.strength)))


def _confirm(image: np.ndarray, cands: list[MarkCandidate], noise_full: float, f: int,
             top: float, min_pixel_snr: float, reach: float = 60.0) -> list[MarkCandidate]:
    """Candidates re-centred on the full-resolution image that stand out pixel by pixel and
    from the background's relief."""
    out = []
    for c in cands:
        # Two marks fused along their bisector: seen so on the coarse line (re-centring
        # would pull it onto one of the two grooves, and the other would go unsaid).
        coarse, fused = c, _fused(image, c, noise_full, top)
        # Twice: a coarse angle smears the profile along a short mark (and hides its contrast).
        c, _ = _full_res(image, c, noise_full, f, top)
        c, snr = _full_res(image, c, noise_full, f, top)
        if snr < min_pixel_snr:
            continue
        # A machining lay running along the candidate: each streak is long, and the ridge
        # filter integrates it into a strong response, but beside it lie many like it.
        ratio, limit = distinctness(image, c, top, reach)
        if ratio < limit:
            continue
        # (once re-centred, a line lies on a groove: two grooves no longer straddle it)
        out.append(c if fused is None else replace(coarse, fused=fused))
    return _drop_fused(_dedupe(out))


def _fused(image: np.ndarray, c: MarkCandidate, noise: float, top: float,
           block_px: int = 20) -> tuple[float, float] | None:
    """Where a candidate is seen as two grooves straddling it (see MarkCandidate.fused):
    median profiles across it over ``block_px`` stretches, each tested for two grooves."""
    half = max(2.5, c.thickness_px)
    n_along = max(int(c.length_px), 2 * block_px)
    vals, e, t = _across(image, c, int(np.ceil(c.thickness_px + 18)), n_along, top)
    sigma = 1.25 * noise / np.sqrt(block_px)
    profs, ts = block_medians(vals, t, block_px)
    return fused_crossing([(tk, double_groove(p, e, c.dark, sigma, half))
                           for tk, p in zip(ts, profs, strict=True)], half)


def block_medians(vals: np.ndarray, t: np.ndarray, block_px: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Median profiles over consecutive blocks of ``block_px`` rows of :func:`_across`
    values (NaN where a column has no value), and each block's mean position t [px]."""
    nb = len(t) // block_px
    v = vals[:nb * block_px].reshape(nb, block_px, -1)
    if np.isfinite(v).all():  # np.median: the same values, several times faster
        profs = np.median(v, axis=1)
    else:
        with warnings.catch_warnings():  # an all-NaN column is NaN, as it should be
            warnings.simplefilter("ignore", RuntimeWarning)
            profs = np.nanmedian(v, axis=1)
    return profs, t[:nb * block_px].reshape(nb, block_px).mean(axis=1)


def _drop_fused(cands: list[MarkCandidate]) -> list[MarkCandidate]:
    """Fused ridges of two crossing marks that were themselves found: not a mark.

    Where two marks cross at a shallow angle their grooves fuse into one ridge along the
    bisector: a third line, between the two in direction, that lies within a groove's reach
    of both over its whole length (a mark there could not be measured apart from them)."""
    out = []
    for c in cands:
        if not any(_fused_of(c, o1, o2) for i, o1 in enumerate(cands) for o2 in cands[i + 1:]
                   if o1 is not c and o2 is not c):
            out.append(c)
    return out


def _fused_of(c: MarkCandidate, o1: MarkCandidate, o2: MarkCandidate) -> bool:
    """Whether c is the fused ridge of o1 and o2 (see :func:`_drop_fused`)."""
    if not (c.dark == o1.dark == o2.dark) or o1.fused is not None or o2.fused is not None:
        return False
    d1, d2 = wrap_angle(c.angle_rad - o1.angle_rad), wrap_angle(o2.angle_rad - c.angle_rad)
    if d1 * d2 <= 0:  # c's direction not between theirs
        return False
    whole = (c.t_start_px, c.t_end_px)
    return all(_covers(c, o, max(6.0, 2 * o.thickness_px), whole) for o in (o1, o2))


def _covers(c: MarkCandidate, o: MarkCandidate, half_px: float,
            whole: tuple[float, float]) -> bool:
    """Whether line o lies within half_px of c over c's whole extent (o's ridge may stop
    where the fused one begins: its groove counts on through the fused stretch)."""
    got = crossing_stretch(c, o, half_px, extend=True)
    return got is not None and got[0] <= whole[0] + half_px and got[1] >= whole[1] - half_px


def _central(image: np.ndarray, size: int) -> np.ndarray:
    """The central size x size part of an image (all of it if smaller)."""
    h, w = image.shape
    y0, x0 = max(0, (h - size) // 2), max(0, (w - size) // 2)
    return image[y0:y0 + size, x0:x0 + size]


def _shift(c: MarkCandidate, s: np.ndarray) -> MarkCandidate:
    """The candidate in a frame whose centre lies at -s from the current one [px]."""
    u, n = line_frame(c.angle_rad)
    return replace(c, offset_px=float(c.offset_px + s @ n), t_start_px=float(c.t_start_px + s @ u),
                   t_end_px=float(c.t_end_px + s @ u))


def _to_full(a, d, t, dark, thick, strength, f, centre_small, centre, contrast
             ) -> MarkCandidate:
    # A downsampled pixel k covers full-res pixels k*f .. k*f+f-1: centre at k*f + (f-1)/2.
    uu, nn = line_frame(a)
    p_small = centre_small + d * nn
    p_full = p_small * f + (f - 1) / 2 - centre
    shift = p_full @ uu
    return MarkCandidate(a, float(p_full @ nn), float(t.min() * f + shift),
                         float(t.max() * f + shift), dark, float(thick * f), strength, contrast)


def _split_crossings(comps: list[np.ndarray], piece: float) -> list[np.ndarray]:
    """Components that are two lines crossing at a shallow angle, as the two lines' points
    (their fused ridge would otherwise be one phantom mark between them)."""
    out = []
    for c in comps:
        two = split_two_lines(c, piece) if np.ptp(c, axis=0).max() >= 4 * piece else None
        out.extend(two if two is not None else [c])
    return out


def _bridged(resp: np.ndarray, p0: np.ndarray, p1: np.ndarray, level: float,
             side: float = 2.0) -> bool:
    """Whether the ridge response stays above ``level`` (within ``side`` px across) at 80 %
    of the 1 px steps from p0 to p1 (small-image pixels): a groove runs on through the gap.

    Where another mark crosses at a shallow angle the two grooves fuse into one ridge along
    their bisector, so each mark's own ridge stops and resumes beyond the crossing; the
    fused ridge lies within a pixel or two of both, and the gap is bridged. Between two
    marks of a row the gap is background."""
    h, w = resp.shape
    v = p1 - p0
    n_steps = max(int(np.hypot(*v)), 1)
    nrm = np.array([-v[1], v[0]]) / max(float(np.hypot(*v)), 1e-9)
    s = np.linspace(0.0, 1.0, n_steps + 1)[:, None]
    e = np.arange(-side, side + 1)
    q = p0 + s[:, :, None].transpose(0, 2, 1) * v + e[None, :, None] * nrm  # (steps, e, 2)
    xi = np.clip(np.rint(q[..., 0]).astype(int), 0, w - 1)
    yi = np.clip(np.rint(q[..., 1]).astype(int), 0, h - 1)
    return float(np.mean(resp[yi, xi].max(axis=1) >= level)) >= 0.8


def _merge(comps: list[np.ndarray], centre: np.ndarray, resp: np.ndarray | None = None
           ) -> list[np.ndarray]:
    """Join collinear pieces (a mark interrupted by dust or a dropout, or by the fused ridge
    where another mark crosses it: ``resp``, the ridge response, tells the gap is bridged)."""
    lines = [(_pca_line(c, centre), c) for c in comps if len(c) >= 5]
    lines.sort(key=lambda x: -len(x[1]))
    used = [False] * len(lines)
    out = []
    for i, ((a, d, _, _), pts) in enumerate(lines):
        if used[i]:
            continue
        group = [pts]
        uu, nn = line_frame(a)
        for j in range(i + 1, len(lines)):
            if used[j]:
                continue
            aj, _, _, _ = lines[j][0]
            dang = abs(wrap_angle(aj - a))
            dist = np.abs((lines[j][1] - centre) @ nn - d)  # this piece's points, own normal
            # Dust or a dropout leaves a gap shorter than the mark's pieces; a collinear
            # stroke far along the line (a logo, the next mark of a row) is another thing.
            tg = np.vstack(group) @ uu
            tj = lines[j][1] @ uu
            gap = max(tj.min() - tg.max(), tg.min() - tj.max())
            if not (dang < np.deg2rad(3) and np.max(dist) < 3.0):
                continue
            if gap <= max(np.ptp(tg), np.ptp(tj)) or (resp is not None and _bridged(
                    resp, *_gap_ends(np.vstack(group), lines[j][1], uu),
                    0.5 * _level(resp, np.vstack(group)))):
                group.append(lines[j][1])
                used[j] = True
        out.append(np.vstack(group))
    return out


def _gap_ends(a: np.ndarray, b: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The facing end points of two point sets along direction u (the gap between them)."""
    ta, tb = a @ u, b @ u
    if ta.max() < tb.min():
        return a[np.argmax(ta)], b[np.argmin(tb)]
    return b[np.argmax(tb)], a[np.argmin(ta)]


def _level(resp: np.ndarray, pts: np.ndarray) -> float:
    """Median ridge response over a piece's points."""
    return float(np.median(resp[pts[:, 1].astype(int), pts[:, 0].astype(int)]))


def _dedupe(cands: list[MarkCandidate]) -> list[MarkCandidate]:
    """The same mark found at two scales or twice: keep the strongest.

    Only of one polarity: a dark mark and the bright strip of background beside it (between
    it and a padded border, say) are two things, and the strip must not replace the mark.
    """
    out: list[MarkCandidate] = []
    for c in cands:
        if any(c.dark == o.dark and _near(c, o, np.deg2rad(3), max(6.0, o.thickness_px))
               and _overlap(c, o) for o in out):
            continue
        out.append(c)
    return out


def _near(c: MarkCandidate, o: MarkCandidate, tol_angle: float, tol_px: float) -> bool:
    """Whether c lies along o: directions within tol_angle, c's middle within tol_px of o's
    line. (Comparing offsets instead would multiply a small angle difference by the lever
    arm from the image centre.)"""
    if abs(wrap_angle(c.angle_rad - o.angle_rad)) >= tol_angle:
        return False
    u, n = line_frame(c.angle_rad)
    mid = c.offset_px * n + 0.5 * (c.t_start_px + c.t_end_px) * u
    return abs(float(mid @ line_frame(o.angle_rad)[1]) - o.offset_px) < tol_px


def _overlap(c: MarkCandidate, o: MarkCandidate) -> bool:
    """Whether two nearly coincident candidates share part of their length."""
    if abs(c.angle_rad - o.angle_rad) > np.pi / 2:  # directions opposite: t runs backwards
        return -c.t_end_px < o.t_end_px and o.t_start_px < -c.t_start_px
    return c.t_start_px < o.t_end_px and o.t_start_px < c.t_end_px


def require_single(cands: list[MarkCandidate], where: str) -> MarkCandidate:
    """The one mark an image is expected to hold, or a clear error."""
    if not cands:
        raise ImageInputError(f"{where}: no mark found (no long straight line stands out)")
    if len(cands) > 1 and cands[1].strength > 0.5 * cands[0].strength:
        raise ImageInputError(
            f"{where}: two competing marks (strengths {cands[0].strength:.0f} and "
            f"{cands[1].strength:.0f}) where one was expected")
    return cands[0]
