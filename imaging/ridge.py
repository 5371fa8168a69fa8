"""The ridge filter of the coarse search and the noise it is judged against.

A Hessian ridge filter (largest eigenvalue, scale-normalised, both polarities) with Steger's
flatness condition, the white-noise sigma of an image (Immerkaer), and the filter's gain on
unit white noise; the image is padded by point reflection so that the frame's edge is no line.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from imaging.median import median_inplace

# Steger's condition: the extremum across the line, |grad| / |lambda| px from the pixel centre,
# lies within FLAT px of it (a little over half a pixel, so that a thin line running between
# two rows of the block-averaged image still marks one of them). Beside a strong step edge (a
# padded or saturated band) the profile also curves, at |grad| / |lambda| = sigma^2 / d from
# the step: those false ridges are told apart later by the two-sided contrast (imaging.confirm).
FLAT = 0.6


def ridge_response(img: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
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
    # In place where a temporary would do: ~30 % of this function's time was allocation.
    tr = dxx + dyy
    tr *= 0.5
    dxx -= dyy
    dxx *= 0.5
    disc = cv2.magnitude(dxx, dxy)
    # The eigenvalue of larger magnitude is tr + sign(tr) disc (disc >= 0), and its magnitude
    # |tr| + disc; Steger's test on squares (no square root of the gradient). The sign is
    # taken from tr + 0.0, which is +0.0 for a trace of -0.0 (counted as >= 0).
    lam = tr + 0.0
    np.copysign(disc, lam, out=lam)
    lam += tr
    gx *= gx
    gy *= gy
    gx += gy
    lam2 = lam * lam
    lam2 *= FLAT * FLAT
    flat = gx < lam2
    lam *= sigma**2
    return lam, flat


def pixel_noise(img: np.ndarray) -> float:
    """Immerkær's fast estimate of white-noise sigma (insensitive to smooth structure) [DN]."""
    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    conv = cv2.filter2D(img.astype(np.float32, copy=False), -1, k,
                        borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
    # The mean |conv| as OpenCV's L1 norm (one pass, summed in float64) over the strided
    # interior: numpy's abs and float32 mean of it took ~1 ms more on a 5 MP frame's 1 MP centre.
    return float(np.sqrt(np.pi / 2) * cv2.norm(conv, cv2.NORM_L1) / conv.size / 6)


def median_abs_deviation(a: np.ndarray) -> float:
    """``float(np.median(np.abs(a - np.median(a))))`` (unscaled MAD), the same number in
    ~0.6x the time (one copy of ``a``, two selections; the coarse search's threshold takes
    it twice per scale of a 5 MP frame's ridge response)."""
    d = a.flatten()
    m = median_inplace(d.copy())
    np.subtract(d, m, out=d)
    np.abs(d, out=d)
    return float(median_inplace(d))


@functools.cache
def ridge_gain(sigma: float) -> float:
    """Standard deviation of the ridge response to unit white noise (seeded, computed once)."""
    noise = np.random.default_rng(0).standard_normal((256, 256)).astype(np.float32)
    r, _ = ridge_response(noise, sigma)
    return float(np.std(r[16:-16, 16:-16]))


def odd_pad(img: np.ndarray, pad: int) -> np.ndarray:
    """Pad by point reflection about the edge pixels (2 v0 - v_k).

    The filters then see a ramp (vignetting, border darkening) continue straight through the
    frame edge, and a dark or saturated band touching the edge as a step: neither is a ridge.
    Even reflection (OpenCV's default) folds a ramp into a V at the edge, i.e. a line.
    """
    pad = int(min(pad, min(img.shape) - 1))
    return np.pad(img, pad, mode="reflect", reflect_type="odd")


def central(image: np.ndarray, size: int) -> np.ndarray:
    """The central size x size part of an image (all of it if smaller)."""
    h, w = image.shape
    y0, x0 = max(0, (h - size) // 2), max(0, (w - size) // 2)
    return image[y0:y0 + size, x0:x0 + size]
