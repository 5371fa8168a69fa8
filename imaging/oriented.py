"""Oriented periodic background: stripes at any angle, found and removed.

A turned or ground surface, a woven or knurled one, interference fringes: the background
carries a periodic pattern of a few to ~100 px whose lay can run at any angle to a mark.
Row/column patterns are :mod:`imaging.stripes`' job; this module finds the rest. Such a
pattern is not random texture: it is correlated along a mark over its whole length (the
stripes cross the mark at the same phase for hundreds of px when they run nearly parallel to
it), so every centre moves alike and the texture replicas (:mod:`imaging.texture`, whose
correlation is tapered at a span much shorter than the mark) do not carry it. It is found
and divided out instead; what the removal leaves is carried in u.

The test (hand-written: no library tests an image for a periodic pattern under a mask).
The background (marks masked, clipped pixels out) relative to its quadratic shading, under
a Hann window, is Fourier transformed. A plane wave is a peak; a random texture, a smooth
spectrum — but a texture *lay* (a 1-D random profile, :mod:`synth.marks` ``texture``) is a
whole ray of high power through the origin. So a bin's power is compared with the mean
power along its own ray, 0.2-0.5 of its radius (>= 3 bins) either side (the largest bin
within 2 across the ray at each radius: a lay's ray is high there too; a plane wave's is
not), and with the mean of its 2-D neighbourhood; under no pattern each ratio is at most
~Exp(1), and the test is the smaller of the two above ln(bins searched / :data:`ALPHA`)
times :data:`MARGIN` (the neighbourhood means are estimates themselves).

Removal: the wave's frequency is refined by least squares on the background pixels
(variable projection: cos/sin amplitudes linear), the image is divided by
1 + a cos + b sin (the pattern modulates the surface's reflectance, the groove's too), and
the test runs again on the result (a second pattern, a harmonic) up to :data:`MAX_WAVES`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import fft, linalg, optimize

from imaging.compressed import compressed

ALPHA = 1e-3
"""Level of the test for a periodic background (one false flag per 1000 clean images)."""
MARGIN = 1.5
"""Factor on the threshold ln(M / ALPHA): the neighbourhood means (~20-200 bins each) are
estimates, and Hann-windowed bins are correlated with their neighbours."""
PERIOD_PX = (3.0, 100.0)
"""Periods searched [px]: finer is pixel noise, coarser is shading (with 128 px, a clean frame
with a gradient, vignetting and a label flagged a 126 px "period": 1 of 400)."""
MIN_BINS = 5
"""Fewest periods across the tested square for a pattern to be searched (a 480 px frame
sees periods up to 96 px)."""
MAX_SIDE = 1024
"""Side of the square (about the image centre) the test transforms: keeps 5 MP cheap."""
MAX_WAVES = 3
"""Patterns removed at most (a pattern and its harmonics)."""
FIT_PIXELS = 40_000
"""Background pixels (evenly spaced) behind the frequency fit."""
MIN_BACKGROUND = 0.3
"""Smallest fraction of the tested square that must be usable background."""


@dataclass(frozen=True)
class Wave:
    """One plane wave in the background: relative amplitude ``amplitude`` (of the local level)
    with standard uncertainty ``amplitude_u``, ``period_px`` [px], ``angle_rad`` the
    stripes' direction (along the crests, the marks' angle convention: x right, y up,
    (-pi/2, pi/2]), wave vector ``k`` [rad/px] (x, y image), cos/sin amplitudes ``ab``, and
    ``ratio`` (peak power over the spectrum about it).

    Attributes
    ----------
    amplitude, amplitude_u : float
        Relative amplitude and its u — dimensionless.
    period_px : float
        Period [px].
    angle_rad : float
        Direction of the crests [rad].
    k : tuple of float
        Wave vector (x, y) [rad/px].
    ab : tuple of float
        Cosine and sine amplitudes (relative).
    ratio : float
        Peak power over the spectrum about it — dimensionless.
    """

    amplitude: float
    amplitude_u: float
    period_px: float
    angle_rad: float
    k: tuple[float, float]
    ab: tuple[float, float]
    ratio: float

    def pattern(self, shape: tuple[int, int]) -> np.ndarray:
        """a cos(k.r) + b sin(k.r) over an image of ``shape`` (relative).

        By the angle-addition formulas, cos(ky y) (a cos kx x + b sin kx x) + sin(ky y)
        (b cos kx x - a sin kx x): cos and sin of one row and one column instead of the
        frame's every pixel (~4x less CPU; equal to ~1e-15)."""
        y, x = np.ogrid[:shape[0], :shape[1]]
        a, b = self.ab
        cx, sx = np.cos(self.k[0] * x), np.sin(self.k[0] * x)
        return np.cos(self.k[1] * y) * (a * cx + b * sx) + np.sin(self.k[1] * y) * (b * cx - a * sx)


