"""Finding scribe marks in a full, cluttered image without being told where they are.

A coarse search on a downsampled copy: a Hessian ridge filter (both polarities,
:mod:`imaging.ridge`), a threshold at a multiple of the response's robust noise, connected
components that are long and thin, and merging of collinear pieces (a mark broken by dust is
one mark); then each candidate is checked on the full-resolution image
(:mod:`imaging.confirm`). The result only seeds the sub-pixel measurement in
:mod:`imaging.profile`. Candidates and the geometry convention: :mod:`imaging.candidate`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from axisbase.memory import reuse_freed_memory
from imaging.candidate import (
    MarkCandidate,
    Roi,
    _dedupe,
    _drop_fused,
    _near,
    _overlap,
    _shift,
    check_roi,
    fused_covers,
    line_frame,
    require_single,
    unfused,
    wrap_angle,
)
from imaging.confirm import confirm_candidates
from imaging.crossing import split_two_lines
from imaging.errors import ImageInputError
from imaging.io import full_scale
from imaging.ridge import (
    central,
    median_abs_deviation,
    odd_pad,
    pixel_noise,
    ridge_gain,
    ridge_response,
)

# Re-exported: the package's modules import a candidate's geometry from here as well.
__all__ = [
    "LENGTH_SLACK", "MIN_LENGTH_PX", "MarkCandidate", "Roi", "Search", "_dedupe", "_near",
    "_overlap", "_shift", "check_roi", "default_min_length", "detect_lines_once", "detect_marks",
    "line_frame", "require_single", "search_factor", "wrap_angle",
]


def _components(mask: np.ndarray, min_len: float) -> list[np.ndarray]:
    """Pixels (x, y) of each 8-connected component of ``mask`` whose bounding box has a
    diagonal of at least ``min_len`` [px], in label order, each in row-major order.

    The bounding boxes come from the labelled pixels themselves: OpenCV's
    connectedComponentsWithStats costs ~10x its plain labelling here (and the masks are
    sparse), and so did selecting the kept labels with np.isin over the whole frame.
    """
    mask = np.ascontiguousarray(mask)
    n, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    if n <= 1:
        return []
    idx = np.flatnonzero(mask)
    lab = labels.ravel()[idx]
    order = np.argsort(lab, kind="stable")
    idx, lab = idx[order], lab[order]
    ys, xs = np.divmod(idx, mask.shape[1])
    starts = np.flatnonzero(np.diff(lab, prepend=-1))
    width = np.maximum.reduceat(xs, starts) - np.minimum.reduceat(xs, starts) + 1
    height = np.maximum.reduceat(ys, starts) - np.minimum.reduceat(ys, starts) + 1
    ends = np.append(starts[1:], lab.size)
    return [np.column_stack([xs[a:b], ys[a:b]]).astype(float)
            for a, b, long_ in zip(starts, ends, np.hypot(width, height) >= min_len, strict=True)
            if long_]


def _pca_line(pts: np.ndarray, centre: np.ndarray) -> tuple[float, float, np.ndarray, float]:
    # The means as np.mean takes them (the sum's reduction, then a true division by the
    # count) without its Python wrapper (~10 us a call of ~40): the same bits.
    m = np.add.reduce(pts, axis=0) / pts.shape[0]
    # np.cov's own steps (centre again, X X^T, times 1/(n-1)) without its argument handling
    # (~40 % of this function's time; it runs ~1000-3000 times on a busy photo): the same
    # matrix to the bit.
    X = np.array((pts - m).T, dtype=np.float64)
    X -= (np.add.reduce(X, axis=1) / X.shape[1])[:, None]
    cov = np.dot(X, X.T.conj())
    cov *= np.true_divide(1, X.shape[1] - 1)
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
MAX_LENGTH_FRACTION = 0.8
"""The longest shortest-mark length an image allows, as a fraction of its smaller side (a
mark must fit with its faded ends inside the frame)."""


def default_min_length(shape: tuple[int, int]) -> float:
    """The shortest mark searched for in an image (or roi) of this shape [px]:
    :data:`MIN_LENGTH_PX`, at most :data:`MAX_LENGTH_FRACTION` of the smaller side."""
    return min(MIN_LENGTH_PX, MAX_LENGTH_FRACTION * min(shape))


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
    first: tuple[MarkCandidate, ...] = ()
    """The first search's coarse candidates (at its ``min_length_px``), confirmed or not: a
    second pass at a shorter length splits some lines differently (a numeral's strokes beside
    a line's end become pieces of it there), so it looks at these too."""
    pieces: dict = field(default_factory=dict, compare=False, repr=False)
    """Each layer's merged pieces and their lines per piece length (see
    :func:`_candidates`), shared by the searches ``replace`` makes of this one: the passes
    for shorter lines (:mod:`imaging.families`) mostly ask for the same piece length (the
    3 px floor), whose components, splits and merges (~0.8 s CPU on building.jpg) are the
    same each time."""

    def candidates(self, min_length_px: float, keep=None) -> list[MarkCandidate]:
        """Coarse candidates at least ``min_length_px`` long (whole-image coordinates are
        applied by :meth:`confirm`), those ``keep(c)`` accepts, strongest first."""
        return _candidates(self.layers, min_length_px, self.f, self.centre_small,
                           self.image.shape, self.min_fill, keep, self.pieces)

    def confirm(self, cands: list[MarkCandidate], reach: float = 60.0) -> list[MarkCandidate]:
        """Full-resolution checks (pixel SNR, distinctness within ``reach`` px beside each
        candidate), in whole-image coordinates."""
        out = confirm_candidates(self.image, cands, self.noise_full, self.f, self.top,
                                 self.min_pixel_snr, reach)
        return [_shift(c, self.shift) for c in out] if self.shift.any() else out


def search_factor(shape: tuple[int, int], min_length_px: float) -> int:
    """The block factor of the coarse search of an image (or roi) of ``shape``.

    The search only seeds the sub-pixel fit, so it runs on a block-averaged copy; the
    shortest mark must stay >= ~25 blocks long there, or short marks in large frames drown.
    Frames under 1000 px are averaged 2 x 2 from 640 px on (a 640 x 480 frame searched at
    full resolution cost more than a 5 MP one at f = 5)."""
    side = max(shape)
    return max(1, min(int(side // 500 if side >= 1000 else side // 320), int(min_length_px // 25)))


def detect_lines_once(image: np.ndarray, min_length_px: float | None = None,
                      snr_threshold: float = 8.0, roi: Roi | None = None,
                      min_fill: float = 0.5, min_pixel_snr: float = 2.4,
                      top: float | None = None, noise_full: float | None = None,
                      block_means: np.ndarray | None = None) -> Search:
    """The search of :func:`detect_marks` (same parameters), every confirmed line kept.
    ``noise_full``: the pixel noise of the searched image's central 1024 px square
    (:func:`imaging.ridge.pixel_noise`), ``block_means``: its f x f block means as float64
    (:func:`imaging.framepass.frame_pass`), when the caller has them."""
    # The measurement of every line allocates and frees the same 0.1-2 MB temporaries over
    # and over: fresh mmap pages each time, unless freed memory is kept (~15 % of a 5 MP
    # image's CPU was page faults: the ridge filter at 640x480 took 2.5 ms, 0.5 ms without).
    reuse_freed_memory()
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
    f = search_factor((h, w), min_length_px)
    hs, ws = h // f, w // f
    small = image[:hs * f, :ws * f]
    if block_means is not None and block_means.shape == (hs, ws):
        small = block_means  # (the caller's, of the same pixels: imaging.framepass)
    elif f > 1:
        # INTER_AREA with an integer factor on an exactly divisible crop is the f x f block
        # mean (OpenCV's is ~10x faster than numpy's reshape-mean here). Taken of float64
        # pixels as they are (not of a float32 copy of all of them: half the time at 5 MP):
        # the same block means to the bit for whole-number pixels (any image read from an
        # integer file), within float32 rounding (< 3e-7) for others.
        if small.dtype != np.float64:
            small = small.astype(np.float32)
        small = cv2.resize(small, (ws, hs), interpolation=cv2.INTER_AREA)
    small = small.astype(np.float32)
    centre_small = np.array([(ws - 1) / 2, (hs - 1) / 2])
    noise = pixel_noise(small)
    layers = []
    for sigma in (1.5, 3.0):
        pad = int(np.ceil(4 * sigma)) + 2
        r, flat = ridge_response(odd_pad(small, pad), sigma)
        r, flat = r[pad:pad + hs, pad:pad + ws], flat[pad:pad + hs, pad:pad + ws]
        # Threshold against the pixel noise carried through the filter, not the spread of
        # the response (which clutter dominates in a busy scene); the MAD is the fallback
        # and a floor relative to the strongest response keeps noise-free images workable.
        sub = r[::3, ::3]  # the spread needs no more than a ninth of the pixels
        mad = min(median_abs_deviation(sub) * 1.4826,
                  noise * ridge_gain(sigma))
        mad = max(mad, 1e-3 * float(np.abs(r).max()))
        if mad <= 0:
            continue
        for dark in (True, False):
            resp = r if dark else -r
            layers.append((sigma, dark, resp, (resp > snr_threshold * mad) & flat, mad))
    if noise_full is None:
        noise_full = pixel_noise(central(image, 1024))
    top = full_scale(image) if top is None else top
    shift = np.zeros(2)
    if roi is not None:
        shift = np.array([x0 + (w - 1) / 2 - (w_full - 1) / 2, y0 + (h - 1) / 2 - (h_full - 1) / 2])
    search = Search([], image, shift, f, layers, centre_small, noise_full, top, min_fill,
                    min_pixel_snr)
    first = search.candidates(min_length_px)
    return replace(search, marks=search.confirm(first), first=tuple(first))


def _candidates(layers, min_length_px: float, f: int, centre_small: np.ndarray,
                shape: tuple[int, int], min_fill: float, keep=None,
                memo: dict | None = None) -> list[MarkCandidate]:
    """Long thin components of the ridge masks, as coarse candidates, strongest first.
    ``memo``: each layer's merged pieces with their lines, by (layer, piece length), their
    coarse candidates, and the fused-ridge coverage of the last list ranked, kept across
    calls (:attr:`Search.pieces`)."""
    h, w = shape
    best: list[MarkCandidate] = []
    memo = {} if memo is None else memo
    # Pieces down to an eighth of the shortest mark: a wide or dusty mark breaks up.
    piece = max(3.0, min_length_px / f / 8)
    for i, (sigma, dark, resp, mask, mad) in enumerate(layers):
        if (i, piece) not in memo:
            memo[i, piece] = _merge(_split_crossings(_components(mask, piece), piece),
                                    centre_small, resp)
        # The response fades below the threshold about a filter width before each end of a
        # faint, blurred mark: the length is judged with that back (_coarse's reach), and
        # with LENGTH_SLACK (a 100 px mark at SNR 8 keeps ~85 px of ridge).
        least = LENGTH_SLACK * min_length_px
        if memo.get(("coarse", i, piece), (np.inf,))[0] > least:
            memo["coarse", i, piece] = (least, _coarse(memo[i, piece], sigma, dark, resp,
                                                       mad, f, centre_small, (h, w),
                                                       min_fill, least))
        best += [c for reach, c in memo["coarse", i, piece][1]
                 if not reach < least and (keep is None or keep(c))]
    ranked = sorted(best, key=lambda c: -c.strength)
    last = memo.get(("fused", piece))
    if keep is not None:
        return _dedupe(_drop_fused(ranked))
    if last is None or last[0] > min_length_px:
        memo["fused", piece] = (min_length_px, ranked, covers := fused_covers(ranked))
        return _dedupe(unfused(ranked, covers))
    # A longer floor over the same pieces (a family's members: 11.36 then 11.40 px on
    # building.jpg) ranks a sublist of the same candidates (the same objects, in the same
    # order): the lines covering each are those of the longer list still in it, without
    # its ~400 coverage tests again (~35 ms CPU there).
    _, longer, covers = last
    at = {id(c): k for k, c in enumerate(ranked)}
    return _dedupe(unfused(ranked, [[at[id(longer[j])] for j in covers[k]
                                     if id(longer[j]) in at]
                                    for k, c in enumerate(longer) if id(c) in at]))


def _coarse(lines, sigma: float, dark: bool, resp: np.ndarray, mad: float, f: int,
            centre_small: np.ndarray, shape: tuple[int, int], min_fill: float, least: float
            ) -> list[tuple[float, MarkCandidate]]:
    """One layer's merged pieces (:func:`_merge`) thin and filled enough, as coarse
    candidates, each with its reach, its length and the filter width faded at both ends
    [px], at least ``least`` (what the length floor is compared with: a longer floor takes
    those of these it passes)."""
    h, w = shape
    out = []
    for pts, (a, d, t, thick) in lines:
        length = (t.max() - t.min()) * f
        if length + 2 * sigma * f < least or thick * f > 0.25 * length:
            continue
        fill = np.unique(np.floor(t)).size / (np.floor(t.max()) - np.floor(t.min()) + 1)
        if fill < min_fill:
            continue
        contrast = float(resp[pts[:, 1].astype(int), pts[:, 0].astype(int)].mean() / mad)
        out.append((length + 2 * sigma * f,
                    _to_full(a, d, t, dark, thick, contrast * length, f, centre_small,
                             np.array([(w - 1) / 2, (h - 1) / 2]), contrast)))
    return out

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
           ) -> list[tuple[np.ndarray, tuple]]:
    """Join collinear pieces (a mark interrupted by dust or a dropout, or by the fused ridge
    where another mark crosses it: ``resp``, the ridge response, tells the gap is bridged).
    Each line's points with their :func:`_pca_line`: a piece joined to none keeps the one
    computed here (its points are the same: on a busy photo most are alone, and the fit
    cost ~0.1 s CPU a pass again)."""
    lines = [(_pca_line(c, centre), c) for c in comps if len(c) >= 5]
    lines.sort(key=lambda x: -len(x[1]))
    angles = np.array([ln[0][0] for ln in lines])
    # Each piece's mean point (from centre): a piece's largest distance from a line is at
    # least its mean point's, so one whose mean point lies 3 px or more (+1e-6 for the
    # rounding) off this piece's line fails the test below for certain. On a busy photo
    # most near-parallel pieces are other lines of a row (~1/3 of this function's CPU).
    if lines:
        sizes = np.array([len(ln[1]) for ln in lines])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        mids = np.add.reduceat(np.vstack([ln[1] for ln in lines]), starts) / sizes[:, None]
        mids -= centre
    used = [False] * len(lines)
    out = []
    for i, (line, pts) in enumerate(lines):
        if used[i]:
            continue
        a, d = line[0], line[1]
        group = [pts]
        uu, nn = line_frame(a)
        tg = pts @ uu
        tg_lo, tg_hi = float(tg.min()), float(tg.max())
        # Only near-parallel pieces can join: the direction test for all of them at once
        # (the pairwise loop below is what made this quadratic step slow on cluttered frames).
        dang = np.abs((angles[i + 1:] - a + np.pi / 2) % np.pi - np.pi / 2)
        near = i + 1 + np.flatnonzero(dang < np.deg2rad(3) + 1e-12)
        for j in near[np.abs(mids[near] @ nn - d) < 3.0 + 1e-6]:
            if used[j] or abs(wrap_angle(lines[j][0][0] - a)) >= np.deg2rad(3):
                continue
            pj = lines[j][1]
            if not np.max(np.abs((pj - centre) @ nn - d)) < 3.0:  # own normal, this piece
                continue
            # Dust or a dropout leaves a gap shorter than the mark's pieces; a collinear
            # stroke far along the line (a logo, the next mark of a row) is another thing.
            tj = pj @ uu
            gap = max(float(tj.min()) - tg_hi, tg_lo - float(tj.max()))
            if gap <= max(tg_hi - tg_lo, float(np.ptp(tj))) or (resp is not None and _bridged(
                    resp, *_gap_ends(np.vstack(group), pj, uu),
                    0.5 * _level(resp, np.vstack(group)))):
                group.append(pj)
                used[j] = True
                tg_lo, tg_hi = min(tg_lo, float(tj.min())), max(tg_hi, float(tj.max()))
        out.append((pts, line) if len(group) == 1 else
                   (merged := np.vstack(group), _pca_line(merged, centre)))
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
