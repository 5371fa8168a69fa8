"""One mark, end to end: detection -> band profile fit -> per-segment centres -> line fit.

This is the declared model only (a straight line in the undistorted image). The residual loop
in :mod:`align.marks` adds effects (distortion, wiggle, illumination) on top of
:class:`MarkMeasurement`, which carries the centres and their regressors.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import median_filter

from imaging.asymmetry import AsymmetryTest, asymmetry_angle
from imaging.band import band_indices, band_mask
from imaging.camera import CameraModel
from imaging.centres import MISFIT_CHI2, Centres, sample_centres
from imaging.clipped import clipped_notes
from imaging.confirm import shadow_note
from imaging.crossmask import MIN_SEGMENTS, crossing_skip, fused_error, segments_needed
from imaging.defocus import BlurTrend, blur_trend
from imaging.detect import (
    LENGTH_SLACK,
    MarkCandidate,
    Roi,
    default_min_length,
    detect_lines_once,
    line_frame,
    require_single,
    wrap_angle,
)
from imaging.ends import EndsCheck, centres_stretch, groove_path, path_u
from imaging.errors import ImageInputError
from imaging.families import detect_lines
from imaging.framepass import stage_pass
from imaging.grating import grating_note
from imaging.groove import ProfileFit
from imaging.io import JpegTables, clipped_note, full_scale
from imaging.jpeg import find_jpeg
from imaging.jpeg_turn import JpegTurn
from imaging.linefit import LineFit, fit_line, fit_line_only
from imaging.median import median, median_inplace
from imaging.oriented import OrientedStripes, find_oriented, oriented_note, oriented_square
from imaging.profile import extent_look, fit_profile, groove_extent
from imaging.ridge import central, pixel_noise
from imaging.shape import profile_angle_u
from imaging.stripes import Stripes, find_stripes, stripes_notes
from imaging.surroundings import ALONE, Surroundings, surroundings_of
from imaging.texture import correlation_cholesky


@dataclass(frozen=True)
class MarkMeasurement:
    """A measured mark: its centres (undistorted if a camera model was given) and line fit.

    ``points``: (N, 2) centres [px] relative to the image centre; ``sigma``: (N,) [px];
    ``regressors``: per-point arrays for the residual loop (``t`` along the line [px],
    ``x``/``y`` [px], ``r2`` squared distance from the image centre [px^2], ``cross_slope``
    local illumination slope / contrast [1/px]); ``chol``: lower Cholesky factor of the
    centres' correlation matrix when surface texture (or removed stripes' offsets,
    :mod:`imaging.stripes`) correlates their errors along the mark (None: independent), for
    generalised least squares; ``sigma`` then includes their share of the variance;
    ``blur``: the blur's trend along the mark (a defocus gradient, :mod:`imaging.defocus`;
    None: too few segments to tell); ``around``: the frame around it as measured (its
    ``jpeg``: the JPEG encoder the image shows, None: none) and ``jpeg_u_rad`` how far its
    blocks move this mark's angle [rad] (:mod:`imaging.jpeg`; a Type B term, computed when
    first read). ``extent_px``: where the groove ends along the
    profile's line (raw image); ``ends_px``: those two ends as (2, 2) points like ``points``
    (relative to the image centre, undistorted if a camera model was given): a bent mark's
    chord and a ruled scale's line middles are read between them.
    ``background_u_rad``: what the removal of an oriented striped background may leave on
    the angle [rad] (:mod:`imaging.oriented`; a Type B term, 0 when none was found);
    ``ends_check``: the groove's ends' obstruction check made while measuring it (None: not).

    Attributes
    ----------
    candidate : MarkCandidate
        The detection it started from.
    profile : ProfileFit
        The band fit of the groove.
    centres : Centres
        The per-segment centres.
    points : ndarray
        (N, 2) centres used [px].
    sigma : ndarray
        (N,) their standard uncertainty across the line [px].
    regressors : dict of str to ndarray
        Per-point regressors of the residual loop (units above).
    line : LineFit
        The straight-line fit.
    image_shape : tuple of int
        (rows, columns) of the image [px].
    n_rejected : int
        Centres rejected as outliers.
    chol : ndarray or None
        Cholesky factor of the centres' correlation (None: independent).
    extent_px : tuple of float
        Where the groove ends along the profile's line [px].
    blur : BlurTrend or None
        The blur's trend along the mark.
    around : Surroundings
        The frame around it (:mod:`imaging.surroundings`), for measuring it again.
    jpeg_turn : JpegTurn or None
        What its blocks add to the angle's u, read as ``jpeg_u_rad`` [rad].
    ends_px : ndarray or None
        (2, 2) ends [px].
    crossings : tuple of tuple of int
        (other candidate, px of this mark left out) per crossing.
    background_u_rad : float
        What an oriented background's removal may leave on the angle [rad].
    profile_u_rad : float
        What the groove's own profile, sampled at the pixel grid's phase, may do to the
        angle [rad] (:func:`imaging.shape.profile_angle_u`; a Type B term).
    ends_check : EndsCheck or None
        Its ends' obstruction check, when made.
    asymmetry : AsymmetryTest or None
        Its asymmetry's change along it: :func:`imaging.asymmetry.asymmetry_angle`.
    """

    candidate: MarkCandidate
    profile: ProfileFit
    centres: Centres
    points: np.ndarray
    sigma: np.ndarray
    regressors: dict[str, np.ndarray]
    line: LineFit
    image_shape: tuple[int, int]
    n_rejected: int = 0
    chol: np.ndarray | None = None
    extent_px: tuple[float, float] = (float("nan"), float("nan"))
    blur: BlurTrend | None = None
    around: Surroundings = ALONE
    jpeg_turn: JpegTurn | None = None
    ends_px: np.ndarray | None = None
    crossings: tuple[tuple[int, int], ...] = ()
    """(index of the other candidate, px of this mark's length left out) per crossing."""
    background_u_rad: float = 0.0
    profile_u_rad: float = 0.0
    ends_check: EndsCheck | None = None
    asymmetry: AsymmetryTest | None = None

    jpeg_u_rad = property(lambda self: self.jpeg_turn.u_rad if self.jpeg_turn else 0.0)
    jpeg = property(lambda self: self.around.jpeg)
    """The JPEG encoder the image shows (None: none)."""
    @property
    def length_px(self) -> float:
        """The groove's length between its half-depth ends [px] (:func:`groove_extent`)."""
        return float(self.extent_px[1] - self.extent_px[0])


def _usable(cen: Centres, where: str, cand: MarkCandidate,
            skip: np.ndarray | None = None) -> np.ndarray:
    """Segments that fit the groove and agree with their neighbours (dust, scratches out; how
    many: crossmask.segments_needed); ``skip``: left out beforehand (another mark crosses)."""
    if skip is not None:
        cen = replace(cen, ok=cen.ok & ~skip)
    if cen.ok.sum() < MIN_SEGMENTS:
        raise ImageInputError(f"{where}: mark at offset {cand.offset_px:.0f} px: too few "
                              "usable segments along it (blurred away or covered)")
    # Segments whose pixels fit the groove much worse than the typical segment: dust or a
    # crossing scratch. Relative to the median so a misjudged noise level cannot empty it.
    typical = float(median(cen.chi2_red[cen.ok]))
    keep = cen.ok & (cen.chi2_red < MISFIT_CHI2 * max(1.0, typical))
    # Segments whose background just beside the groove is disturbed (a dust speck or a
    # scratch in the ring where the illumination slope is read): their centre and their
    # slope regressor are moved by the same speck, which the loop would read as an effect.
    # Uneven light changes the slope smoothly, never by 6 robust deviations at one segment.
    g = cen.cross_slope
    med = float(median(g[keep])) if keep.any() else 0.0
    mad = 1.4826 * float(median_inplace(np.abs(g[keep] - med))) if keep.any() else 0.0
    if mad > 0:
        keep &= np.abs(g - med) <= 6 * mad
    if keep.sum() < (need := segments_needed(int(cen.ok.sum()))):
        raise ImageInputError(f"{where}: mark at offset {cand.offset_px:.0f} px: too few "
                              "segments fit the groove model (covered, or not a groove)")
    idx = np.flatnonzero(keep)
    inl = local_inliers(cen.xy[idx], cen.sigma[idx], cen.t[idx])
    if inl.sum() < need:
        raise ImageInputError(f"{where}: mark at offset {cand.offset_px:.0f} px: too few "
                              "consistent centres along it")
    use = np.zeros_like(keep)
    use[idx[inl]] = True
    return use


def measure_candidate(image: np.ndarray, cand: MarkCandidate, camera: CameraModel | None = None,
                      where: str = "image", top: float | None = None,
                      around: Surroundings = ALONE) -> MarkMeasurement:
    """Measure one detected mark to sub-pixel precision (declared model: straight line).

    ``top``: the image's full-scale DN when already known (else from the image); ``around``:
    the frame around it (:class:`imaging.surroundings.Surroundings`: the lines beside it,
    the marks that may cross it, the file's JPEG encoder, the removed stripes' offsets),
    kept with the measurement for every measurement of it again. A candidate seen as two
    fused grooves is refused.

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN].
    cand : MarkCandidate
        The detected mark.
    camera : CameraModel, optional
        A camera model: the centres are undistorted with it.
    where : str
        The image, as messages name it.
    top : float, optional
        Full scale [DN].
    around : Surroundings
        The frame around the mark (default: alone).

    Returns
    -------
    MarkMeasurement
        The centres, their covariance and the line fit.

    Raises
    ------
    ImageInputError
        A mark that cannot be measured (naming ``where`` and why).
    """
    if cand.fused is not None:
        raise fused_error(cand, where, image.shape)
    top = full_scale(image) if top is None else top
    pf = fit_profile(image, cand, where, top)
    cen = sample_centres(image, pf, every=4 if cand.length_px > 400 else 1, where=where)
    skip, crossed = crossing_skip(image, cen, pf, around.crossing, top, where, look=False)
    use = _usable(cen, where, cand, skip)
    # Second pass about the line through the first centres: the final centres never depend
    # on how well the band fit placed the line (cheap: the profile is tabulated).
    # (Its direction and offset only: fit_line's, the same bits, without the covariance.)
    pf = pf.with_line(*fit_line_only(cen.xy[use], cen.sigma[use]))
    u, n = line_frame(pf.angle_rad)
    # Where the groove really ends, looked for once, before the full pass, along the first
    # centres' path (the full pass's to a fraction of a pixel): the detector's stretch stops
    # ~24 px (640 x 480) to ~40 px (5 MP) short of a mark's ends (its ridge fades a filter
    # width of the search before them), and the full pass runs once, over the whole groove
    # out to its ends (centres_stretch: a 300 px mark's centres spanned 248 px, its angle
    # 1.5x its bound with a lens's k1 free). The ends' check made here is kept. The ends
    # read along the path are taken where they turn its chord, or change the bow they
    # span, by more than u/4 of what the first centres read of them (their scatter about
    # the path in it: a JPEG's blocks').
    path = groove_path(cen, pf)
    tol = tuple(0.25 * v for v in path_u(cen, pf))
    look = extent_look(image, pf, path=path, tol=tol)
    longer, check, on = centres_stretch(image, pf, look[:2], look[2:], cen, around.crossing)
    if longer is not None:
        pf = replace(pf, t_start_px=longer[0], t_end_px=longer[1])

    def full_pass(pf, cen, use):
        # The centres over pf's stretch, started from the previous centres (a bowed
        # groove's ends are far from any straight line through it), their crossings and use.
        cen = sample_centres(image, pf, where=where, texture=True, avoid_px=around.neighbours_px,
                             guess=(cen.xy[use] @ u, cen.xy[use] @ n - pf.offset_px),
                             offsets_var=around.offsets_var, departure=True)
        skip, crossed = crossing_skip(image, cen, pf, around.crossing, top, where)
        return cen, crossed, _usable(cen, where, cand, skip)

    cen, crossed, use = full_pass(pf, cen, use)
    # (The check depends on the profile's line and shape, not on its stretch.)
    check = replace(check, profile=pf, centres=cen)
    ext = look[:2]
    if any(on):
        # The groove ran on past the look (an end the first look could not follow): its
        # extent looked for again from the longer stretch, and the centres sampled once more
        # when it runs on further still.
        t0, t1, open0, open1 = extent_look(image, pf, path=groove_path(cen, pf), tol=tol)
        ext = (t0, t1)
        longer, check, on = centres_stretch(image, pf, ext, (open0, open1), cen,
                                            around.crossing)
        if any(on) and longer is not None:
            pf = replace(pf, t_start_px=longer[0], t_end_px=longer[1])
            cen, crossed, use = full_pass(pf, cen, use)
            ext = groove_extent(image, pf, path=groove_path(cen, pf), tol=tol)
            check = None  # (made on the shorter stretch)
    pts, sig = cen.xy[use], cen.sigma[use]
    if camera is not None:
        pts, sig = camera.undistort_centred(pts, sig, image.shape)
    chol = None
    if cen.texture is not None and cen.texture.acf is not None:
        scale, chol = correlation_cholesky(cen.texture.acf, np.flatnonzero(use))
        sig = sig * scale
    if cen.offsets_cov is not None:
        sig, chol = _with_offsets(sig, chol, cen.offsets_cov[np.ix_(use, use)],
                                  sig / cen.sigma[use] if camera is not None else None)
    regs = {"t": cen.t[use], "x": pts[:, 0], "y": pts[:, 1], "r2": (pts**2).sum(1),
            "cross_slope": cen.cross_slope[use]}
    line = fit_line(pts, sig, reject_sigma=None, chol=chol)
    blur = (blur_trend(cen.t[use], cen.blur_dev[use], cen.blur_dev_u[use], pf.blur_px)
            if cen.blur_dev is not None else None)
    prof = (profile_angle_u(cen.t[use], sig, cen.profile_shift[use],
                            cen.profile_shift_cov[np.ix_(use, use)])
            if cen.profile_shift is not None else 0.0)
    asym = cen.asymmetry and asymmetry_angle(cen.asymmetry, use, cen.t[use], sig)
    return MarkMeasurement(cand, pf, cen, pts, sig, regs, line, image.shape,
                           int(cen.ok.sum() - use.sum()), chol, ext,
                           blur, around, JpegTurn(image.shape, pf, around.jpeg, cen.xy[use]),
                           ends_on_line(pf, ext, line, camera, image.shape), crossed,
                           profile_u_rad=prof, ends_check=check, asymmetry=asym)


def _with_offsets(sig: np.ndarray, chol: np.ndarray | None, C: np.ndarray,
                  gain: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The centres' sigma and correlation factor with removed stripes' offsets' covariance
    ``C`` [px^2] added (``gain``: the undistortion's magnification per centre, if any)."""
    if gain is not None:
        C = C * np.outer(gain, gain)
    R = chol @ chol.T if chol is not None else np.eye(len(sig))
    total = sig[:, None] * R * sig[None, :] + C
    s = np.sqrt(np.diag(total))
    R = total / np.outer(s, s)
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        L = np.linalg.cholesky(R + 1e-6 * np.eye(len(R)))
    return s, L


def ends_on_line(pf: ProfileFit, extent: tuple[float, float], line: LineFit,
                camera: CameraModel | None, shape: tuple[int, int]) -> np.ndarray:
    """The groove's two ends (half-depth, ``extent`` along the profile's line) as points on
    the measured ``line`` [px, relative to the image centre]: undistorted by the camera, then
    put on the line (the profile's line is the raw image's chord, off a mark the lens bows
    by up to its sagitta at the ends; only the position along the line is read from it)."""
    u, n = line_frame(pf.angle_rad)
    ends = np.array([pf.offset_px * n + t * u for t in extent])
    if camera is not None:
        ends = camera.undistort_centred(ends, np.ones(2), shape)[0]
    return on_line(ends, line.angle_rad, line.offset_px)


def on_line(p: np.ndarray, angle_rad: float, offset_px: float) -> np.ndarray:
    """Points ``p`` (N, 2) moved across onto the line (angle, offset) [px].

    Parameters
    ----------
    p : ndarray
        (N, 2) points [px].
    angle_rad : float
        The line's direction [rad].
    offset_px : float
        Its signed distance from the origin [px].

    Returns
    -------
    ndarray
        (N, 2) points on the line [px].
    """
    u, n = line_frame(angle_rad)
    return offset_px * n + np.outer(p @ u, u)


def local_inliers(pts: np.ndarray, sigma: np.ndarray, t: np.ndarray, k: float = 5.0,
                  window: int = 15) -> np.ndarray:
    """Points that agree with their neighbours along the mark (dust, scratch crossings out).

    Compared with a running median of the straight-line residual, so a smooth bow
    (distortion, a bent mark) is kept for the residual loop while local outliers go.
    """
    order = np.argsort(t)
    base = fit_line(pts, sigma, reject_sigma=None)
    r = np.empty(len(pts))
    r[base.used] = base.residuals_px
    rs = r[order]
    med = median_filter(rs, size=min(window, len(rs) // 2 * 2 + 1), mode="nearest")
    dev = rs - med
    scale = np.maximum(sigma[order], 1.4826 * np.median(np.abs(dev)))
    ok = np.empty(len(pts), bool)
    ok[order] = np.abs(dev) <= k * scale
    return ok


@dataclass(frozen=True)
class MeasuredFrame:
    """Every line of one image measured: ``items`` (a measurement or the error that stopped
    it, per reported line), ``families`` (index tuples into ``items``, see
    :mod:`imaging.families`), ``unreported`` (lines found but not reported: beyond
    ``max_marks``; a line the measurement finds shorter than the shortest mark is no mark
    and not counted); ``notes``: what the frame's background did (stripes found, removed or
    carried: :mod:`imaging.stripes`, :mod:`imaging.oriented`), one line each; ``stripes``:
    the row/column findings; ``oriented``: the oriented periodic background's.

    Attributes
    ----------
    items : list of MarkMeasurement or ImageInputError
        Per reported line.
    families : tuple of tuple of int
        Indexes into ``items``, one tuple per family.
    unreported : int
        Lines found but not reported.
    notes : tuple of str
        What the background did.
    stripes : tuple of Stripes
        The row / column stripes' findings.
    oriented : OrientedStripes or None
        The oriented periodic background's.
    """

    items: list[MarkMeasurement | ImageInputError]
    families: tuple[tuple[int, ...], ...] = ()
    unreported: int = 0
    notes: tuple[str, ...] = ()
    stripes: tuple[Stripes, ...] = ()
    oriented: OrientedStripes | None = None


def measure_marks(image: np.ndarray, camera: CameraModel | None = None, where: str = "image",
                  max_marks: int = 8, min_length_px: float | None = None,
                  expect_one: bool = False, roi: Roi | None = None
                  ) -> list[MarkMeasurement | ImageInputError]:
    """Detect and measure every mark in an image; per-mark failures are returned, not raised.

    With ``expect_one`` the image must hold a single mark: two of similar strength raise.
    ``roi`` (x, y, w, h) [px] and ``min_length_px`` restrict the search (see detect_marks).

    Parameters
    ----------
    image : ndarray
        Grayscale image [DN].
    camera : CameraModel, optional
        A camera model (centres undistorted).
    where : str
        The image, as messages name it.
    max_marks : int
        Most marks measured.
    min_length_px : float, optional
        Shortest mark [px].
    expect_one : bool
        The image must hold one mark.
    roi : Roi, optional
        (x, y, w, h) [px] searched.

    Returns
    -------
    list of MarkMeasurement or ImageInputError
        Per mark, its measurement or why it could not be measured.
    """
    return measure_frame(image, camera, where, max_marks, min_length_px, expect_one,
                         roi).items


def measure_frame(image: np.ndarray, camera: CameraModel | None = None, where: str = "image",
                  max_marks: int = 8, min_length_px: float | None = None, expect_one: bool = False,
                  roi: Roi | None = None, jpeg_tables: JpegTables | None = None) -> MeasuredFrame:
    """:func:`measure_marks` with the families of lines and the count of lines not reported.

    Every member of a family is measured (whatever ``max_marks``), and kept whatever its
    length: the family, not ``min_length_px``, says it is a line.

    Parameters
    ----------
    image, camera, where, max_marks, min_length_px, expect_one, roi, jpeg_tables
        As :func:`measure_marks`; ``jpeg_tables``: a JPEG file's header's (:func:`find_jpeg`).

    Returns
    -------
    MeasuredFrame
        The measurements, the families and what the background did.
    """
    # Integer pixels as read by OpenCV (uint16) wrapped around in the differences below: the
    # same frame as an array got u 1745" where its file got 5.3" (read_image: floats, no copy).
    image = raw = np.asarray(image, dtype=float)
    # The maximum once (each pass over 5 MP costs ~1.5-4 ms): when the whole frame is
    # searched, in one pass with what the search and the background tests read of all of it.
    fp = stage_pass(image, min_length_px) if roi is None else None
    mx, blocks = (fp.maximum, fp.block_means) if fp is not None else (float(image.max()), None)
    # (Uniform only if the first pixel is the maximum: the minimum's pass only then.)
    if mx == float(image.flat[0]) and mx == float(image.min()):
        raise ImageInputError(f"{where}: image is uniform (value {image.flat[0]:g}); no mark")
    top = full_scale(mx)
    # The clipped pixels, named below: a pass over the frame only when its maximum is at
    # full scale (else there are none: ~3 ms of a 5 MP frame's CPU, and the notes are ()).
    # (A NaN maximum: tested as before.)
    hot = None if mx < top else image >= top
    if camera is not None and (image.shape[1], image.shape[0]) != tuple(camera.image_size):
        raise ImageInputError(f"{where}: camera model is for {camera.image_size[0]}x"
                              f"{camera.image_size[1]} images, this one is {image.shape[1]}x"
                              f"{image.shape[0]}")
    # The oriented test's square, read once: the detector's noise comes from the same
    # central 1024 px (a second read of a 5 MP frame's strided float64 square cost ~1 ms).
    square = oriented_square(image, top, fp.copy32 if fp is not None else None)
    noise = (pixel_noise(square) if roi is None and square.shape == central(image, 1024).shape
             else None)
    try:
        det = detect_lines(image, min_length_px=min_length_px, max_marks=max_marks, roi=roi,
                           top=top, families=not expect_one, noise_full=noise,
                           block_means=blocks)
    except ImageInputError as exc:
        raise ImageInputError(f"{where}: {exc}") from None
    cands = det.marks
    # Stripes nearly along a mark can hide it from the detector: then the frame is tested
    # for an oriented periodic background (nothing masked) and searched again without it.
    pre = None
    if not cands:
        cleaned, pre = find_oriented(image, None, top, square=square)
        if pre.found:
            try:
                again = detect_lines(cleaned, min_length_px=min_length_px,
                                     max_marks=max_marks, roi=roi, top=top,
                                     families=not expect_one)
            except ImageInputError as exc:
                raise ImageInputError(f"{where}: {exc}") from None
            if again.marks:  # else the frame stays as it was (a grating is said below)
                det, cands, image = again, again.marks, cleaned
            else:
                pre = None
    if not cands:
        grating = grating_note(image)
        clipped = clipped_note(image, top)
        search = detect_lines_once(image, min_length_px, roi=roi, top=top)
        shadow = shadow_note(search.image, search.first, top)
        raise ImageInputError(f"{where}: no mark found (no long straight line stands out"
                              + (f" in roi {','.join(map(str, roi))})" if roi else ")")
                              + (f": {shadow}" if shadow else "")
                              + (f": {grating}" if grating else "")
                              + (f": {clipped}" if clipped else ""))
    if expect_one:
        cands = [require_single(cands, where)]
    # The JPEG encoder read on the file's own pixels (baseline JPEG is 8-bit): a background
    # divided out below leaves no integer pixels. Read after it, a JPEG array without its
    # header's tables was not found (its mark lost jpeg_blocks) and a file's pre-coding
    # noise was read off the divided pixels.
    jpeg = find_jpeg(raw, jpeg_tables) if top == 255 else None
    # The detector judges a ridge's length; the measured groove (half-depth ends) must be
    # as long: a faint streak's ridge can reach the length where the streak itself is
    # shorter (its length_px would then be below --min-length).
    shortest = LENGTH_SLACK * (min_length_px if min_length_px is not None else
                               default_min_length(image.shape if roi is None else roi[:1:-1]))
    member = {i for g in det.families for i in g}
    # The lines' bands, left out of both background tests: one mask for the frame.
    bands = band_mask(image.shape, [band_indices(image, c) for c in (*cands, *det.unreported)])
    # Stripes at any angle (a surface's lay): divided out first — an oblique pattern leaves
    # a profile along the columns that the row/column test below would take for its own.
    image, oriented = find_oriented(image, bands, top,
                                    square=square if image is raw else None)
    if oriented.found and (pre is None or not pre.found):
        # The lines again on the image without the pattern: a crest beside a mark's end
        # moves where the detector ends it (a 250 px mark was measured over 210 px).
        again = detect_lines(image, min_length_px=min_length_px, max_marks=max_marks,
                             roi=roi, top=top, families=not expect_one)
        if again.marks and (not expect_one or len(again.marks) == len(det.marks)):
            det = again
            cands = [require_single(det.marks, where)] if expect_one else det.marks
            member = {i for g in det.families for i in g}
            bands = band_mask(image.shape,
                              [band_indices(image, c) for c in (*cands, *det.unreported)])
    if pre is not None and pre.found:
        oriented = pre.then(oriented)
    # Row/column fixed-pattern noise: tested on the background away from every line found,
    # and removed when each line's columns (rows) have background to estimate it from.
    image, stripes = find_stripes(image, bands, top, samples=(
        (fp.rows, fp.columns) if fp is not None and fp.rows.size and image is raw else None))
    # Each angle carries what the oriented removal may leave of the change it made: the
    # mark measured again with the pattern put back.
    before = image * oriented.factor(image.shape) if oriented.found else image
    out: list[MarkMeasurement | ImageInputError] = []
    index: dict[int, int] = {}
    for i, c in enumerate(cands):
        try:
            args = (c, camera, where, top, surroundings_of(
                cands, i, jpeg, (stripes[0].offsets_var, stripes[1].offsets_var)))
            m = measure_candidate(image, *args)
        except ImageInputError as exc:
            index[i] = len(out)
            out.append(exc)
            continue
        if oriented.found:
            m = _with_background_u(m, before, args, oriented.residual)
        if m.length_px >= shortest or i in member:
            index[i] = len(out)
            out.append(m)
    if not out:
        raise ImageInputError(f"{where}: no mark found (the lines found are shorter than "
                              f"{shortest:.0f} px once measured)")
    # Crossings name the other mark by its place in the output, as the user sees it.
    out = [replace(m, crossings=tuple((index.get(j, j), n) for j, n in m.crossings))
           if isinstance(m, MarkMeasurement) and m.crossings else m for m in out]
    fams = tuple(tuple(index[i] for i in g if i in index) for g in det.families)
    contrast = [abs(m.profile.contrast_dn) for m in out if isinstance(m, MarkMeasurement)]
    notes = (stripes_notes(where, stripes, float(np.median(contrast)) if contrast else 0.0)
             + oriented_note(where, oriented) + (clipped_notes(
                 hot, top, where, [(index[i], c) for i, c in enumerate(cands) if i in index])
                 if hot is not None else ()))
    return MeasuredFrame(out, fams, len(det.unreported), notes, stripes, oriented)


def _with_background_u(m: MarkMeasurement, before: np.ndarray, args: tuple,
                       residual: float) -> MarkMeasurement:
    """``m`` with ``background_u_rad``: the angle change the removed pattern made (the mark
    measured again on the image before the removal, with :func:`measure_candidate`'s other
    arguments ``args``) times the fraction of the pattern the removal may leave. A mark the
    pattern made unmeasurable before the removal gives no change to scale: the term is then
    the angle's own u (the mark stands with u x sqrt 2)."""
    try:
        m0 = measure_candidate(before, *args)
    except ImageInputError:
        return replace(m, background_u_rad=float(m.line.angle_u_rad))
    d = abs(wrap_angle(m0.line.angle_rad - m.line.angle_rad))
    return replace(m, background_u_rad=float(residual * d))
