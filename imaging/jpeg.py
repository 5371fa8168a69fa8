"""JPEG compression: its 8x8 blocks found in the pixels, and what they do to a mark's angle.

A baseline JPEG quantises each 8x8 block's DCT coefficients to multiples of its table's
steps. At a groove's edge that moves the centres by a few hundredths of a px, by an amount
that depends on where the edge sits in the block, the same in every block the mark crosses at
the same phase: a near-axis mark drifting slowly across the block grid collects it as an
angle error (+16-20" on a 400 px mark at quality 50, against a line u of 3.5"), which no
residual test sees.

Found (hand-written: no library estimates a decoded image's quantisation): the decoded
pixels' block DCT coefficients cluster at multiples of the steps. For each quality of the
standard (IJG) luminance table, the low-frequency coefficients' concentration on multiples
of its steps is measured (the mean cosine R of 2 pi c / q over the blocks whose coefficient
is a small non-zero multiple); the lowest quality whose steps all the coefficients follow
(R > :data:`R_MIN`) is the encoder's. Without JPEG, R ~ 1/sqrt(blocks).

Carried (a Type B term, GUM Supplement 1 style: the method run on a known input): the fitted
groove model is rendered where the mark is, on the image's block grid, with the noise the
pixels had before coding (:func:`precoding_noise`, read here), put through a JPEG encoder at
that quality, and its centres measured as the mark's were; the angle's change is the term
``jpeg_blocks`` (:mod:`imaging.jpeg_turn`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from imaging.centres import sample_centres
from imaging.groove import ProfileFit
from imaging.io import JpegTables
from imaging.linefit import fit_line

R_MIN = 0.5
"""Concentration on the steps' multiples that says "quantised" (noise alone gives ~0.01)."""
MIN_BLOCKS = 12
"""Fewest blocks with a coefficient beyond its zero bin for it to count (at least 3 must)."""
FLAT_MIN = 20
"""Flat blocks on the grid that say "JPEG" when the coefficients cannot (a background the
encoder flattened: quality unknown, every quality's effect is then carried)."""
MIN_MULTIPLE = 3
"""Blocks a multiple of a step must hold for it to count as one of the two or more distinct
multiples a coefficient must show (see :func:`_one_multiple`)."""
Z_MIN = 5.0
"""The coefficients' pooled concentration in noise units (sum n R / sqrt(sum n / 2)) needed:
with 12 blocks one coefficient's R has a standard deviation of 0.2 without JPEG."""
# AC only: a block the encoder left flat decodes to one integer level, so its DC moves by
# up to 4 steps of the orthonormal DCT together (DC at quality 70 followed its step at 0.44).
_COEFFS = ((0, 1), (1, 0), (1, 1), (0, 2), (2, 0), (1, 2), (2, 1), (0, 3), (3, 0), (2, 2),
           (0, 4), (4, 0))
# The IJG (libjpeg) standard luminance table (ITU-T T.81 Annex K.1), row-major.
_LUMA = np.array([
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55,
    14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51, 87, 80, 62,
    18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
    49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99],
    float).reshape(8, 8)


def ijg_table(quality: int) -> np.ndarray:
    """The IJG luminance quantisation table at ``quality`` (1-100), as libjpeg scales it."""
    q = min(max(int(quality), 1), 100)
    scale = 5000 / q if q < 50 else 200 - 2 * q
    return np.clip(np.floor((_LUMA * scale + 50) / 100), 1, 255)


def _dct_matrix() -> np.ndarray:
    k = np.arange(8)
    m = np.sqrt(2 / 8) * np.cos((2 * k[None, :] + 1) * k[:, None] * np.pi / 16)
    m[0] /= np.sqrt(2)
    return m


