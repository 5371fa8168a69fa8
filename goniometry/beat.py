"""The counters' quantisation along a log's own phase path: the variance of each mean face
angle, and what batch means of it should read.

A counter reads floor(theta) of the ring laser's continuous phase theta [counts] at each face
pulse. The phase of face k at revolution r advances by the counts of a table revolution K plus
the Earth's share E T_r of that revolution's period (E = K rate / 2 pi [counts/s]): on a
steady table by the same fraction every revolution (the beat), on an unsteady one by a
fraction that wanders with the speed — which the pulse times show. With the phase path known
up to a common offset, the error of any linear combination sum_j w_j frac(theta_j) of the
floors has, over that unknown offset, the variance

    sum_m |sum_j w_j exp(2 pi i m theta_j)|^2 g_m / (2 pi^2 m^2)  (+ white terms),

the Fourier series of the sawtooth's covariance 1/12 - x (1 - x) / 2 at phase separation x;
g_m = exp(-4 pi^2 m^2 sigma^2) is the blur of a pair of pulses by the autocollimator's jitter
sigma [counts], which also adds sigma^2 per pulse. This is the whole per-revolution noise of
a clean log (quantisation and jitter) with no degrees of freedom to estimate: batch means of a
short log (5-10 degrees of freedom) state u with Student-t tails, and cannot see a beat longer
than their blocks; the model does both. Faces are given independent phase offsets (the
fraction of each interval's count is what is being measured, known only to ~u), K only to
+-1/R (the floors of the log's ends): the variance is averaged over that range.
Hand-written: no library evaluates quantisation along a measured phase path.
"""

from __future__ import annotations

import numpy as np

# Harmonics of the sawtooth summed explicitly; the rest (1 % of its variance) is white.
HARMONICS = 48
# Values of the counts per revolution tried over its +-1/R uncertainty.
K_STEPS = 9