@dataclass(frozen=True)
class OrientedStripes:
    """What the test found: the waves removed (empty: none), the largest ratio seen with the
    threshold it was held against, and ``residual``: the relative amplitude of each wave left
    after the removal (fitted again at its frequency, plus 2 of its u) over its amplitude —
    the fraction of the pattern's effect on an angle that the removal may leave.

    Attributes
    ----------
    waves : tuple of Wave
        The waves removed.
    ratio : float
        The largest peak ratio seen — dimensionless.
    threshold : float
        The ratio it was held against.
    residual : float
        Fraction of the pattern's effect the removal may leave — dimensionless.
    reason : str
        Why nothing was removed, when so.
    """

    waves: tuple[Wave, ...]
    ratio: float
    threshold: float
    residual: float = 0.0
    reason: str = ""

    @property
    def found(self) -> bool:
        return bool(self.waves)

    def factor(self, shape: tuple[int, int]) -> np.ndarray:
        """The reflectance factor the waves make over an image of ``shape`` (what was
        divided out)."""
        total = np.ones(shape)
        for w in self.waves:
            total *= 1.0 + w.pattern(shape)
        return total

    def then(self, other: OrientedStripes) -> OrientedStripes:
        """This removal followed by ``other`` (found on the image this one left)."""
        if not other.found:
            return self
        return OrientedStripes(self.waves + other.waves, self.ratio, self.threshold,
                               max(self.residual, other.residual))


def square_slices(shape: tuple[int, int]) -> tuple[slice, slice]:
    """The central square of a frame of ``shape`` that the test reads (at most
    :data:`MAX_SIDE` px a side): (rows, columns)."""
    h, w = shape
    sy, sx = min(h, MAX_SIDE), min(w, MAX_SIDE)
    y0, x0 = (h - sy) // 2, (w - sx) // 2
    return slice(y0, y0 + sy), slice(x0, x0 + sx)


_REL_ROWS = 64
"""Rows per block of :func:`_relative`'s passes (64 x a 5 MP frame's 2592 float32: 0.66 MB)."""


