"""How the background's texture makes the centres' errors correlated along a mark.

The centre of segment k is, to first order, a fixed linear functional of its pixels' noise:
delta_k - truth = c_k . n. Per-pixel white noise makes those errors independent with the
Fisher variances; surface texture (machining streaks, grain) does not: a streak crossing the
mark at a shallow angle moves many consecutive centres the same way, and a straight-line fit
that assumes independent centres understates the angle's uncertainty while the residual
tests see "structure" that is only texture.

Measuring it (hand-written: no library models an estimator's noise covariance from image
replicas). The same functional c_k is applied to *replicas* of the band: the same pixels
shifted by a whole number of pixels along the mark's normal, off the mark, on both sides.
There the image holds only background (texture + noise) with the same pixel phase, so the
replica "centres" are draws of exactly the error the texture puts on the real centres.
Their autocovariance along the mark, in units of the white-noise variance, gives the
centres' correlation; it is used only when the replicas show it (a portmanteau test), so a
clean image keeps its independent centres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from imaging.groupsum import GroupSums
from imaging.median import median, median_inplace
from imaging.ring import ring_geometry, ring_slope  # the ring's slope, as for the mark

ALPHA = 1e-3
"""Level of each test that the replicas show texture (one false use per 1000 clean marks)."""

QUIET = 1e-6
"""Replicas' variance, relative to the white-noise model's, below which the background holds
no noise at all (a noise-free render): a real background holds at least its own read, photon
and quantisation noise, which the model states to within a factor of a few."""


@dataclass(frozen=True)
class TextureModel:
    """What the background's texture does to the centres (from replicas of the band).

    ``acf``: autocovariance of the centres' errors per lag [segments], in units of their
    Fisher variance (acf[0] >= 1 the variance factor), tapered; None: independent.
    ``coupling_px2``: the centre error per unit of the ring's slope/contrast regressor that
    texture alone produces [px^2] (taken out of the centres as a control variate), with
    standard uncertainty ``coupling_u_px2``; ``replicas``: how many replica series were
    used; ``dof``: equivalent degrees of freedom of the tapered spectrum estimate behind
    ``acf`` (Parzen lag window over span M on n replica points in all: 3.709 n / M,
    Priestley 1981 §6.2) — the tests that whiten with this estimated covariance take it
    into their null distributions (inf when ``acf`` is None).
    """

    acf: np.ndarray | None
    coupling_px2: float
    coupling_u_px2: float
    replicas: int
    dof: float = float("inf")


def _replica(image: np.ndarray, ys: np.ndarray, xs: np.ndarray, dx: int, dy: int,
             full_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel values shifted by (dx, dy) and which of them are usable."""
    h, w = image.shape
    yy, xx = ys + dy, xs + dx
    inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
    v = np.zeros(ys.size)
    v[inside] = image[yy[inside], xx[inside]]
    return v, inside & (v < full_scale) & (v > 0)


