"""The JPEG encoder's turn of a mark's angle: the fitted groove, on the mark's own path and with
the noise the pixels had before coding, put through the encoder (:mod:`imaging.jpeg` finds
the encoder and reads that noise); the term ``jpeg_blocks``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from imaging.band import band_pixels
from imaging.candidate import line_frame
from imaging.centres import Centres, sample_centres, sample_centres_batch
from imaging.groove import ProfileFit, ProfileTable, centres_half
from imaging.jpeg import JpegBlocks, jpeg_round_trips
from imaging.jpeg_scatter import block_phase_columns

NOISE_DRAWS = 32
"""Noisy renders :func:`jpeg_angle_shift` puts through the encoder: the term's square, a
mean over the draws, then has a relative sd of sqrt(2 / 32) = 0.25 (its root ~0.12) where
the centres' own scatter is small; 8 draws gave 0-7" where 32 gave 21-22" (a quality-50
mark of user 13's). ~3 ms a draw on a 250 px mark, the draws measured together
(:func:`imaging.centres.sample_centres_batch`). Over seeds the term's sd is ~26 % of it
(the 17 real photos' near-axis marks); antithetic pairs and draws stratified along the
line's noise turn gave no smaller sd for the same number (docs/performance.md)."""


def jpeg_angle_shift(shape: tuple[int, int], pf: ProfileFit, jb: JpegBlocks | None,
                     centres: np.ndarray | None = None) -> float:
    """How far the JPEG encoder ``jb`` moves the angle of the fitted groove ``pf`` [rad], on
    an image of ``shape`` with its block grid (at ``jb.phase``): the model rendered there
    (on the mark's own path, :func:`mark_path`, through its ``centres``: x, y about the
    image's centre [px]) and measured before and after the round trip (the same segments,
    equal weights), through the file's own table when known (0 when ``jb`` is None: not a
    JPEG). Quality and table unknown: the largest shift over qualities 10, 20, ..., 90.

    The encoder quantises the edge's coefficients with the noise the pixels had before
    coding (``jb.noise_dn``, :func:`precoding_noise`): a coefficient near the edge of its
    bin goes one way or the other with the noise, so a noisy edge's centres move by more,
    and differently, than the noise-free model's. With that noise read, the model is
    rendered :data:`NOISE_DRAWS` times with it (a fixed seed: the same term for the same
    image), each through the encoder, and the term is the root of the mean over the draws
    of the turn's square (each coded draw's centres against the noise-free model's, as
    the mark's own error is: the encoder keeps the noise's slow part, which turns the line,
    and drops its fine detail, which the mark's scatter reads) less the share the coded
    centres' scatter carries (:func:`blocks_turn`),
    on marks near an axis (:func:`near_axis`: there the error is a turn). Else, or without
    that noise, the noise-free model once. Only the band's blocks are coded (the encoder
    codes each block alone: the rest of the frame changes nothing)."""
    if jb is None:
        return 0.0  # not a JPEG
    # Quality and table unknown: each quality's encoder on the same renders (the model and
    # its noisy draws do not depend on the encoder), the largest term taken.
    coders = ([replace(jb, quality=q) for q in range(10, 100, 10)]
              if jb.quality is None and jb.table is None else [jb])
    half = centres_half(pf) + 8.0
    e, idx = band_pixels(np.zeros(shape, np.uint8), pf, half, 30.0)
    if idx.size == 0:
        return 0.0
    rows, cols = np.unravel_index(idx, shape)
    e = e - mark_path(pf, centres, shape)(cols, rows)
    p, _ = ProfileTable(pf.width_px, pf.blur_px, pf.angle_rad, half + 2.0)(e)
    # The window: the band's blocks on the grid and a block more each way.
    (r0, r1), (c0, c1) = (_on_grid(v.min(), v.max(), ph, n) for v, ph, n in
                          ((rows, jb.phase[1], shape[0]), (cols, jb.phase[0], shape[1])))
    model = np.full((r1 - r0, c1 - c0), pf.background_dn)
    model[rows - r0, cols - c0] += pf.contrast_dn * p
    model = np.clip(model, 0.0, 255.0)
    phase = ((jb.phase[0] - c0) % 8, (jb.phase[1] - r0) % 8)
    u, n = line_frame(pf.angle_rad)
    shift = (np.array([c0 + c1, r0 + r1], float) - shape[::-1]) / 2  # the window's centre
    pfw = replace(pf, offset_px=pf.offset_px - float(shift @ n),
                  t_start_px=pf.t_start_px - float(shift @ u),
                  t_end_px=pf.t_end_px - float(shift @ u))
    renders = model[None]
    if jb.noise_dn > 0 and near_axis(pf):
        # (one call: the same normals, in the same order, as a call per draw)
        noise = np.random.default_rng(0).normal(0.0, jb.noise_dn, (NOISE_DRAWS, *model.shape))
        renders = np.clip(np.round(model + noise), 0, 255)
    # Every render's centres after each encoder, and the noise-free model's, in one pass (to
    # the bit each image's alone: sample_centres_batch); a table known by its IJG quality is
    # that encoder. Each coded draw is measured as the mark is: its turn from the noise-free
    # model's centres (the truth), less the share the scatter of its own coded centres
    # gives (as the mark's u reads its centres). Not from its own draw before coding: the
    # encoder quantises the noise with the edge, dropping the noise's fine detail (which
    # the centres' neighbour differences read) and keeping its slow part (which turns the
    # line), so the coded mark's scatter under-reads the noise's turn, and the coding's
    # turn follows the noise's (user 13's quality-75 near-axis marks over 8 noise seeds:
    # mean square error 1.2-1.4 x the square of u's noise and blocks pieces when the draws
    # took the turn from their own uncoded draw; with that draw's noise turn taken as the
    # scatter's and only its covariance with the coding's added, RMS z 1.62 on a sweep's
    # files where this gives 1.31 and the old way 1.48).
    coded = [jpeg_round_trips(renders, c.quality, c.table if c.quality is None else None,
                              phase) for c in coders]
    cen = sample_centres_batch(np.concatenate([model[None], *coded]), pfw)
    m = len(renders)
    return max(_term([centres_turn(cen[0], cen[1 + m * j + i], model.shape, pfw)
                      for i in range(m)]) for j in range(len(coders)))


@dataclass(frozen=True, eq=False)
class JpegTurn:
    """:func:`jpeg_angle_shift`'s arguments, its term computed when first read (``u_rad``)
    and kept: a candidate refused after it was measured (too short once measured, its
    removed background's re-measure, a shadow's or a kink's first measure) never pays
    for the noisy draws (0.1-0.3 s a mark). Copies of a measurement share the one value."""

    shape: tuple[int, int]
    profile: ProfileFit
    jpeg: JpegBlocks | None
    centres: np.ndarray | None = None

    @cached_property
    def u_rad(self) -> float:
        """The term [rad] (:func:`jpeg_bound_shift`)."""
        return jpeg_bound_shift(self.shape, self.profile, self.jpeg, self.centres)


def jpeg_bound_shift(shape: tuple[int, int], pf: ProfileFit, jb: JpegBlocks | None,
                     centres: np.ndarray | None = None) -> float:
    """:func:`jpeg_angle_shift` bounded over the qualities the pixels cannot exclude
    (``jb.candidates``, :func:`imaging.jpeg.quality_candidates`): the largest, each with
    the noise before coding read on its own table [rad]. Without candidates, ``jb``'s own.
    A quality read a few steps coarser than the encoder's carried 0" on marks whose own
    table gave 11-17" (user 13's quality-75 crops)."""
    if jb is None or not jb.candidates:
        return jpeg_angle_shift(shape, pf, jb, centres)
    return max(jpeg_angle_shift(shape, pf, replace(jb, quality=q, noise_dn=s, candidates=()),
                                centres) for q, s in jb.candidates)


NEAR_AXIS_ROWS = 4
"""Block rows (or columns) a mark's edge crosses along its length at most for the noisy
draws (:func:`near_axis`)."""


def near_axis(pf: ProfileFit) -> bool:
    """Whether the groove ``pf`` runs so near an axis that its edge crosses at most
    :data:`NEAR_AXIS_ROWS` block rows (columns) along its length: L sin(d) <= 8 x that [px]
    (d its angle from the nearest axis). The encoder's error at the edge follows the edge's
    place in its block: along such a mark that place drifts through a few periods at most,
    and the error is a turn; along a steeper one it cycles many times and averages out
    (the noise-free model's term, once, is then small), and 32 noisy draws (~0.1 s) would be
    spent on nothing."""
    d = pf.angle_rad % (np.pi / 2)
    return bool((pf.t_end_px - pf.t_start_px) * np.sin(min(d, np.pi / 2 - d))
                <= 8 * NEAR_AXIS_ROWS)


def _on_grid(lo: int, hi: int, phase: int, size: int) -> tuple[int, int]:
    """[start, stop) of pixels lo..hi widened to block boundaries (at phase + 8 k) and a
    block more each way, within 0..size."""
    start = phase + 8 * ((int(lo) - phase) // 8) - 8
    stop = phase + 8 * ((int(hi) - phase) // 8 + 2)
    return max(start, 0), min(stop, size)


PATH_DEGREE = 2
"""Degree of the polynomial in t the model's path follows (:func:`mark_path`): a lens bows a
straight groove (a sagitta of 0.2-0.7 px on a 250 px mark of the chessboard lens)."""


def mark_path(pf: ProfileFit, centres: np.ndarray | None, shape: tuple[int, int]):
    """The groove's path across its line, as a function of pixel column and row [px]: a
    polynomial in t (:data:`PATH_DEGREE`) fitted to its centres (x, y about the image's
    centre [px], as :func:`imaging.centres.sample_centres` gives them), 0 without them.

    The blocks' error at an edge depends on the edge's place in its block, so the model
    must cross the block grid where the mark does: a lens's bow of half a px moves a
    near-axis edge through half the phases a straight line would not (the noise-free
    straight model's turn was 0-20" where the bowed groove's was 12-16" mean, 21-41" RMS
    with noise, on user 13's quality-75 marks).
    """
    u, n = line_frame(pf.angle_rad)
    c = (np.array(shape[::-1], float) - 1) / 2
    if centres is None or len(centres) <= PATH_DEGREE + 2:
        return lambda x, y: np.zeros(np.shape(x))
    xy = np.asarray(centres, float)
    coef = np.polyfit(xy @ u, xy @ n - pf.offset_px, PATH_DEGREE)
    return lambda x, y: np.polyval(coef, (np.column_stack([x, y]) - c) @ u)


def _term(turns: list[tuple[float, float]]) -> float:
    """sqrt(max(0, mean(da^2) - mean(u_s^2))) over (da, u_s^2) pairs (:func:`blocks_turn`)."""
    da, us2 = np.array(turns, float).reshape(-1, 2).T
    return float(np.sqrt(max(0.0, np.mean(da**2) - np.mean(us2))))


def blocks_systematic(a_image: np.ndarray, b_image: np.ndarray, pf: ProfileFit) -> float:
    """The part of JPEG's angle shift on the groove ``pf`` (``a_image`` the model, ``b_image``
    it re-encoded) that its centres' scatter does not already carry [rad]:
    sqrt(max(0, da^2 - u_s^2)) of :func:`blocks_turn`."""
    return _term([blocks_turn(a_image, b_image, pf)])


def blocks_turn(a_image: np.ndarray, b_image: np.ndarray, pf: ProfileFit
                ) -> tuple[float, float]:
    """JPEG's turn of the groove ``pf`` (``a_image`` the model, ``b_image`` it re-encoded)
    and the share of it the centres' scatter carries: (da [rad], u_s^2 [rad^2]).

    The blocks move each centre by a pattern that repeats every block along the mark
    (:func:`block_phase_columns`, fitted with the line), by an amount that changes from
    block to block (scatter at the block scale, which :func:`jpeg_centre_scale` reads into
    the centres' sigma and so into the line's u) and by one that drifts with the edge's
    phase in the grid (the systematic).
    The line through the centres' moves turns by da; its scatter s about that line (by
    neighbour differences, as the mark's) would turn it by u_s = s / sqrt(sum (t - t_m)^2)
    alone. What stands beyond, da^2 - u_s^2, is the Type B term's square: counted once.
    Equal weights, the segments valid in both ((0, 0) when fewer than 10 are).
    """
    return centres_turn(sample_centres(a_image, pf), sample_centres(b_image, pf),
                        a_image.shape, pf)


def centres_turn(a: Centres, b: Centres, shape: tuple[int, int], pf: ProfileFit
                 ) -> tuple[float, float]:
    """:func:`blocks_turn` from the centres ``a`` of the model and ``b`` of it re-encoded,
    on images of ``shape``."""
    ok = a.ok & b.ok
    if ok.sum() < 10:
        return 0.0, 0.0
    u, n = line_frame(pf.angle_rad)
    t = a.xy[ok] @ u
    d = (b.xy[ok] - a.xy[ok]) @ n
    # The block pattern the mark's fit takes as known (jpeg_blocks_columns) is no scatter
    # the line's u holds: fitted here too, as there.
    axis = 0 if abs(u[0]) >= abs(u[1]) else 1
    along = a.xy[ok, axis] + (shape[1 - axis] - 1) / 2
    order = np.argsort(t)
    t, d, along = t[order], d[order], along[order]
    X = np.column_stack([np.ones_like(t), t - t.mean(), block_phase_columns(along)])
    beta, *_ = np.linalg.lstsq(X, d, rcond=None)
    r = d - X @ beta
    return float(beta[1]), float(np.mean(np.diff(r) ** 2) / 2 / np.sum((t - t.mean()) ** 2))