@dataclass(frozen=True)
class JpegBlocks:
    """A decoded JPEG's encoder as the pixels show it: ``quality`` of the IJG table whose
    steps the coefficients follow (None: only flattened blocks show it, quality unknown),
    ``concentration`` (the smallest R over the tested coefficients at that quality),
    ``blocks`` used.

    Attributes
    ----------
    quality : int or None
        IJG quality 1-100 the coefficients follow; None: unknown.
    concentration : float
        Smallest R over the tested coefficients at that quality — dimensionless.
    blocks : int
        8x8 blocks used.
    phase : tuple of int
        (x, y) of the block grid's first boundary [px], 0-7: (0, 0) as decoded; else a
        crop (or a turn) moved the grid (:func:`grid_phase`).
    table : tuple of int or None
        The file's own luminance table (64 steps, row-major) when its header gave it
        (``quality`` is then the IJG quality that table is, None: another encoder's);
        None: read from the pixels.
    noise_dn : float
        The pixels' noise before coding [DN] (:func:`precoding_noise`); 0: not read (the
        table unknown, or no coefficient beyond its zero bin).
    candidates : tuple of (int, float)
        (quality, noise_dn) of each IJG quality the pixels cannot exclude when the quality
        was read by re-encoding the blocks (:func:`quality_candidates`; ``quality`` the
        lowest of them): their effects are bounded by the largest. Empty: ``quality``
        alone.
    """

    quality: int | None
    concentration: float
    blocks: int
    phase: tuple[int, int] = (0, 0)
    table: tuple[int, ...] | None = None
    noise_dn: float = 0.0
    candidates: tuple[tuple[int, float], ...] = ()


def table_quality(table: np.ndarray) -> int | None:
    """The IJG quality (1-100) whose luminance table ``table`` (8x8 or 64 steps, row-major)
    is, step for step; None: another encoder's table."""
    t = np.asarray(table, float).reshape(8, 8)
    return next((q for q in range(1, 101) if np.array_equal(ijg_table(q), t)), None)


def grid_phase(image: np.ndarray) -> tuple[int, int]:
    """Where an image's 8x8 JPEG grid would lie: (x, y) of its first block boundary [px],
    0-7 (on any image: whether it is a JPEG's grid is :func:`find_jpeg_at`'s to say).

    The encoder quantises each block alone, so the pixels step at the block boundaries more
    than inside the blocks. Over the 64 phases the statistic separates into x and y: the
    columns' (rows') mean absolute step across the rows (columns), whose median over the
    columns of one phase modulo 8 is that phase's (a median: a mark along a column steps
    in a few columns only). The phase of the largest is the grid's.

    Parameters
    ----------
    image : numpy.ndarray
        2-D image [DN].

    Returns
    -------
    tuple of int
        (x, y) [px].
    """
    img = np.asarray(image, float)
    out = []
    for a in (img, img.T):
        step = np.mean(np.abs(np.diff(a, axis=1)), axis=0)  # step j: between columns j, j+1
        k = (np.arange(len(step)) + 1) % 8  # the phase of the boundary at column j + 1
        out.append(int(np.argmax([np.median(step[k == p]) for p in range(8)])))
    return out[0], out[1]


def find_jpeg(image: np.ndarray, tables: JpegTables | None = None) -> JpegBlocks | None:
    """The JPEG encoder an 8-bit image was decoded from (None: no sign of JPEG, or not
    8-bit data).

    A file's header (``tables``, :func:`imaging.io.read_image_notes`) names its table: it is
    taken as the encoder's. Else the pixels say it (:func:`find_jpeg_at`), on the grid at
    the image's top-left corner, as decoded, and, when the block boundaries put the grid
    elsewhere (:func:`grid_phase`: a crop of a JPEG, saved as PNG), on that grid too: it is
    taken when its quality is read and is lower than the origin's (a background the encoder
    flattened is flat on any grid, so "JPEG, quality unknown" at the origin is no answer).
    """
    return _with_candidates(image, _with_noise(image, _find_jpeg(image, tables)))


def _with_noise(image: np.ndarray, jb: JpegBlocks | None) -> JpegBlocks | None:
    """``jb`` with the noise before coding read on its grid (:func:`precoding_noise`)."""
    if jb is None or (jb.quality is None and jb.table is None):
        return jb
    T = np.array(jb.table, float).reshape(8, 8) if jb.table is not None else ijg_table(jb.quality)
    return replace(jb, noise_dn=precoding_noise(image, T, jb.phase))


def _with_candidates(image: np.ndarray, jb: JpegBlocks | None) -> JpegBlocks | None:
    """``jb`` with the qualities its pixels cannot exclude (:func:`quality_candidates`) when
    its quality was read by re-encoding the blocks (no header, no concentration read)."""
    if jb is None or jb.table is not None or jb.quality is None or np.isfinite(
            jb.concentration):
        return jb
    qs = quality_candidates(image[jb.phase[1]:, jb.phase[0]:], jb.quality)
    cands = tuple((q, precoding_noise(image, ijg_table(q), jb.phase)) for q in qs)
    return replace(jb, quality=cands[0][0], noise_dn=cands[0][1], candidates=cands)


