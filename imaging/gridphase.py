"""The pixel grid's phase: what a groove-model misfit can leave on a mark's angle.

A groove whose cross-section the model does not describe exactly (a rounded V against the
flat-bottomed model, a blur applied on the pixel grid — charge diffusion, crosstalk,
demosaicing — rather than before it) is sampled by the pixels at a phase phi, the centre's
position modulo one pixel. Each segment's fitted centre is then off by a periodic function
delta(phi) (zero at phi = 0 and 1/2 for a symmetric groove). Along a mark at angle a the
phase turns L tan(a) times over its length L: many turns average out, but a mark within a
fraction of a degree of a pixel axis sweeps less than one period and delta becomes a slow
drift along it — a systematic that does not average down like noise and moves the angle.

By Cauchy–Schwarz a residual of weighted norm ||D|| moves a centre of standard uncertainty
sigma by at most ||D|| sigma, at any phase; ||D|| is bounded from the residual pooled over the
whole mark (:attr:`imaging.centres.Centres.misfit`). delta is carried as a sinusoid in each
pixel axis's phase with that amplitude and a random phase (covariance b^2/2 (s s^T + c c^T)),
and propagated through the line fit into the angle: a Type B term, near zero for marks that
sweep many periods or none (a mark exactly along an axis: only its offset moves).
"""

from __future__ import annotations

import numpy as np


def grid_phase_bound_px(misfit: float, sigma: np.ndarray) -> float:
    """Largest centre bias [px] a misfit of ``misfit`` (weighted chi2 per segment) can make:
    sqrt(misfit) times the centres' typical u ``sigma`` [px] (Cauchy–Schwarz)."""
    s = sigma[np.isfinite(sigma)]
    return float(np.sqrt(max(misfit, 0.0)) * np.median(s)) if s.size else 0.0


def grid_phase_u_rad(xy_px: np.ndarray, sigma: np.ndarray, t_px: np.ndarray, angle_rad: float,
                     image_shape: tuple[int, int], bound_px: float, segment_px: float = 4.0
                     ) -> float:
    """Standard uncertainty [rad] the pixel-phase bias puts on a mark's fitted angle.

    Parameters
    ----------
    xy_px : ndarray
        (N, 2) centres in the raw image, relative to its centre [px].
    sigma : ndarray
        (N,) their u across the line [px] (the line fit's weights).
    t_px : ndarray
        (N,) their positions along the line [px].
    angle_rad : float
        The mark's direction [rad]: its phase is read across the pixel axis it runs nearest.
    image_shape : tuple of int
        (rows, columns) [px].
    bound_px : float
        Amplitude of the bias (:func:`grid_phase_bound_px`) [px].
    segment_px : float
        Length of a centre's segment [px]: over it the phase turns segment x tan(a) and its
        bias is the mean of delta there (the sinusoid's amplitude x sinc).

    Returns
    -------
    float
        u of the angle [rad]: the weighted least-squares slope of each phase sinusoid,
        in quadrature, times bound / sqrt 2.
    """
    ok = np.isfinite(sigma) & (sigma > 0)
    if bound_px <= 0 or np.count_nonzero(ok) < 3:
        return 0.0
    h, w = image_shape
    x = xy_px[ok, 0] + (w - 1) / 2
    y = xy_px[ok, 1] + (h - 1) / 2
    t = t_px[ok]
    wt = 1.0 / sigma[ok] ** 2
    tc = t - np.sum(wt * t) / np.sum(wt)
    stt = np.sum(wt * tc * tc)
    if stt <= 0:
        return 0.0
    var = 0.0
    c, s = abs(np.cos(angle_rad)), abs(np.sin(angle_rad))
    q = y if c >= s else x                    # across the nearest pixel axis
    tilt = min(c, s) / max(c, s)              # phase turned per px along the mark
    for f in (np.sin, np.cos):
        v = f(2 * np.pi * q)
        var += (np.sum(wt * tc * v) / stt) ** 2  # slope [px/px] = angle [rad]
    return float(bound_px / np.sqrt(2) * abs(np.sinc(segment_px * tilt)) * np.sqrt(var))
