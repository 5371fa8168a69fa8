"""Face angles from revolution statistics: means, uncertainty, covariance, Allan deviation.

Uncertainty per angle (GUM): Type A from the scatter of block means of the per-revolution
angles (batch means: revolutions are not independent — the quantisation phase advances almost
periodically and the speed wanders); Type B, quantisation (+-1/2 count uniform at each end of
an interval: q / sqrt(6) per angle per revolution, q = 2 pi / counts per revolution), which
averages as 1/sqrt(R) only while its phase dithers. When the per-revolution scatter is well
below q/sqrt(6) the phase is locked (an integer count per revolution, a quiet autocollimator)
and q/sqrt(6) itself is the uncertainty; otherwise the quantisation is already inside the
measured scatter. The closure (angles sum to 2 pi) makes the angles
negatively correlated: the full covariance is reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import goniometry.beat as beat
from goniometry.errors import LogError
from goniometry.revolutions import LogSummary

OMEGA_EARTH = 7.2921150e-5  # rad/s
# Jitter [counts] from which the count quantisation is dithered (independent pulse to pulse).
DITHERED_COUNTS = 0.5
# A phase path drifting through at least this many whole counts over the log is not locked
# (the counts per revolution known to +-1/R move the drift by up to one count).
UNLOCK_COUNTS = 4.0
# Up to this many revolutions (all kept whole) u comes from the phase-path model.
PATH_MODEL_REVOLUTIONS = 2048
# The floors' pattern (the jitter) is fitted on at most this many revolutions.
FIT_REVOLUTIONS = 512
# The type A method when the floors do not follow the log's phase path (steps everywhere but
# intervals as sharp as quantisation alone): batch means bound what moved the phase — a
# wandering speed whose Earth share the path does not know, or, without times, a drop-out of
# a whole number of revolutions (the faces' sequence goes on, so nothing in the rows shows it,
# but the ring laser's phase went on through the lost revolutions: the floors' steps after
# the gap fall at another phase). Which of the two, and where, the floors cannot tell: a scan
# for a phase offset at every pulse found 2 of 40 stitches and 22 in their 40 clean twins
# (benchmarks/gonio_stitch_scan.py; docs/goniometer-dropouts.md).
METHOD_OFF_PATH = "batch means (floors off the phase path)"


@dataclass(frozen=True)
class FaceAngles:
    """Angles [rad] from face k to face k+1 in passing order (face 0: the reference).

    Per revolution a_k = 2 pi c_k / sum(c) (closure-normalised); the fields are statistics
    of a_k - rho g_k over the revolutions used (rho: the vertical rate removed).

    Attributes
    ----------
    angles_rad : ndarray, shape (n,)
        Means over the revolutions [rad].
    u_rad : ndarray, shape (n,)
        Standard uncertainties [rad]: Type A and the Type B terms in quadrature.
    cov : ndarray, shape (n, n)
        Covariance of the angles [rad^2], in the same order.
    u_type_a_rad, u_type_b_rad : ndarray, shape (n,)
        The two parts of ``u_rad`` [rad].
    revolutions : int
        Revolutions used.
    counts_per_rev : float
        Mean counts of a revolution [ring-laser periods].
    allan_tau_rev, allan_dev_rad : ndarray
        Allan deviation per angle [rad] at averaging lengths [revolutions].
    quantisation_locked : ndarray of bool, shape (n,)
        Angles whose quantisation phase is locked (per-revolution scatter below half of
        q / sqrt(6)): it does not average, and q / sqrt(6) itself enters u.
    type_b_terms : dict of str to ndarray
        Name -> (n,) [rad]: each effect the log cannot determine (or determines only to
        +-u) whose bound enters u.
    type_a_method : str
        How the scatter part was evaluated: "phase path" (the quantisation and jitter along
        the log's own phase path, :mod:`goniometry.beat`), "batch means" or "lag 1".
    jitter_counts : float
        The autocollimator's jitter it used [counts].
    """

    angles_rad: np.ndarray
    u_rad: np.ndarray
    cov: np.ndarray
    u_type_a_rad: np.ndarray
    u_type_b_rad: np.ndarray
    revolutions: int
    counts_per_rev: float
    allan_tau_rev: np.ndarray
    allan_dev_rad: np.ndarray
    quantisation_locked: np.ndarray
    type_b_terms: dict = field(default_factory=dict)
    type_a_method: str = "batch means"
    jitter_counts: float = float("nan")

    @property
    def quantum_rad(self) -> float:
        return 2 * np.pi / self.counts_per_rev


def quantisation_of_mean(frac_per_rev: float, revolutions: int, block: int = 512,
                         grid: int = 256) -> float:
    """Standard deviation [counts] of the quantisation error of one interval's mean count
    over ``revolutions`` revolutions of a steady table whose counts per revolution have the
    fractional part ``frac_per_rev`` (the phase of each floor advances by it every revolution).

    Each interval is floor(b) - floor(a): its error is saw(a) - saw(b) with saw the
    fractional part, the two ends' phases unknown (uniform, independent). Averaged over R
    revolutions, M(phi) = mean_r saw(phi + r f): dithered when f is far from a fraction with
    a small denominator (~1/R), not averaged at all when f ~ 0 (locked), and anything in
    between — which batch means of a short log cannot see (the beat is longer than the
    blocks). Returns sqrt(2) std_phi M. Hand-written: no library computes this; blocks of
    ``block`` revolutions reuse one table of M on a phase grid, so the cost does not grow
    with R.
    """
    f = frac_per_rev % 1.0
    R = int(revolutions)
    B = min(block, R)
    psi = (np.arange(grid) + 0.5) / grid
    # M_B(psi): the fractional parts as x - floor(x) (x >= 0: the remainder's numbers, both
    # exact, at a fifth of its cost).
    x = np.add.outer(psi, np.arange(B) * f)
    m_block = np.subtract(x, np.floor(x), out=x).mean(1)
    nb = R // B
    phis = (np.arange(32) + 0.5) / 32
    starts = (phis[:, None] + np.arange(nb)[None, :] * B * f) % 1.0
    idx = np.minimum((starts * grid).astype(int), grid - 1)
    tot = m_block[idx].sum(1) * B
    rest = R - nb * B
    if rest:
        last = (phis + nb * B * f) % 1.0
        tot += ((last[:, None] + np.arange(rest)[None, :] * f) % 1.0).sum(1)
    return float(np.sqrt(2) * np.std(tot / R))


def face_angles(summary: LogSummary, earth_rate: float = 0.0, earth_rate_u: float = 0.0,
                type_b: dict[str, float] | None = None) -> FaceAngles:
    """Face angles of a log's revolutions.

    Parameters
    ----------
    summary : LogSummary
        The one pass over the log (:func:`goniometry.read_revolutions`).
    earth_rate : float
        Vertical rate [rad/s] removed from the counts (the Earth's, signed as the ring laser
        sees it), applied through the accumulated sensitivities g (exact to 1e-9).
    earth_rate_u : float
        Its standard uncertainty [rad/s], carried into the angles.
    type_b : dict of str to float, optional
        Further rate terms not determined by the log, name -> half-range [rad/s] of the
        rate (e.g. the Earth rate over all latitudes): each enters u as |mean g| times it,
        fully correlated between the angles.

    Returns
    -------
    FaceAngles
        Means, uncertainties [rad], covariance [rad^2] and Allan deviation.

    Raises
    ------
    LogError
        Fewer than 2 usable revolutions.
    """
    st = summary.stats
    if st.n < 2:
        raise LogError(f"only {st.n} usable revolutions: need at least 2")
    n = st.n_faces
    # y = [a, g]: the corrected angles are a - rate g (linear), so their mean, covariance and
    # Allan variance follow from the sums of y for any rate.
    w = np.concatenate([np.eye(n), -earth_rate * np.eye(n)], axis=1)  # (n, 2n)
    mean_y = st.s1 / st.n
    cov_y = (st.s2 - st.n * np.outer(mean_y, mean_y)) / (st.n - 1)
    mean = w @ (st.shift + mean_y)
    cov_rev = w @ cov_y @ w.T
    n_per_rev = st.total_sum / st.n
    var_rev = np.diag(cov_rev)
    ua = np.sqrt(var_rev / st.n)
    taus, adev = st.allan.deviation(earth_rate)
    blocks = st.n / taus
    usable = blocks >= 8
    # The autocollimator's jitter [counts] from the per-interval scatter of the counts about
    # the face pattern: 2 sigma_j^2 + 1/6 (the floor at each end).
    sig = summary.sigma_counts
    jitter = np.sqrt(max((sig**2 - 1 / 6) / 2, 0.0)) if np.isfinite(sig) else 0.0
    if usable.any():
        # Revolutions are not independent; the scatter of block means over the longest
        # averaging with >= 8 blocks gives the uncertainty of the mean (batch means) — from
        # successive differences of nb = 8-16 block means (an Allan variance), i.e.
        # 2 (nb - 1)^2 / (3 nb - 4) = 5-10 degrees of freedom (not nb - 1).
        j = int(np.flatnonzero(usable)[-1])
        nb = blocks[j]
        nu = 2 * (nb - 1) ** 2 / (3 * nb - 4)
        v = np.full(n, adev[j] ** 2 * taus[j] / st.n)
        nu = np.full(n, nu)
        if jitter >= DITHERED_COUNTS and taus[0] == 1:
            # Jitter this large dithers the quantisation (its sawtooth's first harmonic is
            # attenuated by exp(-2 pi^2 sigma_j^2) < 1 %): the pulses' errors are then
            # independent, and the revolutions correlate only through the reference pulse
            # consecutive ones share (the closure divides by counts that end on it), at lag 1.
            # The variance of the mean to lag 1, (gamma0 + 2 gamma1) / R =
            # (3 var - 2 avar(1)) / R, has ~R/3 degrees of freedom instead of 5-10: the
            # normalised errors over 30 logs at 2 us jitter and 0.5 rev/s went from heavy
            # tails (RMS 1.18) to RMS 1.13, that of the exact u on the same logs.
            # Batch means are kept where they are significantly larger (F-test, 5 %): what
            # correlates farther revolutions (a wandering speed) only they see.
            from scipy.special import fdtrc  # (the F survival function, without scipy.stats)

            nu_1 = st.n / 3
            v_1 = np.maximum(3 * var_rev - 2 * adev[0] ** 2, 0.0) / st.n
            ratio = v / np.maximum(v_1, np.finfo(float).tiny)
            lag1 = fdtrc(nu, nu_1, ratio) >= 0.05
            v = np.where(lag1, v_1, v)
            nu = np.where(lag1, nu_1, nu)
        # An error over a variance estimated from nu degrees of freedom follows Student's t,
        # whose variance is nu / (nu - 2): scaled so the normalised errors have unit variance.
        ua = np.sqrt(v * nu / np.maximum(nu - 2, 1.0))
    method = "batch means" if usable.any() else "scatter"
    if usable.any() and jitter >= DITHERED_COUNTS and taus[0] == 1:
        method = "lag 1" if np.all(lag1) else "batch means"
    model = None
    if st.n_kept == st.n and st.n <= PATH_MODEL_REVOLUTIONS:
        # Short logs (all revolutions kept whole): the quantisation and jitter along the
        # log's own phase path give the variance of each mean with no degrees of freedom
        # to estimate (batch means: 5-10, so Student tails — 3 angles beyond 4 u in 2400 —
        # and blind to a beat longer than their blocks). Longer logs keep batch means.
        model = _path_model(summary, earth_rate, n_per_rev, taus, adev, usable)
        if isinstance(model, str):  # (METHOD_OFF_PATH)
            model = None
            method = METHOD_OFF_PATH if method == "batch means" else method
    q6 = 2 * np.pi / n_per_rev / np.sqrt(6)
    # Averaging beats quantisation only if its phase dithers from one revolution to the
    # next; a scatter well below q/sqrt(6) means it is locked (e.g. an integer number of
    # counts per revolution and little jitter): then it does not average at all.
    locked = np.sqrt(np.diag(cov_rev)) < 0.5 * q6
    ub = np.where(locked, q6, q6 / np.sqrt(st.n))
    # Type B enters only when the quantisation is locked (then it is the whole story);
    # otherwise it is inside the measured scatter — unless the phase beats more slowly than
    # the batch-means blocks can see (nearly locked): its deterministic floor for this log's
    # counts per revolution and length is then the larger.
    # The log knows its counts per revolution only to ~1/R (the quantisation of its ends; a
    # period-2 beat at f = 0.5000 reads as 0.4958 over 119 revolutions): f uniform over that
    # range, the RMS (the spikes at fractions p/q are ~1/(qR) wide).
    fs = n_per_rev + np.linspace(-1, 1, 17) / st.n
    uq = 2 * np.pi / n_per_rev * float(np.sqrt(np.mean(
        [quantisation_of_mean(f, st.n) ** 2 for f in fs])))
    ub = np.where(locked, ub, np.maximum(ub, uq))
    u = np.where(locked, np.maximum(ua, ub), np.maximum(ua, uq))
    if model is not None:
        u_path, consistent, jitter, sweep = model
        # Not locked after all where the phase path drifts through whole counts (the Earth's
        # share of the period near the equator, a slow beat): the per-revolution scatter is
        # small, but the quantisation averages along the drift, which the model follows.
        # UNLOCK_COUNTS: beyond the drift the counts per revolution's +-1/R leaves unknown.
        locked = locked & ~(sweep >= UNLOCK_COUNTS)
        # The model is the whole per-revolution noise of a clean log; where the scatter of
        # block means is significantly larger than the model says it should be, something
        # else varies (e.g. the Earth rate not removed on an unsteady table): batch means
        # then still bound it.
        ua = np.where(consistent, u_path, np.maximum(ua, u_path))
        # A (nearly) locked phase: its pattern cannot pin the jitter nor the counts per
        # revolution (they trade off), so the steady table's deterministic floor stays a
        # floor (seed 420 of the fault plan: f = 0.000, 0.65 count off, 2.9 u with it).
        u = np.where(locked, np.maximum(ua, ub), np.maximum(ua, uq))
        # The quantisation is inside the model: its white-noise share q/sqrt(6)/sqrt(R) is
        # no floor (a beat averages faster than that), only the deterministic floor uq is —
        # so the Type B part reported never exceeds u.
        ub = np.where(locked, ub, uq)
        method = "phase path" if np.all(consistent) else "phase path + batch means"
    # Scale the scatter covariance so its diagonal is the stated variance (keeps the closure
    # correlations of the measured scatter).
    d = np.sqrt(np.diag(cov_rev) / st.n)
    corr = cov_rev / st.n / np.outer(np.where(d > 0, d, 1), np.where(d > 0, d, 1))
    corr[np.diag_indices(n)] = 1.0  # (also where the scatter is zero: locked quantisation)
    cov = corr * np.outer(u, u)
    # dA_k / d rate = -mean g_k [s]: a rate known to +-u moves the angles together.
    sens = -(st.shift + mean_y)[n:]
    terms = {}
    if earth_rate_u:
        terms["earth_rate (estimated)"] = earth_rate_u
    terms.update(type_b or {})
    extra = {}
    for name, half in terms.items():
        cov = cov + np.outer(sens, sens) * half**2
        extra[name] = np.abs(sens) * half
    ub_all = np.sqrt(ub**2 + sum(v**2 for v in extra.values())) if extra else ub
    return FaceAngles(mean, np.sqrt(np.diag(cov)), cov, ua, ub_all, st.n, n_per_rev, taus,
                      adev, locked, extra, method, float(jitter))


def _path_model(summary: LogSummary, rate: float, n_per_rev: float, taus: np.ndarray,
                adev: np.ndarray, usable: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray] | str | None:
    """u [rad] of each angle from the quantisation and jitter along the kept revolutions'
    phase path (:mod:`goniometry.beat`), whether the batch means agree with it (one-sided
    chi-square at 1 %), and the fitted jitter [counts]. None when the log has too few
    revolutions for the pattern, or its pattern does not follow the path."""
    from scipy.special import chdtrc  # (the chi-square survival function)


    counts, dt, t_end = kept_table(summary)
    # Without times, where revolutions were excluded the path goes on with an unknown phase
    # (see beat.unlinked_runs): the kept revolutions' lines say where.
    links = summary.stats.kept_links() if dt is None else None
    if len(counts) < 16 or (dt is None and summary.excluded_revolutions and links is None):
        return None
    theta, turn = beat.phase_path(counts, dt, t_end, rate, links)
    # The pattern from the longest run of consecutive revolutions (at most FIT_REVOLUTIONS:
    # the fit's cost grows with R). Where excluded revolutions cut the log, the runs'
    # patterns did not join up to a common counts per revolution (a lost row, seed 256 of
    # the fault plan): the jitter is the run's, and the counts per revolution only known to
    # +-1/R (the model averages over that range).
    cut = np.flatnonzero(np.diff(turn) != 1) + 1
    edges = np.concatenate([[0], cut, [len(turn)]])
    i = int(np.argmax(np.diff(edges)))
    a, b = int(edges[i]), min(int(edges[i + 1]), int(edges[i]) + FIT_REVOLUTIONS)
    if b - a < 16:
        return None
    # (the log's mean counts per revolution, which the path uses, is off by up to 1/R per
    # run)
    dk, _, sigmas = beat.fit_pattern(counts[a:b], theta[a:b], turn[a:b],
                                     dk_range=(len(edges) - 1) / len(counts))
    spread = None
    if b - a < len(counts):
        dk, spread = None, (len(edges) - 1) / len(counts)
    # A jitter of a quarter count or more blurs the floors' steps beyond the fit's reach
    # (pulses crossing two floors) but shows in the scatter of the intervals' counts about
    # the path, 1/6 + 2 sigma^2 (to ~10 % at 120 revolutions; below ~0.15 count it cannot
    # be told from none).
    scatter = float(np.mean(np.var(counts - np.diff(theta, axis=1), axis=0, ddof=1)))
    sig_scatter = np.sqrt(max((scatter - 1 / 6) / 2, 0.0))
    if sig_scatter >= 0.25:
        sigmas = (sig_scatter,) * 3
    elif sigmas[1] >= 0.25:
        # Steps everywhere but intervals as sharp as quantisation alone: the path is wrong,
        # not the jitter large (an unsteady table whose Earth rate is not removed: its share
        # of the wandering period walks the phase by counts; without times also a stitched
        # whole-revolution drop-out) — no model then.
        return METHOD_OFF_PATH
    sigma = sigmas[1]
    q = 2 * np.pi / n_per_rev
    # The larger at the two ends of the jitters the pulses allow: a locked phase whose
    # pulses never come near a step says little about the jitter, which decides whether it
    # dithers.
    var = np.max([beat.variance_of_mean(counts, dt, t_end, rate, sg, dk, spread, links)
                  for sg in sorted({sigmas[0], sigmas[2]})], axis=0)
    consistent = np.ones(len(var), bool)
    if usable.any():
        j = int(np.flatnonzero(usable)[-1])
        nb = len(counts) // int(taus[j])
        nu = 2 * (nb - 1) ** 2 / (3 * nb - 4)
        expect = beat.allan_expected(counts, dt, t_end, rate, sigma, int(taus[j]), dk,
                                     spread, links)
        ratio = (adev[j] / q) ** 2 / np.maximum(expect, np.finfo(float).tiny)
        consistent = chdtrc(nu, nu * ratio) >= 0.01
    # How far each pulse's fractional phase drifts over the log [counts] (the net of its
    # per-revolution advances taken modulo one count): an angle whose ends drift through
    # several whole counts has its quantisation averaged, however little the counts of
    # successive revolutions scatter.
    step = np.diff(theta, axis=0)[np.diff(turn) == 1]  # (across a gap: not a drift)
    drift = np.abs((step - np.round(step)).sum(0))
    sweep = np.minimum(drift[:-1], drift[1:])
    return q * np.sqrt(var), consistent, sigma, sweep


def kept_table(summary: LogSummary) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The revolutions the pass kept whole (the first ``keep`` of them).

    Parameters
    ----------
    summary : LogSummary
        The one pass over the log.

    Returns
    -------
    counts : ndarray, shape (R, n)
        Counts of each face interval [ring-laser periods].
    dt : ndarray, shape (R, n), or None
        Interval durations [s] (None without times).
    t_end : ndarray, shape (R,), or None
        End time of each revolution [s] (None without times).
    """
    return summary.stats.kept()


def vertical_earth_rate(latitude_rad: float, direction: int) -> float:
    """The Earth's rotation about the table axis as the ring laser sees it.

    Parameters
    ----------
    latitude_rad : float
        Latitude of the table [rad] (a user's degrees are converted at the edge:
        ``--latitude``, ``latitude_deg`` in session.toml).
    direction : int
        +1: the table turns counter-clockwise seen from above; -1: clockwise.

    Returns
    -------
    float
        direction * Omega_E * sin(latitude) [rad/s].
    """
    return direction * OMEGA_EARTH * np.sin(latitude_rad)


def earth_rate_counts(counts: np.ndarray, dt: np.ndarray, rate: float) -> np.ndarray:
    """Counts with the Earth's rotation during each interval removed (needs durations).

    The ring laser counts inertial rotation: table + ``rate`` [rad/s]. A duration that is
    unknown (the log's first interval, started by the unlogged arming pulse) is taken from the
    revolution's own count rate: leaving that interval uncorrected would bias the first angle
    by the whole Earth share of one interval divided by the number of revolutions (~0.02″ over
    100 revolutions at 1 rev/s — seen as a 0.3 sigma offset of the reference face).

    Parameters
    ----------
    counts : ndarray, shape (R, n)
        Counts of each face interval [ring-laser periods].
    dt : ndarray, shape (R, n)
        Interval durations [s]; NaN where unknown.
    rate : float
        Vertical rate to remove [rad/s].

    Returns
    -------
    ndarray, shape (R, n)
        c - N rate dt / 2 pi [ring-laser periods], N the revolution's counts.
    """
    dt = np.asarray(dt, float)
    miss = ~np.isfinite(dt)
    if miss.any():
        known_c = np.where(miss, 0.0, counts).sum(1, keepdims=True)
        known_t = np.where(miss, 0.0, dt).sum(1, keepdims=True)
        dt = np.where(miss, counts * known_t / np.maximum(known_c, 1.0), dt)
    k = counts.sum(1, keepdims=True)  # ~ pulses per revolution (the 1e-5 Earth share is
    # negligible in the scale)
    return counts - k * rate * dt / (2 * np.pi)