def _relative(image: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The image over its quadratic shading minus 1 (0 where not valid), as float32 (a
    relative level of ~1e-2 keeps ~1e-9 of it; the test's spectrum is float32 too)."""
    h, w = image.shape
    # Every step-th valid pixel, from one flat index (the same pixels as nonzero's pairs).
    flat = np.flatnonzero(valid)
    step = max(1, flat.size // 20000)
    flat = flat[::step]
    yy, xx = np.divmod(flat, w)
    x, y = xx / w - 0.5, yy / h - 0.5
    A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    z = image[yy, xx].astype(float)
    # By the 6x6 normal equations with one step of refinement, not lstsq's SVD of the
    # 20000 x 6 matrix (0.3 ms, not 0.85, on one core; ~4 ms less where BLAS has threads):
    # the terms over [-1/2, 1/2] are well conditioned (cond(A) ~ 20), and the step takes the
    # normal equations' rounding (~1e-13 of c) down to lstsq's; c is used as float32 below
    # (the fingerprints' 26 frames: bit-identical).
    G = A.T @ A
    c = np.linalg.solve(G, A.T @ z)
    c += np.linalg.solve(G, A.T @ (z - A @ c))
    X = (np.arange(w)[None, :] / w - 0.5).astype(np.float32)
    Y = (np.arange(h)[:, None] / h - 0.5).astype(np.float32)
    # c0 + c1 X + c3 X^2 + c2 Y + c5 Y^2 + c4 X Y: the terms in one variable on a row and a
    # column, then the frame's passes (each full-frame pass of 5 MP costs its page faults).
    # The coefficients as float32: a float64 scalar times a float32 array is float64 (NumPy
    # 2), and the frame-wide level and ratio were float64, twice the bytes for nothing.
    c = c.astype(np.float32)
    row, col, cy = (c[0] + c[1] * X) + c[3] * X * X, c[2] * Y + c[5] * Y * Y, c[4] * Y
    # Block by block of rows, each step elementwise (the same values as over the whole
    # frame): a block's level stays in cache from its sum to its ratio, and the X Y term's
    # product goes through one small buffer, not a fresh 5 MP temporary and its page faults
    # (~0.6x the time of the whole-frame passes at 5 MP).
    rel = np.empty((h, w), np.float32)
    buf = np.empty((min(h, _REL_ROWS), w), np.float32)
    for r in range(0, h, _REL_ROWS):
        rows = slice(r, r + _REL_ROWS)
        lev, xy = rel[rows], buf[:min(_REL_ROWS, h - r)]
        np.add(row, col[rows], out=lev)
        lev += np.multiply(cy[rows], X, out=xy)
        if not lev.min() > 0:  # (a shading that reaches 0 or NaN here; else no mask pass)
            np.copyto(lev, 1.0, where=~(lev > 0))
        np.divide(image[rows], lev, out=lev)
        lev -= 1.0
        np.copyto(lev, 0.0, where=~valid[rows])  # (a boolean-index assignment: ~1.5x)
    return rel



@functools.lru_cache(maxsize=8)
def _grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per frame shape: the 2-D Hann window (float32, as the spectrum), the rfft2 frequencies
    fx (1, w//2+1), fy (h, 1) [cycles/px] and the bins searched (read-only; frames of one
    camera share them)."""
    win = np.outer(np.hanning(h), np.hanning(w)).astype(np.float32)
    fy = fft.fftfreq(h)[:, None]
    fx = fft.rfftfreq(w)[None, :]
    f = np.hypot(fx, fy)
    # At least MIN_BINS from the origin: the ray test needs its inner side (a steep smooth
    # spectrum — shading, a lay's broad part — is lower outside than inside).
    bins = np.hypot(fx * w, fy * h)
    search = (f >= 1 / PERIOD_PX[1]) & (f <= 1 / PERIOD_PX[0]) & (bins >= MIN_BINS)
    for a in (win, fx, fy, search):
        a.flags.writeable = False
    return win, fx, fy, search


@functools.lru_cache(maxsize=8)
def _searched(h: int, w: int) -> int:
    """How many bins :func:`_grid`'s search holds (per frame shape)."""
    return int(np.count_nonzero(_grid(h, w)[3]))


def _box_sums(P: np.ndarray, sizes: tuple[int, ...]) -> list[np.ndarray]:
    """Sums of P over the size x size bins about each bin, the spectrum wrapped around (as
    scipy.ndimage.uniform_filter(mode="wrap") x size^2, ~4x faster), per size (odd). One
    wrapped copy for all sizes: the largest's pad holds each smaller one's (the same
    array, cut out of it), so each sum is the one its own pad gave, to the bit."""
    R = max(sizes) // 2
    Q = np.pad(P, R, mode="wrap")
    out = []
    for size in sizes:
        r = size // 2
        q = Q[R - r:Q.shape[0] - (R - r), R - r:Q.shape[1] - (R - r)]
        out.append(cv2.boxFilter(q, -1, (size, size), normalize=False,
                                 borderType=cv2.BORDER_CONSTANT)[r:-r, r:-r])
    return out


def _peak(rel: np.ndarray, valid: np.ndarray, alpha: float = ALPHA
          ) -> tuple[float, float, float, float]:
    """The strongest periodic peak: (ratio, threshold, fx, fy) [cycles/px]."""
    h, w = rel.shape
    win, fx, fy, search = _grid(h, w)
    # (rel - mean * valid) * win, in one buffer: off the background 0 - 0 * mean = 0.
    # The spectrum in float32: half the passes' bytes and a transform ~2x faster at 5 MP;
    # its rounding (~1e-6 of a bin's power) is far below the ratios' own scatter (~100 %).
    x = np.subtract(rel, rel[valid].mean(), dtype=np.float32)
    np.copyto(x, 0.0, where=~valid)
    x *= win
    P = np.abs(fft.rfft2(x, workers=1))
    del x
    P *= P
    # 2-D neighbourhood: 15x15 bins less the 5x5 core (a windowed peak's spread)
    cand, core = _box_sums(P, (15, 5))
    # (box15 - box5) / 200, floored, then P over it, in place; 0 off the bins searched.
    cand -= core
    cand /= np.float32(200.0)
    np.maximum(cand, np.finfo(np.float32).tiny, out=cand)
    np.divide(P, cand, out=cand)
    np.copyto(cand, np.float32(0.0), where=~search)
    thr = MARGIN * float(np.log(_searched(h, w) / alpha))
    best = (0.0, thr, 0.0, 0.0)
    above = np.flatnonzero(cand >= thr)  # usually none
    order = above[np.argsort(cand.flat[above])[::-1]][:20]
    for flat in order:
        iy, ix = np.unravel_index(flat, P.shape)
        r = _radial_ratio(P, iy, ix)
        ratio = min(float(cand[iy, ix]), r)
        if ratio > best[0]:
            best = (ratio, thr, float(fx[0, ix]), float(fy[iy, 0]))
    if best[0] == 0.0:
        best = (float(cand.max()), thr, 0.0, 0.0)
    return best


def _radial_ratio(P: np.ndarray, iy: int, ix: int) -> float:
    """The bin's power over the mean along its own ray (0.2-0.5 of its radius either side,
    at least 3-6 bins, none nearer the origin than 2 bins): a texture lay is high all along
    its ray, a plane wave is not. The ray's power at a radius is the largest of the bins
    within 2 across it — a lay's line is one or two bins wide and seldom on the grid, so an
    interpolated sample beside it would miss it (a lay passed for a peak in 2 of 240 clean
    frames that way). The level is the larger of the inner and the outer side's means."""
    h = P.shape[0]
    ky = iy if iy < h // 2 else iy - h  # signed row frequency index
    r = np.hypot(ix, ky)
    # Out of the windowed peak's main lobe (+-2 bins) however close to the origin it is.
    d = np.linspace(max(3.0, 0.2 * r), max(6.0, 0.5 * r), 7)
    s = np.r_[1 - d[r - d >= 2] / r, 1 + d]
    ux, uy = ix / r, ky / r
    inner = s < 1
    best = np.zeros(s.size)
    for off in np.arange(-2.0, 2.5, 0.5):
        px = np.rint(s * ix - off * uy).astype(int)
        py = np.rint(s * ky + off * ux).astype(int)
        flip = px < 0  # the rfft half-plane: P(-f) = P(f)
        px, py = np.where(flip, -px, px), np.where(flip, -py, py)
        best = np.maximum(best, P[np.mod(py, h), np.minimum(px, P.shape[1] - 1)])
    # The larger side: a steep but smooth spectrum (a lay's broad component) is far lower
    # outside than inside; a peak stands above both.
    level = max(best[inner].mean() if inner.any() else 0.0, best[~inner].mean())
    return float(P[iy, ix] / max(level, 1e-300))


def _project(k: np.ndarray, X: np.ndarray, Y: np.ndarray, z: np.ndarray
             ) -> tuple[np.ndarray, ...]:
    """At wave vector k: cos and sin of the phase, the Cholesky factor of G = A^T A (A: cos,
    sin, level), the least-squares amplitudes c and the variable-projection residual
    r = A c - z.

    By the 3x3 normal equations, not a QR of A: forming Q over ~40k pixels was ~60 % of a
    step's CPU; cos, sin and 1 over the >= 4.8 periods the search admits are near orthogonal
    (cond(G) ~ 2), so G loses nothing a QR keeps (~1e-15 of c)."""
    ph = k[0] * X + k[1] * Y
    cs, sn = np.cos(ph), np.sin(ph)
    s_c, s_s = cs.sum(), sn.sum()
    cs_sn = cs @ sn
    G = np.array([[cs @ cs, cs_sn, s_c], [cs_sn, sn @ sn, s_s], [s_c, s_s, float(z.size)]])
    cho = linalg.cho_factor(G)
    c = linalg.cho_solve(cho, np.array([cs @ z, sn @ z, z.sum()]))
    return cs, sn, cho, c, (c[0] * cs + c[1] * sn + c[2]) - z


def _jacobian(proj: tuple[np.ndarray, ...], X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """dr/dk (n, 2) of :func:`_project`'s residual [1/(rad/px)].

    The exact Jacobian of the projected residual (Golub & Pereyra 1973, written out: scipy
    has no variable projection): with D_j = dA/dk_j and G = A^T A,
    dr/dk_j = (I - A G^-1 A^T) D_j c - A G^-1 D_j^T r (the QR form's Q Q^T and Q R^-T
    written with A and G). A finite-difference Jacobian cost two more residuals (cos, sin
    and a 3-column fit over ~40k pixels each) per step.
    """
    cs, sn, cho, c, r = proj
    g = c[1] * cs - c[0] * sn  # d(A c)/d(phase)
    J = np.empty((r.size, 2))
    for j, coord in enumerate((X, Y)):
        v = coord * g  # D_j c
        atv_w = np.array([cs @ v - (sn * coord) @ r, sn @ v + (cs * coord) @ r, v.sum()])
        m = linalg.cho_solve(cho, atv_w)  # G^-1 (A^T D_j c + D_j^T r)
        J[:, j] = v - (m[0] * cs + m[1] * sn + m[2])
    return J


def _resid_jac(k: np.ndarray, X: np.ndarray, Y: np.ndarray, z: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The residual r(k) = A(k) c(k) - z, its Jacobian dr/dk and c (:func:`_project`)."""
    proj = _project(k, X, Y, z)
    return proj[4], _jacobian(proj, X, Y), proj[3]


def _fit(rel: np.ndarray, valid: np.ndarray, f0: tuple[float, float], origin: tuple[int, int]
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wave vector k [rad/px] (full-image coordinates), (a, b) and their covariance, fitted by
    least squares on the background (variable projection: a, b linear; analytic Jacobian,
    :func:`_jacobian`)."""
    yy, xx = np.nonzero(valid)
    step = max(1, yy.size // FIT_PIXELS)
    yy, xx = yy[::step], xx[::step]
    z = rel[yy, xx].astype(float)
    X, Y = (xx + origin[1]).astype(float), (yy + origin[0]).astype(float)
    # Levenberg-Marquardt sees the n residuals only through |r|, J^T J and J^T r, so it is
    # given the compressed problem instead: J's triangle R (J^T J = R^T R), R^-T J^T r and the
    # norm of the rest of r — the same steps, the same stops, without MINPACK's QR of the
    # n x 2 Jacobian and its copies (~half a fit's CPU at n ~ 40k). Each trial k's projection
    # serves its residual and Jacobian calls both.
    last: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def at(k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = np.asarray(k, float).tobytes()
        if key not in last:
            last.clear()
            proj = _project(k, X, Y, z)
            last[key] = compressed(proj[4], _jacobian(proj, X, Y))
        return last[key]

    k0 = 2 * np.pi * np.asarray(f0)
    sol = optimize.least_squares(lambda k: at(k)[0], k0, jac=lambda k: at(k)[1],
                                 x_scale=2 * np.pi / max(rel.shape), method="lm")
    cs, sn, _, c, r = _project(sol.x, X, Y, z)
    A = np.column_stack([cs, sn, np.ones_like(cs)])
    cov = np.linalg.inv(A.T @ A) * float(r @ r) / max(z.size - 5, 1)
    return sol.x, c[:2], cov[:2, :2]


def _wave(k: np.ndarray, ab: np.ndarray, cov: np.ndarray, ratio: float) -> Wave:
    amp = float(np.hypot(*ab))
    g = ab / max(amp, 1e-300)
    # The crests run perpendicular to k; angles counter-clockwise with y up (the marks').
    ang = float(np.arctan2(-k[0], -k[1]))
    ang = float((ang + np.pi / 2) % np.pi - np.pi / 2)
    return Wave(amp, float(np.sqrt(max(g @ cov @ g, 0.0))), float(2 * np.pi / np.hypot(*k)),
                ang if ang != -np.pi / 2 else np.pi / 2, (float(k[0]), float(k[1])),
                (float(ab[0]), float(ab[1])), ratio)


def _exact_float32(raw: np.ndarray, full_scale: float) -> np.ndarray:
    """A float64 square cut from a larger frame as float32 when that holds every value and
    ``full_scale`` exactly (whole pixels up to 2^24: any image read from an integer file),
    else as it is.

    A 5 MP frame's 1024 px square is a strided view of 8 MB: its two range tests and the
    shading's division read it at ~5x a contiguous float32 copy's cost (~3 ms; the copy and
    OpenCV's one-pass check ~1.3). The same answers to the bit: the tests compare the same
    values, and a quotient of float32 values rounded once to float32 equals the float64
    quotient rounded to float32 (53 >= 2 x 24 + 2 bits: the double rounding is innocuous,
    Figueroa 1995). (NaN: the check may pass it; NaN compares and divides alike in both.)"""
    if (raw.dtype != np.float64 or raw.flags.c_contiguous  # (a whole small frame: as fast)
            or float(np.float32(full_scale)) != full_scale):
        return raw
    r32 = raw.astype(np.float32)
    # The sum of |differences| is 0 exactly when each is (a sum of non-negative terms is at
    # least its largest; NaN or inf makes it NaN): OpenCV's L1 norm runs ~2x its max norm.
    return r32 if cv2.norm(raw, r32.astype(np.float64), cv2.NORM_L1) == 0 else raw


def oriented_square(image: np.ndarray, full_scale: float, copy32: np.ndarray | None = None
                  ) -> np.ndarray:
    """The image's central square that :func:`find_oriented` tests (:func:`square_slices`:
    the detector's noise square too, :func:`imaging.ridge.central`), as float32 when that
    holds every pixel exactly, else as it is (see :func:`_exact_float32`). Made once per
    frame by a caller that needs it for both (a second read of a 5 MP frame's strided
    float64 square cost ~1 ms); ``copy32``: the square cast to float32 and found to hold
    every pixel exactly, when the caller has it (:func:`imaging.framepass.frame_pass`)."""
    raw = image[square_slices(image.shape)]
    if (copy32 is not None and raw.dtype == np.float64 and not raw.flags.c_contiguous
            and float(np.float32(full_scale)) == full_scale):
        return copy32
    return _exact_float32(raw, full_scale)


def find_oriented(image: np.ndarray, mask: np.ndarray | None, full_scale: float,
                  alpha: float = ALPHA, square: np.ndarray | None = None
                  ) -> tuple[np.ndarray, OrientedStripes]:
    """The image with its oriented periodic background divided out where found, and the
    finding.

    ``mask``: True on the lines' bands (:func:`imaging.band.band_mask`; None: no lines), left
    out of the background; clipped pixels (0 or ``full_scale``) too. The image comes back
    unchanged (same object) when no pattern is found. ``square``: :func:`oriented_square` of
    this image when the caller has it.
    """
    sl = square_slices(image.shape)
    if min(image[sl].shape) < 4 * PERIOD_PX[1] // 2:
        return image, OrientedStripes((), 0.0, float("inf"), reason="image too small to test")
    raw = oriented_square(image, full_scale) if square is None else square
    valid = (raw > 0) & (raw < full_scale)
    if mask is not None:
        valid &= ~mask[sl]
    if np.count_nonzero(valid) / valid.size < MIN_BACKGROUND:  # (the mean, no float copy)
        return image, OrientedStripes((), 0.0, float("inf"),
                                      reason="too little background to test")
    cur = raw
    waves: list[Wave] = []
    ratio0, thr = 0.0, float("inf")
    for _ in range(MAX_WAVES):
        rel = _relative(cur, valid)
        ratio, thr, fx, fy = _peak(rel, valid, alpha)
        ratio0 = ratio0 or ratio
        if ratio < thr:
            break
        k, ab, cov = _fit(rel, valid, (fx, fy), (sl[0].start, sl[1].start))
        w = _wave(k, ab, cov, ratio)
        waves.append(w)
        cur = cur / (1.0 + w.pattern(image.shape)[sl])
    if not waves:
        return image, OrientedStripes((), ratio0, thr)
    # What is left of each wave at its own frequency: the removal's remaining fraction.
    rel = _relative(cur, valid)
    left = 0.0
    for w in waves:
        _, ab, cov = _fit_fixed(rel, valid, w.k, (sl[0].start, sl[1].start))
        amp = float(np.hypot(*ab))
        left = max(left, (amp + 2 * float(np.sqrt(np.trace(cov) / 2))) / w.amplitude)
    found = OrientedStripes(tuple(waves), ratio0, thr, min(left, 1.0))
    out = image.astype(float) / found.factor(image.shape)
    clipped = (image <= 0) | (image >= full_scale)  # "beyond the range": kept as they are
    out[clipped] = image[clipped]
    return out, found


def _fit_fixed(rel: np.ndarray, valid: np.ndarray, k: tuple[float, float],
               origin: tuple[int, int]) -> tuple[None, np.ndarray, np.ndarray]:
    """(a, b) and their covariance at a fixed wave vector."""
    yy, xx = np.nonzero(valid)
    step = max(1, yy.size // FIT_PIXELS)
    yy, xx = yy[::step], xx[::step]
    z = rel[yy, xx]
    ph = k[0] * (xx + origin[1]) + k[1] * (yy + origin[0])
    A = np.column_stack([np.cos(ph), np.sin(ph), np.ones_like(ph)])
    c, *_ = np.linalg.lstsq(A, z, rcond=None)
    r = A @ c - z
    cov = np.linalg.inv(A.T @ A) * float(r @ r) / max(z.size - 3, 1)
    return None, c[:2], cov[:2, :2]


def oriented_note(where: str, found: OrientedStripes) -> tuple[str, ...]:
    """One line per wave removed: what it is and what was done about it."""
    return tuple(
        f"{where}: striped background: period {w.period_px:.1f} px at "
        f"{np.rad2deg(w.angle_rad):.1f} deg, amplitude {100 * w.amplitude:.2g} % of the "
        f"level (peak {w.ratio:.3g}x the spectrum about it; a turned or ground surface's lay, "
        "or fringes): divided out; the angle change it made, times the fraction the removal "
        f"may leave ({100 * found.residual:.2g} %), is carried in u"
        for w in found.waves)
