"""A mark's band (:mod:`imaging.band`): rasterised along the line, it holds exactly the
pixels a brute-force test of every pixel of the frame selects, with their distances."""

from __future__ import annotations

import numpy as np

from imaging.band import _band
from imaging.candidate import line_frame


def _brute(image: np.ndarray, angle: float, offset: float, t0: float, t1: float,
           half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pixel of the frame tested: flat indices (sorted), e and t of those pixels."""
    h, w = image.shape
    u, n = line_frame(angle)
    ys, xs = np.mgrid[:h, :w]
    px, py = xs - (w - 1) / 2, ys - (h - 1) / 2
    e = px * n[0] + py * n[1] - offset
    t = px * u[0] + py * u[1]
    sel = (np.abs(e) <= half) & (t >= t0) & (t <= t1)
    return np.flatnonzero(sel), e[sel], t[sel]


def test_the_band_is_every_pixel_within_its_reach_and_no_other():
    """Lines at any angle (steep and shallow, through the frame's edges and corners): the
    band's pixels are those the brute-force test selects, once each, with the same e and t
    to rounding, and values read from the image at their flat indices."""
    rng = np.random.default_rng(0)
    image = rng.normal(size=(150, 200))
    for _ in range(50):
        angle = rng.uniform(-np.pi / 2, np.pi / 2)
        offset = rng.uniform(-90, 90)
        t0 = rng.uniform(-130, 20)
        t1 = t0 + rng.uniform(0, 200)
        half = rng.uniform(0.5, 25)
        vals, e, t, idx = _band(image, angle, offset, t0, t1, half)
        want, we, wt = _brute(image, angle, offset, t0, t1, half)
        order = np.argsort(idx)
        # (a pixel exactly on the band's edge may fall either side by rounding)
        edge = (np.abs(np.abs(we) - half) < 1e-9) | (np.abs(wt - t0) < 1e-9) \
            | (np.abs(wt - t1) < 1e-9)
        assert np.unique(idx).size == idx.size
        assert set(want[~edge]) <= set(idx) <= set(want)
        keep = np.isin(want, idx)
        np.testing.assert_allclose(e[order], we[keep], atol=1e-9)
        np.testing.assert_allclose(t[order], wt[keep], atol=1e-9)
        np.testing.assert_array_equal(vals, image.ravel()[idx])


def test_a_transposed_view_is_read_at_the_same_pixels():
    """A non-contiguous image (a transposed view) gives the same pixels and values as its
    contiguous copy."""
    image = np.random.default_rng(5).normal(size=(120, 90)).T
    for angle in (0.1, 1.2, -0.7):
        a = _band(image, angle, 10.0, -60.0, 50.0, 7.5)
        b = _band(np.ascontiguousarray(image), angle, 10.0, -60.0, 50.0, 7.5)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