QUALITY_SPAN = 8
"""Qualities above a re-encoding's reading (:func:`requantised_quality`) that may be the
encoder's: its 1 DN tolerance gives back tables a few steps coarser (70-73 read on user 13's
quality-75 crops)."""
Z_EXCLUDE = 3.0
"""A quality is excluded when a coefficient's concentration on its steps is this far below
0 in noise units (R sqrt(2 n)): the coefficients sit between its multiples."""


def quality_candidates(image: np.ndarray, quality: int) -> tuple[int, ...]:
    """The IJG qualities from ``quality`` (a re-encoding's reading, :func:`requantised_quality`)
    to :data:`QUALITY_SPAN` above it that the decoded blocks (grid at ``image``'s corner)
    cannot exclude: none of the tested coefficients lies between the steps' multiples
    (its mean cosine R below 0 by :data:`Z_EXCLUDE` in noise units; a coefficient the table
    quantises keeps R > 0, down to ~0.2 where rounding bends small patterns: quality 75's
    (2, 0)). The re-encoding reads tables a few steps coarser than the encoder's (its
    1 DN tolerance); the concentration on the steps sees most of them (a quality-75 crop
    of user 13's read at 72: 68-71 excluded at -4.1 to -7.9 sigma, 72-73 at -2.9 kept,
    74-75 at +2.3 or more, 76-80 excluded at -5.6 or less).

    Parameters
    ----------
    image : numpy.ndarray
        2-D decoded 8-bit image [DN], its block grid at the corner.
    quality : int
        The reading (1-100).

    Returns
    -------
    tuple of int
        The qualities, ascending; ``(quality,)`` when every one is excluded.
    """
    got = _block_dct(image)
    if got is None:
        return (quality,)
    xs = got[2]
    kept = []
    for q in range(quality, min(quality + QUALITY_SPAN, 100) + 1):
        T = ijg_table(q)
        rs = [_concentration(xs[uv], T[uv]) for uv in _COEFFS]
        if all(r is None or r[0] * np.sqrt(2 * r[1]) >= -Z_EXCLUDE for r in rs):
            kept.append(q)
    return tuple(kept) or (quality,)


