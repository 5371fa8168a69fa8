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
from imaging.jpeg_scatter import block_phase_columns, posterior_factor

NOISE_DRAWS = 32
"""Noisy renders :func:`jpeg_angle_shift` puts through the encoder at a time: 8 draws gave
0-7" where 32 gave 21-22" (a quality-50 mark of user 13's). ~3 ms a draw on a 250 px mark,
the draws measured together (:func:`imaging.centres.sample_centres_batch`). Antithetic pairs
and draws stratified along the line's noise turn gave no smaller spread for the same number
(docs/performance.md)."""

TERM_REL_SD = 0.3
"""The sd of the term's square (:class:`TurnEstimate`) relative to the angle's u^2 it enters
(the rest of u and the term) below which no more draws are made: the Welch-Satterthwaite dof
of that u^2 then >= 2 / 0.3^2 = 22, its factor <= 1.1 (1.05 on u). On a mark whose u the
term makes, the term to ~15 %. 32 draws read 26 % on the term over seeds
(median; 14-60 %) on the 17 real photos' near-axis marks, and their squares are heavy
tailed (128 draws still read 0.2-0.4 on the square on building.jpg's marks): more draws
bring a mark's term towards its mean, and what spread remains goes into u."""

NOISE_SEED = 0
"""The draws' seed: the same term for the same image."""

MAX_DRAWS = 4 * NOISE_DRAWS
"""Most noisy draws a coder takes (:data:`TERM_REL_SD` unmet): ~0.4 s a 250 px mark."""


@dataclass(frozen=True)
class TurnEstimate:
    """The JPEG term as the draws estimate it.

    Attributes
    ----------
    u_rad : float
        The term [rad]: the root of the mean over the draws of (turn^2 - the scatter's share).
    var_sq_rad4 : float
        Variance of that mean (the term's square) from the draws' own spread [rad^4]
        (0: the noise-free model once, no sampling).
    draws : int
        Noisy draws taken (0: the noise-free model once); dimensionless.
    """

    u_rad: float
    var_sq_rad4: float = 0.0
    draws: int = 0

    def to_dict(self) -> dict:
        return {"u_rad": self.u_rad, "var_sq_rad4": self.var_sq_rad4, "draws": self.draws}

    @classmethod
    def from_dict(cls, d: dict) -> TurnEstimate:
        return cls(float(d["u_rad"]), float(d["var_sq_rad4"]), int(d["draws"]))

    @property
    def rel_sd(self) -> float:
        """Relative sd of the term's square [-] (inf when it reads 0 with spread)."""
        sq = self.u_rad ** 2
        return float(np.sqrt(self.var_sq_rad4) / sq) if sq > 0 else (
            float("inf") if self.var_sq_rad4 > 0 else 0.0)

    def angle_u(self, u_rad: float) -> float:
        """The angle's u [rad] from its other part ``u_rad`` and this term, the term's own
        sampling spread carried (Welch-Satterthwaite).

        The term's square is a mean over the draws: an estimate of variance ``var_sq_rad4``
        (a chi2 of 2 T^4 / var dof). With the rest of u exact, u^2 = u_rad^2 + T^2 has
        nu = 2 u^4 / var dof, and the error over it is Student's t of variance nu / (nu - 2)
        (:func:`imaging.jpeg_scatter.posterior_factor`): u^2 takes that factor. Where the
        rest dominates, nu is large and nothing changes; nu is taken >= 3 (a term read 0
        with a wide spread on a clean mark: at most 3 x u^2)."""
        u2 = u_rad ** 2 + self.u_rad ** 2
        if self.var_sq_rad4 <= 0 or u2 <= 0:
            return float(np.sqrt(u2))
        nu = max(3.0, 2.0 * u2 ** 2 / self.var_sq_rad4)
        return float(np.sqrt(posterior_factor(u2, nu)))


def jpeg_angle_shift(shape: tuple[int, int], pf: ProfileFit, jb: JpegBlocks | None,
                     centres: np.ndarray | None = None) -> float:
    """How far the JPEG encoder ``jb`` moves the angle of the fitted groove ``pf`` [rad]:
    :func:`jpeg_turn_estimate`'s term."""
    return jpeg_turn_estimate(shape, pf, jb, centres).u_rad