def phase_path(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
               rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Phase [counts] of every face pulse of the kept revolutions, up to one offset per face,
    and the revolution numbers.

    Returns ``theta`` (R, n + 1) — faces 0..n-1 at the start of each revolution and the
    closing reference pulse — and ``turn`` (R,), each revolution's number from the first
    (gaps where revolutions were excluded: from the times; without times the revolutions are
    taken as consecutive and the table as steady).
    """
    R, n = counts.shape
    N = counts.sum(1)
    if dt is None or t_end is None:
        turn = np.arange(R, dtype=float)
        K = float(N.mean())
        theta = (turn[:, None] + np.arange(n + 1)[None, :] * 0.0) * K
        theta[:, n] += K
        return theta, turn
    from goniometry.revolutions import fill_first_interval

    d = fill_first_interval(counts, np.asarray(dt, float))
    T = d.sum(1)
    # Pulse times: the closing reference, and back through the intervals.
    t = np.empty((R, n + 1))
    t[:, n] = t_end
    t[:, :n] = t_end[:, None] - np.cumsum(d[:, ::-1], 1)[:, ::-1]
    # Revolutions between consecutive kept ones: the elapsed time over the period (the speed
    # wanders by a few % at most between neighbours).
    gap = np.maximum(np.rint(np.diff(t[:, 0]) / T[:-1]), 1.0)
    turn = np.concatenate([[0.0], np.cumsum(gap)])
    E = rate / (2 * np.pi) * float(N.mean()) / (1 + rate * float(T.mean()) / (2 * np.pi))
    K = float(N.mean() - E * T.mean())  # counts of one table revolution
    theta = turn[:, None] * K + E * (t - t[0, 0])
    theta[:, n] += K  # the closing reference is the next revolution's face 0
    return theta, turn


def _weights(counts: np.ndarray) -> np.ndarray:
    """Weights (n, R, n + 1) of each pulse's fractional phase in each angle's per-revolution
    error [counts of the angle]: interval k's count is floor(end) - floor(start), the angle
    2 pi n_k / N_r with N_r the revolution's total (the closure)."""
    R, n = counts.shape
    p = counts.mean(0) / counts.sum(1).mean()
    w = np.zeros((n, R, n + 1))
    for k in range(n):
        w[k, :, k] += 1.0
        w[k, :, k + 1] -= 1.0
        w[k, :, 0] -= p[k]
        w[k, :, n] += p[k]
    return w


def _merge(w: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """Fold each closing reference into the next revolution's face 0 where they are the same
    pulse (consecutive revolutions): (..., R, n + 1) -> (..., R + 1, n) pulses by face (the
    last row holds the closing references; zero where merged)."""
    *lead, R, n1 = w.shape
    n = n1 - 1
    out = np.zeros((*lead, R + 1, n))
    out[..., :R, :] = w[..., :n]
    nxt = np.concatenate([np.diff(turn) == 1, [False]])
    out[..., 1:, 0] += np.where(nxt, w[..., n], 0.0)
    out[..., R, 0] = 0.0
    sep = w[..., n] * ~nxt  # closing references not shared
    return out, sep


def _variance(w: np.ndarray, theta: np.ndarray, turn: np.ndarray, sigma: float,
              dk: float) -> np.ndarray:
    """Variance [counts^2] over the unknown phase offsets of sum w * frac(theta + jitter),
    for weight sets w (..., R, n + 1); the counts per revolution off by ``dk``."""
    R, n1 = theta.shape
    n = n1 - 1
    th = theta + dk * (turn[:, None] + (np.arange(n1) == n)[None, :])
    m = np.arange(1, HARMONICS + 1)
    c = np.exp(-4 * np.pi**2 * m**2 * sigma**2) / (2 * np.pi**2 * m**2)
    # Each face its own offset: sum over faces of |W_m|^2 (closing references are face 0).
    face = np.concatenate([np.arange(n), [0]])
    e = np.exp(2j * np.pi * (m[:, None, None] * (th[None] % 1.0)))
    lead = w.shape[:-2]
    wf = w.reshape(-1, R, n1)
    tot = np.zeros(len(wf))
    for f in range(n):
        cols = face == f
        W = np.einsum("brj,mrj->bm", wf[:, :, cols], e[:, :, cols])
        tot += (np.abs(W) ** 2) @ c
    merged, sep = _merge(wf, turn)
    white = 1 / 12 + sigma**2 - c.sum()
    tot += white * ((merged**2).sum((1, 2)) + (sep**2).sum(1))
    return tot.reshape(lead)


def fit_pattern(counts: np.ndarray, theta: np.ndarray, turn: np.ndarray,
                sigmas: np.ndarray | None = None
                ) -> tuple[float, np.ndarray, tuple[float, float, float]]:
    """The floors' pattern along the phase path: the counts per revolution's correction dk
    (within +-1/R), each face's phase offset, and the autocollimator's jitter [counts]:
    (lowest, most likely, highest) the pulses allow.

    Each interval's count is floor(end) - floor(start): its excess over the path's phase
    advance is c_k + frac(start + phi_k) - frac(end + phi_k+1). (dk, phi) by grid search
    (least squares, c_k free; coordinate descent over the faces); then the jitter sigma,
    which blurs each floor near its step (E frac(x + e) = frac x - Phi((frac x - 1) / sigma)
    + Phi(-frac x / sigma)), by a 1-D search on the residual — from the few pulses near a
    step, but from every revolution (a 20 % estimate where the per-interval scatter, 1/6 +
    2 sigma^2, cannot tell 0.06 counts from none).
    """
    from scipy.special import ndtr  # (the normal CDF; scipy.stats costs 0.8 s to import)

    R, n = counts.shape
    col = np.arange(n + 1)
    face = np.where(col == n, 0, col)
    span = turn[-1] + 1
    base = counts - np.diff(theta, axis=1)  # (R, n)
    grid = (np.arange(128) + 0.5) / 128

    def rss_of(fr_s: np.ndarray, fr_e: np.ndarray) -> np.ndarray:
        r = base[..., :] - fr_s + fr_e
        r = r - r.mean(-2, keepdims=True)
        return (r**2).sum(-2)

    best = (np.inf, 0.0, np.zeros(n))
    for dk in np.linspace(-1, 1, 41) / span:
        th = (theta + dk * (turn[:, None] + (col == n)[None, :])) % 1.0
        phi = np.zeros(n)
        for _ in range(2):
            for f in range(n):
                tot = np.zeros(len(grid))
                for k in range(n):
                    s, e = face[k], face[k + 1]
                    if f not in (s, e):
                        continue
                    ps = grid[:, None] if s == f else phi[s]
                    pe = grid[:, None] if e == f else phi[e]
                    fs = (th[None, :, k] + ps) % 1.0 if s == f else \
                        np.broadcast_to((th[:, k] + ps) % 1.0, (len(grid), R))
                    fe = (th[None, :, k + 1] + pe) % 1.0 if e == f else \
                        np.broadcast_to((th[:, k + 1] + pe) % 1.0, (len(grid), R))
                    r = base[None, :, k] - fs + fe
                    tot += ((r - r.mean(1, keepdims=True)) ** 2).sum(1)
                phi[f] = grid[int(np.argmin(tot))]
        fr = (th + phi[face][None, :]) % 1.0
        total = float(rss_of(fr[:, :n], fr[:, 1:]).sum())
        if total < best[0]:
            best = (total, float(dk), phi.copy())
    _, dk, phi = best
    # Each pulse's floor along the chain of consecutive revolutions (the closing reference
    # is the next revolution's face 0): its count from the chain's start less the path's
    # phase is a per-face constant less frac(phase) — plus the jitter's step, delta in
    # {-1, 0, 1}, where the pulse crossed its floor: P(+1) = Phi((y - 1) / sigma),
    # P(-1) = Phi(-y / sigma), y the pulse's fractional phase.
    th = theta + dk * (turn[:, None] + (col == n)[None, :])
    y = (th + phi[face][None, :]) % 1.0
    seg = np.concatenate([[0], np.cumsum(np.diff(turn) != 1)])
    deltas, ys = [], []
    for s_ in np.unique(seg):
        rows = np.flatnonzero(seg == s_)
        cum = np.concatenate([[0.0], np.cumsum(counts[rows].ravel())])
        ph = np.concatenate([th[rows, :n].ravel(), th[rows[-1:], n]])
        yy = np.concatenate([y[rows, :n].ravel(), y[rows[-1:], n]])
        ff = np.concatenate([np.tile(face[:n], len(rows)), [0]])
        v = cum - (ph - ph[0]) + yy
        for f in range(n):
            m = ff == f
            d = np.round(v[m] - v[m][0])  # delta less the first pulse's
            deltas.append(d - np.median(d))  # (most pulses do not cross)
            ys.append(yy[m])
    delta, yv = np.concatenate(deltas), np.concatenate(ys)
    if sigmas is None:
        sigmas = np.geomspace(0.004, 0.5, 48)
    s_ = sigmas[:, None]
    p_up, p_dn = ndtr((yv - 1) / s_), ndtr(-yv / s_)
    like = np.where(delta > 0, p_up, np.where(delta < 0, p_dn, 1 - p_up - p_dn))
    ll = np.log(np.maximum(like, 1e-300)).sum(1)
    # The jitters the pulses allow (log-likelihood within 2 of its maximum, ~95 %): wide
    # where few pulses come near a step (a locked phase).
    ok = np.flatnonzero(ll >= ll.max() - 2)
    return dk, phi, (float(sigmas[ok[0]]), float(sigmas[int(np.argmax(ll))]),
                     float(sigmas[ok[-1]]))


def _dks(dk: float, span: float) -> np.ndarray:
    """Counts-per-revolution corrections averaged over: the fitted one +-1/(8 R) (the
    pattern's resolution), or +-1/R without a fit."""
    half = 1 / 8 if dk is not None else 1.0
    return (dk or 0.0) + np.linspace(-half, half, K_STEPS) / span


def variance_of_mean(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
                     rate: float, sigma: float, dk: float | None = None) -> np.ndarray:
    """Variance [counts^2] of each mean face angle's error from quantisation and jitter
    (sigma [counts] per pulse), averaged over the counts per revolution's uncertainty."""
    theta, turn = phase_path(counts, dt, t_end, rate)
    R = len(counts)
    w = _weights(counts) / R
    return np.mean([_variance(w, theta, turn, sigma, d)
                    for d in _dks(dk, turn[-1] + 1)], axis=0)


def allan_expected(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
                   rate: float, sigma: float, tau: int, dk: float | None = None
                   ) -> np.ndarray:
    """Expected non-overlapping Allan variance [counts^2] of the per-revolution angles at
    averaging ``tau`` revolutions (blocks aligned from the first), under the same model."""
    theta, turn = phase_path(counts, dt, t_end, rate)
    R, n = counts.shape
    nb = R // tau
    w1 = _weights(counts)  # (n, R, n + 1)
    tot = np.zeros(n)
    dks = _dks(dk, turn[-1] + 1)
    sign = np.where(np.arange(2 * tau) < tau, -1.0, 1.0) / tau
    for i in range(nb - 1):
        sl = slice(i * tau, (i + 2) * tau)
        w = w1[:, sl] * sign[None, :, None]
        tot += np.mean([_variance(w, theta[sl], turn[sl], sigma, d) for d in dks], axis=0)
    return tot / (2 * (nb - 1))
