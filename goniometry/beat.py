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
than their blocks; the model does neither. Faces are given independent phase offsets (the
fraction of each interval's count is what is being measured, known only to ~u). The log's
mean counts per revolution give K to +-1/R; the floors' own pattern (:func:`fit_pattern`)
pins it to ~1/(20 R) and measures the jitter: the variance is averaged over what remains.
Hand-written: no library evaluates quantisation along a measured phase path.
"""

from __future__ import annotations

import numpy as np

from goniometry.stats import fill_first_interval

# Harmonics of the sawtooth summed explicitly at most (fewer where the jitter blurs them);
# the rest (1 % of its variance) is white.
HARMONICS = 48
# Values of the counts per revolution tried over its +-1/R uncertainty.
K_STEPS = 5


def phase_path(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
               rate: float, links: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Phase [counts] of every face pulse of the kept revolutions, up to one offset per face,
    and the revolution numbers.

    Returns ``theta`` (R, n + 1) — faces 0..n-1 at the start of each revolution and the
    closing reference pulse — and ``turn`` (R,), each revolution's number from the first
    (gaps where revolutions were excluded: from the times; without times the revolutions are
    taken as consecutive and the table as steady, except where ``links`` (R - 1,) is False:
    there revolutions were excluded, how many is unknown (a drop-out takes its rows with it),
    and ``turn`` skips one — the runs' phases are then unlinked, see :func:`unlinked_runs`).
    """
    R, n = counts.shape
    N = counts.sum(1)
    if dt is None or t_end is None:
        turn = np.arange(R, dtype=float)
        if links is not None:
            turn += np.concatenate([[0.0], np.cumsum(~np.asarray(links, bool))])
        K = float(N.mean())
        theta = np.repeat(turn[:, None] * K, n + 1, axis=1)
        theta[:, n] += K
        return theta, turn

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


def unlinked_runs(turn: np.ndarray, timed: bool) -> np.ndarray:
    """Run number of each revolution whose phase is unknown relative to the other runs'
    (zeros when every gap's phase is known: with times, the path crosses a gap by them).

    Without times the revolutions an exclusion took are not counted, so the phase across it
    is unknown: each run then has its own offsets (uniform over a count), and averaged over
    them the cross terms between runs vanish — the variance of a mean over the runs is the
    sum of each run's share (a drop-out without times otherwise left u to batch means of
    5-10 degrees of freedom: 0.042" against the path's 0.077" on its drop-out-free twin).
    """
    if timed:
        return np.zeros(len(turn), int)
    return np.concatenate([[0], np.cumsum(np.diff(turn) != 1)]).astype(int)


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


def _merge(w: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fold each closing reference into the next revolution's face 0 where they are the same
    pulse (consecutive revolutions): (..., R, n + 1) -> (..., R + 1, n) weights of the pulses
    by face, and (..., R) those of the closing references not shared."""
    *lead, R, n1 = w.shape
    n = n1 - 1
    out = np.zeros((*lead, R + 1, n))
    out[..., :R, :] = w[..., :n]
    nxt = np.concatenate([np.diff(turn) == 1, [False]])
    out[..., 1:, 0] += np.where(nxt, w[..., n], 0.0)
    sep = w[..., n] * ~nxt  # closing references not shared
    return out, sep


def _variance(w: np.ndarray, theta: np.ndarray, turn: np.ndarray, sigma: float,
              dk: float, runs: np.ndarray | None = None) -> np.ndarray:
    """Variance [counts^2] over the unknown phase offsets of sum w * frac(theta + jitter),
    for weight sets w (..., R, n + 1); the counts per revolution off by ``dk``; ``runs``
    (R,): revolutions of different runs have independent offsets (see unlinked_runs)."""
    R, n1 = theta.shape
    n = n1 - 1
    th = theta + dk * (turn[:, None] + (np.arange(n1) == n)[None, :])
    # Harmonics the jitter has not yet blurred away (g_m > 1e-3; beyond, they are white).
    top = HARMONICS if sigma <= 0 else int(np.clip(np.ceil(0.42 / sigma), 8, HARMONICS))
    m = np.arange(1, top + 1)
    c = np.exp(-4 * np.pi**2 * m**2 * sigma**2) / (2 * np.pi**2 * m**2)
    # Each face its own offset: sum over faces of |W_m|^2 (closing references are face 0).
    face = np.concatenate([np.arange(n), [0]])
    e = np.exp(2j * np.pi * (m[:, None, None] * (th[None] % 1.0)))
    lead = w.shape[:-2]
    wf = w.reshape(-1, R, n1)
    tot = np.zeros(len(wf))
    ids = np.unique(runs) if runs is not None else np.zeros(1, int)
    for f in range(n):
        cols = face == f
        wc, ec = wf[:, :, cols], e[:, :, cols]
        for r_ in ids:
            if len(ids) == 1:  # (one run: all its revolutions; the same arrays as selected)
                W = np.einsum("brj,mrj->bm", wc, ec)
            else:
                rr = runs == r_
                W = np.einsum("brj,mrj->bm", wc[:, rr], ec[:, rr])
            tot += (np.abs(W) ** 2) @ c
    merged, sep = _merge(wf, turn)
    white = 1 / 12 + sigma**2 - c.sum()
    tot += white * ((merged**2).sum((1, 2)) + (sep**2).sum(1))
    return tot.reshape(lead)


def _chains(counts: np.ndarray, theta: np.ndarray, turn: np.ndarray
            ) -> tuple[np.ndarray, ...]:
    """The pulses in time order along each run of consecutive revolutions (the closing
    reference is the next revolution's face 0): v = count from the run's start less the
    path's phase advance, the path's phase, the face, the run and the revolution number of
    each pulse."""
    R, n = counts.shape
    col = np.arange(n + 1)
    face = np.where(col == n, 0, col)
    seg = np.concatenate([[0], np.cumsum(np.diff(turn) != 1)])
    vs, ths, fs, ss, rs = [], [], [], [], []
    for s_ in np.unique(seg):
        rows = np.flatnonzero(seg == s_)
        cum = np.concatenate([[0.0], np.cumsum(counts[rows].ravel())])
        ph = np.concatenate([theta[rows, :n].ravel(), theta[rows[-1:], n]])
        vs.append(cum - (ph - ph[0]))
        ths.append(ph)
        fs.append(np.concatenate([np.tile(face[:n], len(rows)), [0]]))
        ss.append(np.full(len(ph), s_))
        rs.append(np.append(np.repeat(turn[rows], n), turn[rows[-1]] + 1))
    return tuple(np.concatenate(a) for a in (vs, ths, fs, ss, rs))


def fit_pattern(counts: np.ndarray, theta: np.ndarray, turn: np.ndarray,
                sigmas: np.ndarray | None = None, dk_range: float | None = None
                ) -> tuple[float, np.ndarray, tuple[float, float, float]]:
    """The floors' pattern along the phase path: the counts per revolution's correction dk
    [counts], each face's phase offset [counts], and the autocollimator's jitter [counts]:
    (lowest, most likely, highest) the pulses allow.

    Along a run of consecutive revolutions a pulse's count from the run's start less the
    path's phase advance is v = c_f - frac(theta + phi_f) + delta: a constant per face, the
    floor's sawtooth, and the jitter's step delta in {-1, 0, 1} where the pulse crossed its
    floor (P(+1) = Phi((y - 1) / sigma), P(-1) = Phi(-y / sigma), y = frac(theta + phi_f)).
    (dk within +-``dk_range``, by default 1/R per run of consecutive revolutions — the
    error of a mean of floors — and phi_f) by grid search (least squares, each face alone;
    the phase's offset per run free); then sigma by maximum
    likelihood of the steps — from the few pulses near a step, but from every revolution (a
    20 % estimate where the per-interval scatter, 1/6 + 2 sigma^2, cannot tell 0.06 counts
    from none).
    """
    from scipy.special import ndtr  # (the normal CDF; scipy.stats costs 0.8 s to import)

    n = counts.shape[1]
    v, ph, fc, sg, rev = _chains(counts, theta, turn)
    # The pulses grouped by face (a stable sort: each (run, face) group keeps its time order,
    # so every sum below adds the same numbers in the same order): each face one slice.
    order = np.argsort(fc, kind="stable")
    v, ph, fc, sg, rev = (a_[order] for a_ in (v, ph, fc, sg, rev))
    edges = np.searchsorted(fc, np.arange(n + 1))
    # Index of each pulse's (run, face) group: its constant c_f.
    grp = sg * n + fc
    ng = int(grp.max()) + 1
    count = np.bincount(grp, minlength=ng)
    size = np.maximum(count, 1)
    first = np.cumsum(count) - count  # where each group starts among the pulses by group
    grid = (np.arange(64) + 0.5) / 64

    # Per face: its pulses and where each (run, face) group starts among them (runs are
    # consecutive in time order), for the group sums by reduceat.
    parts = []
    for f in range(n):
        m = slice(edges[f], edges[f + 1])
        starts = np.flatnonzero(np.diff(grp[m], prepend=-1))
        parts.append((m, starts, np.diff(np.append(starts, m.stop - m.start))))

    def score(dk: float) -> tuple[float, float, np.ndarray]:
        x = (ph + dk * rev) % 1.0
        total, phi = 0.0, np.zeros(n)
        for f, (m, starts, cnt) in enumerate(parts):
            # v + (x + grid) % 1 (grid, pulses), the remainder taken as a subtraction of 1
            # past 1: the same numbers (x + grid < 2; both exact) at an eighth of the cost.
            w = np.add.outer(grid, x[m])
            np.subtract(w, w >= 1.0, out=w)
            w += v[m]
            sums = np.add.reduceat(w, starts, axis=1)
            rss = np.square(w, out=w).sum(1) - (sums**2 / cnt).sum(1)
            i = int(np.argmin(rss))
            total += float(rss[i])
            phi[f] = grid[i]
        return total, dk, phi

    # dk coarse (a phase error of 1/20 count at the ends), then fine around the best. The
    # mean counts per revolution is off by up to 1/R for each run of consecutive
    # revolutions (the floors at its ends; excluded revolutions cut the log into runs).
    step = 1 / 10 / (turn[-1] - turn[0] + 1)
    if dk_range is None:
        dk_range = (int(sg.max()) + 1) / (turn[-1] - turn[0] + 1)
    k = int(np.ceil(dk_range / step))
    best = min((score(dk) for dk in np.arange(-k, k + 1) * step), key=lambda b: b[0])
    best = min((score(best[1] + dk) for dk in np.arange(-5, 6) * step / 5),
               key=lambda b: b[0])
    _, dk0, phi0 = best
    # A coarse grid of jitters while the pattern is refined, a fine one for the profile.
    s_ = np.geomspace(0.004, 0.5, 12)[:, None]

    def loglik(dk: float, phi: np.ndarray) -> np.ndarray:
        """Log-likelihood (faces, sigmas) of the steps."""
        y = (ph + dk * rev + phi[fc]) % 1.0
        w = v + y
        d = np.round(w - (np.bincount(grp, w, ng) / size)[grp])
        # The constant by the most common step (zero: most pulses do not cross): each
        # group's median, (middle + middle) / 2 of its sorted steps as np.median takes it.
        ds = d[np.lexsort((d, grp))]
        med = (ds[np.minimum(first + (count - 1) // 2, len(d) - 1)]
               + ds[np.minimum(first + count // 2, len(d) - 1)]) / 2
        d -= med[grp]
        p_up, p_dn = ndtr((y - 1) / s_), ndtr(-y / s_)
        like = np.where(d > 0, p_up, np.where(d < 0, p_dn, 1 - p_up - p_dn))
        lg = np.log(np.maximum(like, 1e-300))
        return np.stack([lg[:, edges[f]:edges[f + 1]].sum(1) for f in range(n)])

    # Least squares counts a step as a misfit of 1 and so places the sawtooth a little off
    # (an apparent jitter 15 % high): refined by the likelihood itself, dk about the
    # centre of the log (the phases there held), each face's phase by +-2/128.
    mid = float(np.mean(rev))
    best_ll, dk, phi, ll = -np.inf, dk0, phi0, None
    shifts = np.arange(-2, 3) / 128
    for ddk in np.arange(-3, 4) * step / 10:
        lf = np.stack([loglik(dk0 + ddk, (phi0 - ddk * mid + sh) % 1.0) for sh in shifts])
        tot = lf.max(0).sum(0)  # (shifts, faces, sigmas) -> sigmas
        if tot.max() > best_ll:
            best_ll, dk, ll = float(tot.max()), dk0 + ddk, tot
            phi = (phi0 - ddk * mid + shifts[lf[:, :, int(np.argmax(tot))].argmax(0)]) % 1.0
    # The profile on a fine grid of jitters at the best pattern.
    if sigmas is None:
        sigmas = np.geomspace(0.004, 0.5, 96)
    s_ = sigmas[:, None]
    ll = loglik(dk, phi).sum(0)
    # The jitters the pulses allow (log-likelihood within 2 of its maximum, ~95 %): wide
    # where few pulses come near a step (a locked phase).
    ok = np.flatnonzero(ll >= ll.max() - 2)
    return dk, phi, (float(sigmas[ok[0]]), float(sigmas[int(np.argmax(ll))]),
                     float(sigmas[ok[-1]]))


def _dks(dk: float | None, span: float, spread: float | None) -> np.ndarray:
    """Counts-per-revolution corrections averaged over: the fitted one +-1/(8 R) (the
    pattern's resolution), or +-1/R without a fit (``spread`` [counts] when given)."""
    if spread is None:
        spread = (1 / 8 if dk is not None else 1.0) / span
    return (dk or 0.0) + np.linspace(-spread, spread, K_STEPS)


def variance_of_mean(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
                     rate: float, sigma: float, dk: float | None = None,
                     spread: float | None = None, links: np.ndarray | None = None
                     ) -> np.ndarray:
    """Variance [counts^2] of each mean face angle's error from quantisation and jitter
    (sigma [counts] per pulse), averaged over the counts per revolution's uncertainty (dk
    +- ``spread``, see :func:`_dks`); ``links`` as in :func:`phase_path`."""
    theta, turn = phase_path(counts, dt, t_end, rate, links)
    runs = unlinked_runs(turn, dt is not None and t_end is not None)
    R = len(counts)
    w = _weights(counts) / R
    return np.mean([_variance(w, theta, turn, sigma, d, runs)
                    for d in _dks(dk, turn[-1] + 1, spread)], axis=0)


def allan_expected(counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
                   rate: float, sigma: float, tau: int, dk: float | None = None,
                   spread: float | None = None, links: np.ndarray | None = None
                   ) -> np.ndarray:
    """Expected non-overlapping Allan variance [counts^2] of the per-revolution angles at
    averaging ``tau`` revolutions (blocks aligned from the first), under the same model."""
    theta, turn = phase_path(counts, dt, t_end, rate, links)
    runs = unlinked_runs(turn, dt is not None and t_end is not None)
    R, n = counts.shape
    nb = R // tau
    w1 = _weights(counts)  # (n, R, n + 1)
    dks = _dks(dk, turn[-1] + 1, spread)
    sign = np.where(np.arange(2 * tau) < tau, -1.0, 1.0) / tau
    if R <= 256:
        # Short: one weight set per pair of consecutive blocks, zero outside it, in one call.
        w = np.zeros((nb - 1, *w1.shape))  # (pairs, n, R, n + 1)
        for i in range(nb - 1):
            sl = slice(i * tau, (i + 2) * tau)
            w[i, :, sl] = w1[:, sl] * sign[None, :, None]
        return np.mean([_variance(w, theta, turn, sigma, d, runs) for d in dks],
                       axis=0).sum(0) / (2 * (nb - 1))
    tot = np.zeros(n)
    for i in range(nb - 1):  # longer: each pair on its own revolutions
        sl = slice(i * tau, (i + 2) * tau)
        w = w1[:, sl] * sign[None, :, None]
        tot += np.mean([_variance(w, theta[sl], turn[sl], sigma, d, runs[sl]) for d in dks],
                       axis=0)
    return tot / (2 * (nb - 1))