class _Shifted:
    """:func:`_replica` of one set of pixels (flat indices into the image) at many shifts,
    their bounding box taken once (16 replicas per mark): a replica wholly inside the image
    (the usual case) is one gather by flat index, ~3x cheaper than the masks and 2-D
    indexing."""

    def __init__(self, image: np.ndarray, flat: np.ndarray, full_scale: float):
        self.image, self.flat, self.full_scale = image, flat, full_scale
        w = image.shape[1]
        self.box = None
        if image.flags.c_contiguous and flat.size:
            # (Rows from the extreme flat indices: the row is flat // w, monotone in it.)
            col = flat % w
            self.first = int(flat.min())
            self.box = (self.first // w, int(flat.max()) // w, int(col.min()), int(col.max()))
            # Each replica gathers from the flat image advanced to its shifted first pixel:
            # no shifted copy of the indices per replica.
            self.rel = flat - self.first

    def __call__(self, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The values shifted by (dx, dy) and which are usable (None: every one, as two
        reductions told: cheaper than the masks, and the usual case)."""
        h, w = self.image.shape
        if self.box is not None and (self.box[0] + dy >= 0 and self.box[1] + dy < h
                                     and self.box[2] + dx >= 0 and self.box[3] + dx < w):
            v = (self.image.ravel()[self.first + dy * w + dx:].take(self.rel)
                 .astype(float, copy=False))
            if v.min() > 0 and v.max() < self.full_scale:  # (NaN fails both)
                return v, None
            return v, (v < self.full_scale) & (v > 0)
        ys, xs = np.divmod(self.flat, w)
        return _replica(self.image, ys, xs, dx, dy, self.full_scale)


def _demean(z: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Remove the mean over the valid entries, zero elsewhere."""
    out = np.where(valid, z, 0.0)
    out[valid] -= out[valid].mean()
    return out


def texture_model(image: np.ndarray, band: tuple[np.ndarray, np.ndarray],
                  nseg: int, wgt: np.ndarray, J: Sequence[np.ndarray], cov: np.ndarray,
                  ok: np.ndarray, ring: tuple[np.ndarray, ...], contrast: np.ndarray,
                  normal: np.ndarray, shifts_px: Sequence[float],
                  noise_var: tuple[float, float], full_scale: float,
                  avoid_px: Sequence[float] = (), clear_px: float = 0.0,
                  npx: np.ndarray | None = None, sums: GroupSums | None = None,
                  ring_geo: tuple | None = None) -> TextureModel | None:
    """Measure the texture's effect on the centres from replicas of the band.

    Parameters
    ----------
    band : (flat index into ``image``, segment) of the band's pixels
    wgt, J : per-pixel weights and the k design columns of the segment fit (centre first)
    cov : (nseg, k, k) inverse normal matrices of the segments; ``ok`` valid segments
    ring : (flat index, e, segment) of the illumination ring's pixels
    contrast : (nseg,) the segments' contrast [DN] (the regressor is slope / contrast)
    normal : unit normal of the mark (x, y)
    shifts_px : distances along the normal at which replicas are taken (both signs)
    noise_var : (v0, v1) of the white pixel-noise model var = v0 + v1 * value [DN^2]
    avoid_px, clear_px : signed distances along ``normal`` of other lines beside the mark
        (a ruled scale's neighbours) [px]: no replica is taken within ``clear_px`` of one —
        there the replica holds a line, not background.
    npx : the band's pixel count per segment, when the caller has it (else counted here)
    sums : the band's per-segment sums (:class:`imaging.groupsum.GroupSums` of its segments),
        when the caller has them (else grouped here)
    ring_geo : :func:`imaging.ring.ring_geometry` of the ring, when the caller has it

    Returns None when no replica could be taken (all off the image or clipped); ``acf`` is
    None when the replicas are consistent with independent centres of the Fisher variance,
    and ``acf`` None with a coupling of 0 when they hold no noise at all (below
    :data:`QUIET`: a noise-free render, nothing to estimate from).
    """

    flat, seg = band
    v0, v1 = noise_var
    k = len(J)
    c0 = np.where(ok[:, None], cov[:, 0, :], 0.0)

    bc = GroupSums(seg, nseg, eager=True) if sums is None else sums

    wj = [wgt * j for j in J]
    # White-noise variance of a replica's centre, (N^-1 J^T W V W J N^-1)_00, with the
    # pixel variance V taken per segment at the replica's mean level (one sum for all).
    M0 = np.empty((nseg, k, k))
    for i in range(k):
        for j in range(i, k):
            M0[:, i, j] = M0[:, j, i] = bc(wj[i] * wj[j])
    w0 = np.einsum("ni,nij,nj->n", c0, M0, c0)
    # The centre functional per pixel, (N^-1 J^T W)_0: a replica's centre is one sum of
    # f v per segment (not k sums then the segment's row of N^-1).
    # (c0's columns as rows: each gather one contiguous take; the sum in the order
    # ``sum()`` adds, 0 first: the same numbers.)
    c0_rows = np.ascontiguousarray(c0.T)
    f = c0_rows[0].take(seg) * wj[0]
    f += 0.0
    for i in range(1, k):
        f += c0_rows[i].take(seg) * wj[i]
    npx = np.maximum(bc(np.ones(flat.size)) if npx is None else npx, 1)
    if ring_geo is None:
        ring_geo = ring_geometry(ring[1], ring[2], nseg)  # the same for every replica
    ring_n = ring_geo[0]
    band_at, ring_at = _Shifted(image, flat, full_scale), _Shifted(image, ring[0], full_scale)
    reps = []
    for dist in shifts_px:
        for sign in (1.0, -1.0):
            if any(abs(sign * dist - a) < clear_px for a in avoid_px):
                continue
            dx, dy = (int(round(sign * dist * c)) for c in normal)
            v, good = band_at(dx, dy)
            valid = (ok.copy() if good is None or good.all()  # (changed in place below)
                     else ok & (np.bincount(seg[~good], minlength=nseg) == 0))
            rv, rgood = ring_at(dx, dy)
            whole = rgood is None or rgood.all()
            if not whole:  # (all usable: every segment has its whole ring)
                valid &= np.bincount(ring[2], rgood, minlength=nseg) >= 0.8 * ring_n
            if valid.sum() < 20:
                continue
            # The centre functional applied to the replica: (N^-1 J^T W v)_0 per segment,
            # and its white-noise variance (N^-1 J^T W V W J N^-1)_00.
            d = bc(f * v)
            wv = w0 * np.maximum(v0 + v1 * bc(v) / npx, 1e-9)
            valid &= np.isfinite(d) & (wv > 0)
            s = np.sqrt(np.where(valid, wv, 1.0))
            x = ring_slope(rv if whole else np.where(rgood, rv, 0.0), ring[1], ring[2], nseg,
                           full_scale, ring_geo, True if rgood is None else rgood)
            # The centres' series keeps its mean: the texture's slow undulations are what moves a
            # fitted angle, and demeaning (or detrending) a replica forces the autocovariance to
            # sum to ~0, i.e. no low-frequency power (u came out 20-30 % too small). The
            # regressor is centred, as the loop's illumination column is.
            reps.append((np.where(valid, d / s, 0.0), _demean(x / contrast / s, valid), s,
                         valid))
    if not reps:
        return None
    # A noise-free background (the noise model's variance is then the groove model's misfit,
    # not the pixels'): the replica centres are float rounding (~1e-22 of the white variance)
    # and the coupling and the portmanteau below would be ratios of rounding errors (a
    # coupling of -6e15 px^2, applied to the mark's rounding-level ring slope, tilted a
    # noise-free 1000 px mark at 37 deg by 1571" at a stated u of 0.002"). No texture there.
    if np.median([np.sum(z**2) / v.sum() for z, _, _, v in reps]) < QUIET:
        return TextureModel(None, 0.0, 0.0, len(reps))
    # Dust, a scratch or another mark in a replica: robust outlier cut per replica, and a
    # replica far noisier than the others (it crosses something bright) left out.
    clean = []
    for z, x, _, valid in reps:
        for y in (z, x):  # the ring's slope too: dust beside the band moves both
            med = median(y[valid])
            mad = 1.4826 * median_inplace(np.abs(y[valid] - med))
            valid = valid & (np.abs(y - med) <= 6 * max(mad, 1e-12))
        clean.append((np.where(valid, z, 0.0), np.where(valid, x, 0.0), valid))
    var0 = np.array([np.sum(z**2) / v.sum() for z, _, v in clean])
    keep = var0 <= 2.0 * median(var0)
    clean = [c for c, kp in zip(clean, keep, strict=True) if kp]
    z_all = np.concatenate([z for z, _, _ in clean])
    x_all = np.concatenate([x for _, x, _ in clean])
    n_tot = float(sum(v.sum() for _, _, v in clean))
    # Coupling of the centre error to the regressor (weighted regression through 0).
    sxx = float(x_all @ x_all)
    beta = float(z_all @ x_all) / sxx if sxx > 0 else 0.0
    res = z_all - beta * x_all
    beta_u = float(np.sqrt(res @ res / max(n_tot - 1, 1) / sxx)) if sxx > 0 else np.inf
    # Applied whatever its significance: a control variate estimated from ~8 times the
    # mark's own data adds ~1/8 of its noise, and leaves no texture coupling for the loop's
    # correlation test to mistake for an illumination effect.
    # Biased autocovariance (sum over pairs / number of points) of each zero-filled series,
    # after the coupling is taken out: a positive semi-definite sequence, so the covariance
    # matrix built from it is one too.
    nfft = 1 << int(np.ceil(np.log2(2 * nseg)))
    acf = np.zeros(nseg)
    for z, x, valid in clean:
        f = np.fft.rfft(np.where(valid, z - beta * x, 0.0), nfft)
        acf += np.fft.irfft(f * f.conj(), nfft)[:nseg]
    acf /= n_tot
    lags = int(min(20, max(2, nseg // 5)))
    rho = acf[1:lags + 1] / acf[0]
    # Portmanteau on the pooled replicas, and their variance against chi2(n).
    p_corr = float(special.chdtrc(lags, n_tot * np.sum(rho**2)))
    p_var = float(special.chdtrc(n_tot, acf[0] * n_tot))
    dof = float("inf")
    if min(p_corr, p_var) >= ALPHA / 3:
        acf_out = None
    else:
        # Parzen lag window (non-negative spectral window, so the tapered sequence stays
        # positive semi-definite) over the mark's length: noisy long-lag estimates fade out.
        span = float(max(4, nseg))
        t = np.arange(nseg) / span
        taper = np.where(t <= 0.5, 1 - 6 * t**2 + 6 * t**3,
                         np.where(t <= 1, 2 * (1 - t) ** 3, 0.0))
        acf_out = acf * taper
        # Texture adds to the white noise, never takes from it (more diagonal stays PSD).
        acf_out[0] = max(acf_out[0], 1.0)
        # Replicas a few px apart see overlapping texture, so this is an upper bound on the
        # estimate's information (the tests stay slightly liberal, never over-cautious).
        dof = 3.709 * n_tot / span
    # The coupling in px^2: z and x were both divided by the same white sigma per segment.
    return TextureModel(acf_out, beta, beta_u, len(clean), dof)


def texture_control(tex: TextureModel, regressor: np.ndarray, ok: np.ndarray,
                    sigma: np.ndarray) -> np.ndarray:
    """The centres' moves [px] the texture's coupling predicts from the mark's own ring
    ``regressor`` (slope / contrast per segment [1/px]), to be taken out of them: the
    coupling times the regressor less its mean over the usable segments ``ok``, weighted as
    the line weighs the centres (1 / ``sigma``^2, ``sigma`` their u [px]).

    Centred as the replicas' regressors are (:func:`texture_model`): their mean holds no
    information on the coupling, so the coupling's error is not bounded along it, and the
    mark's regressor holds there the background's shading (its slope across the mark, the
    same in every segment), not texture. Applied uncentred, the coupling's estimation noise
    times the shading moved the whole mark: the outer lines of 64 stage-micrometer frames
    (one side clear of the other lines, the only ones with the 4 replica series the
    coupling needs) had offset z RMS 1.85 under shaded light, the inner ones 1.21; centred,
    1.02 and 0.97. The mean weighted as the line's: a segment of almost no contrast (a
    JPEG-coded end) has a regressor of ~1e12 /px and a sigma of ~1e14 px; in a plain mean it
    moved every centre by ~1e11 px. Zeros where the regressor is not finite."""
    finite = np.isfinite(regressor)
    w = np.where(ok & finite & (sigma > 0), 1.0 / np.where(sigma > 0, sigma, 1.0) ** 2, 0.0)
    if tex.coupling_px2 == 0 or not np.any(w > 0):
        return np.zeros(regressor.shape)
    mean = float(np.sum(w * np.where(finite, regressor, 0.0)) / np.sum(w))
    return np.where(finite, tex.coupling_px2 * (regressor - mean), 0.0)


def correlation_cholesky(acf: np.ndarray, index: np.ndarray) -> tuple[float, np.ndarray]:
    """Scale of the centres' sigma and the Cholesky factor of their correlation matrix.

    ``index``: each used centre's segment number. Returns (factor on sigma, lower L with
    L L^T = R, R_ij = acf[|i - j|] / acf[0]).
    """
    lag = np.abs(index[:, None] - index[None, :])
    R = acf[np.minimum(lag, len(acf) - 1)] / acf[0]
    R[lag >= len(acf)] = 0.0
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:
        # Rounding can leave a tapered estimate barely indefinite: a touch of white noise.
        L = np.linalg.cholesky(R + 1e-6 * np.eye(len(R)))
    return float(np.sqrt(acf[0])), L