def jpeg_turn_estimate(shape: tuple[int, int], pf: ProfileFit, jb: JpegBlocks | None,
                       centres: np.ndarray | None = None, u_rest_rad: float = 0.0
                       ) -> TurnEstimate:
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
    rendered with it (a fixed seed: the same term for the same image), each draw through
    the encoder, and the term is the root of the mean over the draws of the turn's square
    (each coded draw's centres against the noise-free model's, as the mark's own error is:
    the encoder keeps the noise's slow part, which turns the line, and drops its fine
    detail, which the mark's scatter reads) less the share the coded centres' scatter
    carries (:func:`blocks_turn`), on marks near an axis (:func:`near_axis`: there the
    error is a turn). The draws come :data:`NOISE_DRAWS` at a time until the mean's sd,
    read from the draws' own spread, is within :data:`TERM_REL_SD` of the angle's u^2
    (``u_rest_rad`` [rad] the rest of it: draws are spent where the term's spread matters;
    0: of the term's own square) (or
    :data:`MAX_DRAWS`), each coder on its own (the same draws: a coder alone reads what it
    reads among others); the estimate's remaining spread goes with it (:class:`TurnEstimate`).
    Else, or without that noise, the noise-free model once. Only the band's blocks are coded
    (the encoder codes each block alone: the rest of the frame changes nothing)."""
    if jb is None:
        return TurnEstimate(0.0)  # not a JPEG
    # Quality and table unknown: each quality's encoder on the same renders (the model and
    # its noisy draws do not depend on the encoder), the largest term taken.
    coders = ([replace(jb, quality=q) for q in range(10, 100, 10)]
              if jb.quality is None and jb.table is None else [jb])
    half = centres_half(pf) + 8.0
    e, idx = band_pixels(np.zeros(shape, np.uint8), pf, half, 30.0)
    if idx.size == 0:
        return TurnEstimate(0.0)
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
    def coded_centres(renders, which, first):
        coded = [jpeg_round_trips(renders, coders[j].quality,
                                  coders[j].table if coders[j].quality is None else None, phase)
                 for j in which]
        return sample_centres_batch(np.concatenate([model[None]] * first + coded), pfw)

    if not (jb.noise_dn > 0 and near_axis(pf)):
        cen = coded_centres(model[None], range(len(coders)), 1)
        return max((TurnEstimate(_term([centres_turn(cen[0], c, model.shape, pfw)]))
                    for c in cen[1:]), key=lambda t: t.u_rad)
    rng = np.random.default_rng(NOISE_SEED)  # (one call a batch: as a call per draw)
    x: list[list[float]] = [[] for _ in coders]
    est: list[TurnEstimate] = [TurnEstimate(0.0)] * len(coders)
    active, cen0 = list(range(len(coders))), None
    while active:
        noise = rng.normal(0.0, jb.noise_dn, (NOISE_DRAWS, *model.shape))
        cen = coded_centres(np.clip(np.round(model + noise), 0, 255), active, cen0 is None)
        cen0, cen = (cen[0], cen[1:]) if cen0 is None else (cen0, cen)
        for k, j in enumerate(active):
            x[j] += [da**2 - us2 for da, us2 in (centres_turn(
                cen0, cen[k * NOISE_DRAWS + i], model.shape, pfw) for i in range(NOISE_DRAWS))]
            est[j] = _estimate(np.array(x[j]))
        # (a term read 0 stops too: its spread still goes into u, TurnEstimate.angle_u)
        active = [j for j in active if len(x[j]) < MAX_DRAWS and est[j].u_rad > 0
                  and not np.sqrt(est[j].var_sq_rad4)
                  <= TERM_REL_SD * (u_rest_rad**2 + est[j].u_rad**2)]
    return max(est, key=lambda t: t.u_rad)


def _estimate(x: np.ndarray) -> TurnEstimate:
    """The term from the draws' x = turn^2 - the scatter's share [rad^2]: the root of their
    mean (clipped at 0), the mean's variance from their spread."""
    return TurnEstimate(float(np.sqrt(max(0.0, float(np.mean(x))))),
                        float(np.var(x, ddof=1) / x.size), int(x.size))


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
    def _first(self) -> list[TurnEstimate]:
        return []

    def estimate(self, u_rest_rad: float = 0.0) -> TurnEstimate:
        """The term and its spread (:func:`jpeg_bound_shift`), its draws spent as the
        angle's u with ``u_rest_rad`` [rad] the rest of it needs; the first reading kept."""
        if not self._first:
            self._first.append(jpeg_bound_shift(self.shape, self.profile, self.jpeg,
                                                self.centres, u_rest_rad))
        return self._first[0]

    def angle_u(self, u_rest_rad: float) -> float:
        """The angle's u [rad] from the rest of it and this term (:meth:`TurnEstimate.angle_u`)."""
        return self.estimate(u_rest_rad).angle_u(u_rest_rad)

    u_rad = property(lambda self: self.estimate().u_rad)
    """The term [rad]."""


def jpeg_bound_shift(shape: tuple[int, int], pf: ProfileFit, jb: JpegBlocks | None,
                     centres: np.ndarray | None = None, u_rest_rad: float = 0.0
                     ) -> TurnEstimate:
    """:func:`jpeg_angle_shift` bounded over the qualities the pixels cannot exclude
    (``jb.candidates``, :func:`imaging.jpeg.quality_candidates`): the largest, each with
    the noise before coding read on its own table (:class:`TurnEstimate`). Without
    candidates, ``jb``'s own. A quality read a few steps coarser than the encoder's carried
    0" on marks whose own table gave 11-17" (user 13's quality-75 crops)."""
    if jb is None or not jb.candidates:
        return jpeg_turn_estimate(shape, pf, jb, centres, u_rest_rad)
    return max((jpeg_turn_estimate(shape, pf, replace(jb, quality=q, noise_dn=s, candidates=()),
                                   centres, u_rest_rad) for q, s in jb.candidates),
               key=lambda t: t.u_rad)


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