def _block_dct(image: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict] | None:
    """The 8x8 blocks on the grid at the image's corner (a, b, 8, 8) [DN], their orthonormal
    DCT about 128 (N, 8, 8), and each tested coefficient (:data:`_COEFFS`) over the blocks,
    contiguous (taken once, not once a quality from the strided array). None: fewer than
    2 x 2 blocks."""
    h, w = (s // 8 * 8 for s in image.shape)
    if h < 16 or w < 16:
        return None
    b = np.asarray(image, float)[:h, :w].reshape(h // 8, 8, w // 8, 8).transpose(0, 2, 1, 3)
    D = _dct_matrix()
    c = np.einsum("ij,abjk,lk->abil", D, b - 128.0, D).reshape(-1, 8, 8)
    return b, c, {uv: np.ascontiguousarray(c[:, uv[0], uv[1]]) for uv in _COEFFS}


def _concentration(x: np.ndarray, step: float, mag: np.ndarray | None = None
                   ) -> tuple[float, int] | None:
    """(R, n): the mean cosine of 2 pi x / step over the n coefficients ``x`` beyond the zero
    bin and within 4.5 steps (the first 1000); None: too few (:data:`MIN_BLOCKS`), a step
    below 2, or blocks alike (:func:`_one_multiple`: a groove along a block row, not a
    quantiser). ``mag``: |x| when already taken.

    Small multiples only: the encoder's fast DCT is exact to a fraction of a % of the
    coefficient, which at 10 steps blurs the phase. The mean cosine, not the resultant
    length: noise coefficients just past the +-T/2 cut sit at phase pi (a resultant length
    near 1 on a raw image)."""
    mag = np.abs(x) if mag is None else mag
    big = (mag >= 0.5 * step) & (mag <= 4.5 * step)
    if big.sum() < MIN_BLOCKS or step < 2 or _one_multiple(x[big], step):
        return None
    return float(np.mean(np.cos(2 * np.pi * x[big][:1000] / step))), min(int(big.sum()), 1000)


def _find_jpeg(image: np.ndarray, tables: JpegTables | None) -> JpegBlocks | None:
    if tables is not None:
        h, w = image.shape
        return JpegBlocks(table_quality(np.array(tables.luma)), float("nan"),
                          (h // 8) * (w // 8), tables.phase, tables.luma)
    found = find_jpeg_at(image)
    if min(image.shape) < 24:
        return found
    px, py = grid_phase(image)
    if (px, py) == (0, 0):
        return found
    moved = find_jpeg_at(image[py:, px:])
    if moved is None or (found is not None and moved.quality is None):
        return found
    if found is not None and found.quality is not None and found.quality <= (moved.quality or 0):
        return found
    # On the encoder's grid its coarse steps show; a grid off by a few px sees sums of
    # neighbouring blocks' coefficients, on finer steps at best (quality ~94 read at the
    # origin of a quality-75 JPEG cropped by one row): the coarser reading is the grid's.
    return replace(moved, phase=(px, py))


def find_jpeg_at(image: np.ndarray) -> JpegBlocks | None:
    """The JPEG quality an 8-bit image was decoded from (None: no sign of JPEG, or not
    8-bit data), its block grid at the image's top-left corner."""
    if image.dtype != np.uint8 and not (float(image.max()) <= 255
                                        and np.all(image == np.round(image))):
        return None
    got = _block_dct(image)
    if got is None:
        return None
    b, c, xs = got
    h, w = (s // 8 * 8 for s in image.shape)
    best = None
    # Each tested coefficient's magnitude: the same numbers for every quality (taken once,
    # not 100 times).
    mags = {uv: np.abs(x) for uv, x in xs.items()}
    for quality in range(1, 101):
        T = ijg_table(quality)
        rs: list[tuple[float, int]] | None = []
        for uv in _COEFFS:
            rn = _concentration(xs[uv], T[uv], mags[uv])
            if rn is None:
                continue  # too few beyond the zero bin, or blocks alike: cannot tell
            if not rn[0] > R_MIN:
                rs = None  # this quality fails (its smallest R is at most R_MIN): the rest
                break      # of its coefficients cannot change that (a raw image: at once)
            rs.append(rn)
        if rs is None or len(rs) < 3:
            continue
        r, n = np.array(rs).T
        if r.min() > R_MIN and (n @ r) / np.sqrt(n.sum() / 2) > Z_MIN:
            best = JpegBlocks(quality, float(r.min()), len(c))
            break  # the lowest quality (largest steps) the coefficients follow
    if best is None and _flat_on_the_grid(image[:h, :w]):
        # The encoder flattened the background; its quality is read from the blocks it did
        # not flatten (a mark's), by re-encoding them (None: too few to tell).
        best = JpegBlocks(requantised_quality(b.reshape(-1, 8, 8), c), float("nan"), len(c))
    return best


NOISE_MIN_STEP = 3
"""Smallest step of a coefficient :func:`precoding_noise` counts (finer steps: the decoded
pixels' rounding, 0.3 DN a coefficient, moves a value across the zero bin's edge)."""


def precoding_noise(image: np.ndarray, table: np.ndarray, phase: tuple[int, int] = (0, 0)
                    ) -> float:
    """The pixels' white noise before coding [DN], from the share of each coefficient the
    encoder did not quantise to zero.

    A background block's orthonormal DCT turns white pixel noise of sigma s into AC
    coefficients of the same sigma, each; the encoder sets one to zero when it is within
    half its step T of 0, with probability p0 = erf(T / (2 sqrt(2) s)). The decoded blocks'
    coefficients (on the grid at ``phase``) show which did: the counts beyond the zero bin
    over the AC frequencies with T >= :data:`NOISE_MIN_STEP` give s by maximum likelihood
    (binomial counts, pooled: the finest steps say most). Where the encoder flattened the
    background, the few coefficients it kept are what is left of that noise; the decoded
    background's own scatter is not (~0). Blocks with content (the first coefficients
    (0, 1), (1, 0) beyond 2 steps: an edge, a gradient) or clipped are left out, and those
    two coefficients with them; what content remains reads as noise (s too large: u wider).

    Parameters
    ----------
    image : numpy.ndarray
        2-D decoded 8-bit image [DN].
    table : numpy.ndarray
        (8, 8) the encoder's luminance steps [DN of the orthonormal DCT].
    phase : tuple of int
        (x, y) of the grid's first block boundary [px].

    Returns
    -------
    float
        s [DN]; 0: no coefficient beyond its zero bin (or no block to count).
    """
    from scipy.special import erfc

    a = np.asarray(image, float)[phase[1]:, phase[0]:]
    h, w = (s // 8 * 8 for s in a.shape)
    if h < 8 or w < 8:
        return 0.0
    b = a[:h, :w].reshape(h // 8, 8, w // 8, 8).transpose(0, 2, 1, 3).reshape(-1, 8, 8)
    D = _dct_matrix()
    T = np.asarray(table, float).reshape(8, 8)
    k = np.round(np.einsum("ij,njk,lk->nil", D, b - 128.0, D) / T)
    busy = ((np.abs(k[:, 0, 1]) > 2) | (np.abs(k[:, 1, 0]) > 2)
            | (b.min(axis=(1, 2)) == 0) | (b.max(axis=(1, 2)) == 255)).reshape(h // 8, w // 8)
    # And their neighbours: an edge's tail (a groove's blur, its soft end) runs into them.
    near = busy.copy()
    near[1:] |= busy[:-1]
    near[:-1] |= busy[1:]
    near[:, 1:] |= busy[:, :-1]
    near[:, :-1] |= busy[:, 1:]
    bg = ~near.ravel()
    use = T >= NOISE_MIN_STEP
    use[0, 0] = use[0, 1] = use[1, 0] = False
    n_bg = int(bg.sum())
    if n_bg == 0 or not use.any():
        return 0.0
    kept = np.sum(k[bg][:, use] != 0, axis=0).astype(float)
    if kept.sum() == 0:
        return 0.0
    steps = T[use]
    s = np.geomspace(0.05, 50.0, 400)[:, None]
    p = np.clip(erfc(steps[None, :] / (2 * np.sqrt(2) * s)), 1e-300, 1 - 1e-16)
    loglik = (kept * np.log(p) + (n_bg - kept) * np.log1p(-p)).sum(axis=1)
    return float(s[np.argmax(loglik), 0])


REQUANT_MIN_BLOCKS = 20
"""Fewest blocks with content (not flat) :func:`requantised_quality` reads a quality from."""
REQUANT_SHARE = 0.98
"""Share of those blocks a quality's table must give back (each pixel within 1 DN)."""
REQUANT_MAX = 97
"""Highest quality tried: above it the steps (1-2 at 99) are within the 1 DN allowed, and any
image is given back."""


def requantised_quality(blocks: np.ndarray, coeffs: np.ndarray, most: int = 400) -> int | None:
    """The lowest IJG quality whose table gives back the decoded blocks: each block's DCT
    coefficients quantised to that table's steps and decoded again (rounded, clipped) must
    reproduce its pixels within 1 DN (the encoder's fixed-point DCT) in
    :data:`REQUANT_SHARE` of the blocks with content.

    A decoded JPEG is (nearly) a fixed point of its own quantiser, and of any finer one
    whose steps divide its own; a coarser table moves the pixels by whole steps. Unlike the
    coefficients' concentration on the steps' multiples (:func:`find_jpeg`), this holds for
    blocks whose few non-zero coefficients decode to patterns of 1-2 DN, which rounding
    to integers moves by a large part of a step (quality 75's (2, 0) coefficient read back
    at 5.2 for its step of 7). A raw image is given back only by the finest tables (steps of
    1-2 at quality 99, within the 1 DN allowed): qualities up to :data:`REQUANT_MAX` are tried.

    Parameters
    ----------
    blocks : numpy.ndarray
        (N, 8, 8) decoded blocks [DN].
    coeffs : numpy.ndarray
        (N, 8, 8) their orthonormal DCT about 128 [DN].
    most : int
        Blocks with content used at most (the first ones).

    Returns
    -------
    int or None
        The quality 1-:data:`REQUANT_MAX`; None: fewer than :data:`REQUANT_MIN_BLOCKS`
        blocks with content, or no quality up to it gives them back.
    """
    busy = np.flatnonzero(blocks.max(axis=(1, 2)) > blocks.min(axis=(1, 2)))[:most]
    if len(busy) < REQUANT_MIN_BLOCKS:
        return None
    b, c, D = blocks[busy], coeffs[busy], _dct_matrix()

    def given_back(T: np.ndarray, n: int) -> float:
        rec = np.einsum("ji,njk,kl->nil", D, np.round(c[:n] / T) * T, D) + 128.0
        return float(np.mean(np.abs(np.clip(np.round(rec), 0, 255) - b[:n]).max(axis=(1, 2))
                             <= 1))

    for quality in range(1, REQUANT_MAX + 1):
        T = ijg_table(quality)
        # A table that fails on the first 20 blocks fails (a coarser one moves most of
        # them): the full count only where it may pass.
        if given_back(T, REQUANT_MIN_BLOCKS) >= 0.8 and given_back(T, len(b)) >= REQUANT_SHARE:
            return quality
    return None


def _one_multiple(x: np.ndarray, step: float) -> bool:
    """Whether coefficients ``x`` sit at fewer than two multiples of ``step`` held by
    ``MIN_MULTIPLE`` blocks each. Blocks with one content (an axis-aligned groove at one
    phase of the grid: every block along it alike) share one value, which lies near a
    multiple of some quality's step by chance; quantisation shows only as different
    contents all falling on multiples."""
    _, n = np.unique(np.round(x / step), return_counts=True)
    return int(np.sum(n >= MIN_MULTIPLE)) < 2


def _flat_on_the_grid(img: np.ndarray) -> bool:
    """Whether the encoder flattened blocks (every AC step beyond the background's noise):
    8x8 blocks of one value, not clipped, far more often on the block grid than on the
    grid shifted by (4, 4) (a raw image's noise makes both rare and alike), or on most of
    the frame."""
    def flat(a: np.ndarray) -> int:
        hh, ww = (s // 8 * 8 for s in a.shape)
        b = a[:hh, :ww].reshape(hh // 8, 8, ww // 8, 8)
        lo, hi = b.min(axis=(1, 3)), b.max(axis=(1, 3))
        return int(np.sum((lo == hi) & (lo > 0) & (hi < 255)))

    on, off = flat(img), flat(img[4:, 4:])
    # Or most of the frame flat on the grid: no sensor is that quiet (8-bit shot noise
    # alone is ~1 DN at mid-scale); the encoder removed the noise with every AC step.
    return on >= FLAT_MIN and (on >= 4 * (off + 1) or on >= 0.5 * (img.size // 64))


def jpeg_round_trip(image: np.ndarray, quality: int | None, table: Sequence[int] | None = None,
                    phase: tuple[int, int] = (0, 0)) -> np.ndarray:
    """An 8-bit image through a baseline JPEG encoder and decoder at ``quality`` (IJG), or
    with the luminance ``table`` (64 steps, row-major) when given, on a block grid whose
    first boundary is at ``phase`` (x, y) [px] (the image padded before it by edge pixels,
    and cropped back)."""
    return jpeg_round_trips(np.asarray(image)[None], quality, table, phase)[0]


JPEG_MAX_ROWS = 65500
"""libjpeg's most rows: :func:`jpeg_round_trips` codes a taller column in parts."""


def jpeg_round_trips(images: np.ndarray, quality: int | None, table: Sequence[int] | None = None,
                     phase: tuple[int, int] = (0, 0)) -> np.ndarray:
    """:func:`jpeg_round_trip` of each of a stack of images (k, h, w) by one encode and
    decode: each padded to whole blocks (by edge pixels, as the encoder pads a partial one),
    coded as one column. A baseline grey JPEG quantises and decodes each 8 x 8 block alone
    (the DC's lossless prediction aside), so each comes back as coded alone, to the bit."""
    a = np.clip(np.round(images), 0, 255).astype(np.uint8)
    k, h, _ = a.shape
    top, left = (8 - phase[1]) % 8, (8 - phase[0]) % 8
    bottom = -(top + h) % 8
    per = max(1, JPEG_MAX_ROWS // (top + h + bottom))
    if k > per:  # (a column within the format's height)
        return np.concatenate([jpeg_round_trips(images[i:i + per], quality, table, phase)
                               for i in range(0, k, per)])
    a = np.pad(a, ((0, 0), (top, bottom), (left, 0)), mode="edge")
    tall = a.reshape(-1, a.shape[2])
    if table is not None:
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(tall).save(buf, "JPEG", qtables=[[int(v) for v in table]])
        buf.seek(0)
        with Image.open(buf) as im:
            out = np.asarray(im.convert("L"), float)
    else:
        import cv2

        ok, enc = cv2.imencode(".jpg", tall, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            return np.asarray(images, float)
        out = cv2.imdecode(enc, cv2.IMREAD_GRAYSCALE).astype(float)
    return out.reshape(a.shape)[:, top:top + h, left:]


def jpeg_note(where: str, jb: JpegBlocks, u_arcsec: float, spread: float = 1.0) -> str:
    """The line that names JPEG blocks on a mark and what they add to its u.

    Parameters
    ----------
    where : str
        The mark, as messages name it.
    jb : JpegBlocks
        The encoder found.
    u_arcsec : float
        What the blocks' systematic turn adds to the angle's u [″] (text: an edge).
    spread : float
        Factor on the centres' sigma their scatter was read to have (1: none beyond the
        stated; :func:`jpeg_centre_scale`, square-rooted) [-].

    Returns
    -------
    str
        The note.
    """
    if jb.table is not None:
        q = (f"quality {jb.quality} of the standard table, from the file's header"
             if jb.quality is not None else "the file's own table, from its header")
    else:
        q = (f"quality ~{jb.quality} of the standard table" if jb.quality is not None else
             "flattened blocks, quality unknown: the worst of 10-90 carried")
        if len(jb.candidates) > 1:
            q = (f"quality {jb.candidates[0][0]}-{jb.candidates[-1][0]} of the standard table "
                 "(read by re-encoding the blocks; the worst of those the coefficients cannot "
                 "exclude carried)")
    if jb.phase != (0, 0):
        q += (f"; its grid starts at x={jb.phase[0]}, y={jb.phase[1]} px, not at the "
              "image's corner: a crop of the JPEG, and its blocks taken there")
    scatter = (f"their scatter, taken as the blocks' and not as structure, widens the centres' "
               f"sigma x{spread:.3g}; " if spread > 1.0 else "")
    return (f"{where}: JPEG compression (8x8 blocks, {q}): the blocks move the centres "
            f"with the edge's place in the grid; {scatter}u widened by {u_arcsec:.2g}\" "
            "(jpeg_blocks: the fitted groove re-encoded)")


def rendering_angle_shift(a_image: np.ndarray, b_image: np.ndarray, pf: ProfileFit) -> float:
    """|angle in ``b_image`` - angle in ``a_image``| [rad] of the groove ``pf``: its centres
    sampled on the same segments of both, the line fitted with equal weights to the segments
    valid in both (0 when fewer than 10 are)."""
    a, b = sample_centres(a_image, pf), sample_centres(b_image, pf)
    ok = a.ok & b.ok
    if ok.sum() < 10:
        return 0.0
    one = np.ones(int(ok.sum()))
    da = fit_line(b.xy[ok], one, reject_sigma=None).angle_rad - fit_line(
        a.xy[ok], one, reject_sigma=None).angle_rad
    return float(abs((da + np.pi / 2) % np.pi - np.pi / 2))


def block_labels(xy: np.ndarray, phase: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Each point's 8x8 block (an integer label) on a grid whose block boundaries lie at
    x = phase[0] + 8 k and y = phase[1] + 8 k (pixel corners: a pixel's centre at x is in
    the block holding x + 0.5).

    Parameters
    ----------
    xy : numpy.ndarray
        (N, 2) image coordinates, x right and y down, of pixel centres at integers [px].
    phase : tuple of int
        (x, y) of the grid's first block boundary, 0-7 [px].

    Returns
    -------
    numpy.ndarray
        (N,) labels [-].
    """
    xy = np.asarray(xy, float)
    bx = np.floor((xy[:, 0] + 0.5 - phase[0]) / 8).astype(np.int64)
    by = np.floor((xy[:, 1] + 0.5 - phase[1]) / 8).astype(np.int64)
    return by * 1_000_003 + bx
