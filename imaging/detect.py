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
from dataclasses import dataclass

import cv2
import numpy as np

from imaging.errors import ImageInputError


@dataclass(frozen=True)
class MarkCandidate:
    """A coarse mark: line (angle [rad], offset [px]), extent along it [px], polarity,
    strength (contrast x length) and mean ridge contrast (in units of the response noise)."""

    angle_rad: float
    offset_px: float
    t_start_px: float
    t_end_px: float
    dark: bool
    thickness_px: float
    strength: float
    contrast: float = float("inf")

    @property
    def length_px(self) -> float:
        return self.t_end_px - self.t_start_px


def line_frame(angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction u and normal n of a line at ``angle_rad`` in (x right, y down) pixels."""
    return (np.array([np.cos(angle_rad), -np.sin(angle_rad)]),
            np.array([np.sin(angle_rad), np.cos(angle_rad)]))


def wrap_angle(angle_rad: float) -> float:
    """Wrap a line direction to (-pi/2, pi/2]."""
    a = (angle_rad + np.pi / 2) % np.pi - np.pi / 2
    return float(np.pi / 2 if np.isclose(a, -np.pi / 2, atol=0) else a)


def same_line(a1: float, d1: float, a2: float, d2: float, tol_angle: float,
              tol_offset: float) -> bool:
    """Whether two lines (angle [rad], offset [px]) coincide within tolerances.

    Across the +-90 deg wrap the normal flips, and with it the sign of the offset.
    """
    if abs(wrap_angle(a1 - a2)) >= tol_angle:
        return False
    flipped = abs(a1 - a2) > np.pi / 2
    return abs(d1 - (-d2 if flipped else d2)) < tol_offset


def _ridge(img: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Largest Hessian eigenvalue (scale-normalised): > 0 on dark lines, < 0 on bright ones.

    Also returns where the gradient is not steep compared with the curvature: the flanks of a line
    (and edges) curve too, but only the line's centre is flat (Steger's condition).
    """
    g = cv2.GaussianBlur(img, (0, 0), sigma)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8
    dxx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3) / 4
    dyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3) / 4
    dxy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3) / 16
    tr = (dxx + dyy) / 2
    disc = np.sqrt(((dxx - dyy) / 2) ** 2 + dxy**2)
    lam1, lam2 = tr + disc, tr - disc
    # Keep the eigenvalue of larger magnitude, with its sign.
    lam = np.where(np.abs(lam1) >= np.abs(lam2), lam1, lam2)
    flat = np.hypot(gx, gy) < 0.5 * sigma * np.abs(lam)
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


def detect_marks(image: np.ndarray, min_length_px: float | None = None,
                 max_marks: int = 8, snr_threshold: float = 8.0,
                 relative_strength: float = 0.25) -> list[MarkCandidate]:
    """Find long straight dark or bright thin marks.

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN].
    min_length_px : float, optional
        Shortest mark to report [px]; default 20 % of the smaller image side.
    max_marks : int
        At most this many candidates, strongest first.
    snr_threshold : float
        Ridge response threshold in units of its robust (MAD) noise.
    relative_strength : float
        Drop candidates weaker (contrast x length) than this fraction of the strongest:
        scratches and machining marks are fainter and shorter than engraved scribe marks.

    Returns
    -------
    list of MarkCandidate, strongest first (empty when nothing qualifies).
    """
    h, w = image.shape
    if min_length_px is None:
        min_length_px = 0.2 * min(h, w)
    # The search only seeds the sub-pixel fit: ~500 px across is plenty.
    f = max(1, int(max(h, w) // 500))
    small = cv2.resize(image.astype(np.float32), (w // f, h // f), interpolation=cv2.INTER_AREA)
    centre_small = np.array([(small.shape[1] - 1) / 2, (small.shape[0] - 1) / 2])
    noise = pixel_noise(small)
    best: list[MarkCandidate] = []
    for sigma in (1.5, 3.0):
        r, flat = _ridge(small, sigma)
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
            mask = (resp > snr_threshold * mad) & flat
            for pts in _merge(_components(mask, min_length_px / f / 4), centre_small):
                a, d, t, thick = _pca_line(pts, centre_small)
                length = (t.max() - t.min()) * f
                if length < min_length_px or thick * f > 0.25 * length:
                    continue
                contrast = float(resp[pts[:, 1].astype(int), pts[:, 0].astype(int)].mean()
                                 / mad)
                best.append(_to_full(a, d, t, dark, thick, contrast * length, f,
                                     centre_small, np.array([(w - 1) / 2, (h - 1) / 2]),
                                     contrast))
    out = _dedupe(sorted(best, key=lambda c: -c.strength))
    if not out:
        return []
    # Both the contrast x length and the contrast alone: machining streaks merged into long
    # lines can be long, but their contrast is a small fraction of an engraved mark's.
    top_c = max(c.contrast for c in out)
    return [c for c in out if c.strength >= relative_strength * out[0].strength
            and c.contrast >= relative_strength * top_c][:max_marks]


def _to_full(a, d, t, dark, thick, strength, f, centre_small, centre, contrast
             ) -> MarkCandidate:
    # A downsampled pixel k covers full-res pixels k*f .. k*f+f-1: centre at k*f + (f-1)/2.
    uu, nn = line_frame(a)
    p_small = centre_small + d * nn
    p_full = p_small * f + (f - 1) / 2 - centre
    shift = p_full @ uu
    return MarkCandidate(a, float(p_full @ nn), float(t.min() * f + shift),
                         float(t.max() * f + shift), dark, float(thick * f), strength, contrast)


def _merge(comps: list[np.ndarray], centre: np.ndarray) -> list[np.ndarray]:
    """Join collinear pieces (a mark interrupted by dust or a dropout)."""
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
            if dang < np.deg2rad(3) and np.max(dist) < 3.0:
                group.append(lines[j][1])
                used[j] = True
        out.append(np.vstack(group))
    return out


def _dedupe(cands: list[MarkCandidate]) -> list[MarkCandidate]:
    """The same mark found at two scales or twice: keep the strongest."""
    out: list[MarkCandidate] = []
    for c in cands:
        if any(same_line(c.angle_rad, c.offset_px, o.angle_rad, o.offset_px, np.deg2rad(3),
                         max(6.0, o.thickness_px)) and _overlap(c, o) for o in out):
            continue
        out.append(c)
    return out


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
