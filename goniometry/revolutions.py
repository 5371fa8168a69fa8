"""Counter log -> revolutions -> face-angle statistics, in one streaming pass.

Each revolution runs from a face-0 pulse to the next: n_faces intervals, face k -> k+1, the
last closing on face 0. A stretch of rows between two reference marks that has n_faces rows,
alternating counters and face angles within 5 sigma of the log's face pattern (the median of
the chunk's revolutions; sigma the counts' quantisation and jitter, measured) is a clean
revolution, handled vectorised. Every other stretch goes to :mod:`goniometry.faults`, which
decides pulse by pulse from the ring-laser counts (predicted from the neighbouring clean
revolutions) which pulses are faces, which are spurious and which faces are missing; the
revolutions it completes are screened again (5 sigma) and every decision is listed with its
line. The rows before the first reference mark (the log may be armed on any face) and after
the last one are matched the same way (backwards / forwards) and not used unless complete.

Per revolution the angles are closure-normalised, a_k = 2 pi c_k / sum(c) (a whole revolution
is 360 deg whatever the ring laser's scale factor). With pulse times, the per-revolution
sensitivity to a vertical rate is accumulated too, g_k = dt_k - a_k T / 2 pi [s]: removing a
rate rho (the Earth's) from the counts changes a_k by -rho g_k (to 1e-9 relative), so the
Earth rate — from the latitude, or found by the residual loop after the pass — is applied
without reading the log again. Statistics are sums (memory independent of the log's
length); the first ``keep`` revolutions are also kept whole for the loop and the plots.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axisbase.memory import reuse_freed_memory
from goniometry.errors import FaceCountError, LogError
from goniometry.faults import SPURIOUS, revolutions_of, walk
from goniometry.reader import iter_log

SCREEN_SIGMA = 5.0
NEIGHBOURS = 16
LINES_KEPT = 1000
FLUSH_ROWS = 1 << 15
# Fewest usable revolutions: the face pattern that screens pulse faults is learnt from >= 8
# clean revolutions (below that nothing is screened), and the uncertainty's batch means
# need >= 8 blocks (below that u rests on a handful of values and is not a standard
# uncertainty anyone can rely on).
MIN_REVOLUTIONS = 8
# Revolutions on each side of a face-pattern change (see _Pass._pattern_change).
PATTERN_WINDOW = 8
# Reference marks this many revolutions apart decide the log's faces per revolution early.
FACE_COUNT_SEGMENTS = 16

R_SPURIOUS = "spurious pulse (fits no face of the pattern): dropped, its intervals merged"
R_AMBIGUOUS = ("double trigger: two pulses within the match tolerance of one face (which is "
               "the face cannot be known): revolution excluded")
R_MISSING = "missing autocollimator pulse: revolution excluded"
R_REF_FAILED = "reference signal failed (face 0 found by the count pattern): repaired"
R_REF_WRONG = "reference mark on a pulse that is not face 0: mark ignored"
R_LOST = ("a row is missing from the log (counter did not alternate, the counts do not fit): "
          "revolution excluded")
R_LABEL = ("counter id did not alternate but no row is missing (the counts fit the face "
           "pattern): mislabelled, revolution kept")
R_REANCHOR = "face pattern lost: restarted at the next reference mark"
R_SCREEN = "face angles off the pattern by more than 5 sigma: revolution excluded"
R_TAIL = ("face angles off the pattern by more than 5 sigma, but no further than the noise "
          "reaches somewhere in a log this long: revolution excluded, not counted as a fault")

# Which screened revolutions are faults. A log of R revolutions of n faces has n R deviations
# from the pattern; Gaussian noise alone puts one in 1.7e6 beyond 5 sigma, so a long clean log
# has some (2 of 12 clean 60 000-revolution logs were once warned of "pulse faults"). A
# revolution excluded by the screen counts as a fault only beyond the deviation the noise
# exceeds with probability TAIL_ALPHA anywhere in the log (look-elsewhere); 1e-4 rather than
# 1e-3 because the tails measured on jittered logs run ~7x above Gaussian at 5 sigma.
TAIL_ALPHA = 1e-4
# Screened revolutions remembered with their deviation (beyond that, all count as faults).
SCREENED_KEPT = 10000


def noise_reach(samples: int) -> float:
    """The deviation [sigma] that Gaussian noise exceeds with probability ``TAIL_ALPHA``
    somewhere among ``samples`` deviations (never below the screen's 5 sigma)."""
    from statistics import NormalDist

    if samples <= 0:
        return SCREEN_SIGMA
    return max(SCREEN_SIGMA, -NormalDist().inv_cdf(TAIL_ALPHA / (2 * samples)))
R_DROPOUT = ("communication drop-out: rows missing from the log (the time of a row spans more "
             "than its counts' face interval, or the sequence of faces jumps): the revolutions "
             "it spans excluded, not stitched")
# A row's interval is a drop-out when its duration exceeds this many times what its counts
# take at the log's speed (seconds per count, the chunk's median): the counts of the lost
# rows are lost with them, so the row after a gap of k rows holds one face interval's counts
# and k + 1 intervals' time (ratio ~k + 1). A missing autocollimator pulse has both doubled
# (ratio 1) and a glint both split; a table whose speed changed by a third within one face
# interval is no table a goniometer runs on.
DROPOUT_RATIO = 1.5
R_NOPATTERN = "no clean revolution nearby to predict the face pattern: stretch excluded"


def dropouts(count: np.ndarray, dt: np.ndarray | None) -> np.ndarray:
    """Rows whose interval spans a communication drop-out (see ``DROPOUT_RATIO``): their
    duration [s] beyond DROPOUT_RATIO times their counts at the median seconds per count
    (of every 16th row: the speed, not each row, is what the median needs; a full median
    per block cost a quarter of the pass). All False without times (then only the count
    pattern tells, see :func:`phase_break`)."""
    if dt is None or len(count) < 2:
        return np.zeros(len(count), bool)
    step = 16 if len(count) >= 256 else 1
    ratio = dt[::step] / count[::step]
    ratio = ratio[np.isfinite(ratio)]
    if len(ratio) < 2:
        return np.zeros(len(count), bool)
    limit = DROPOUT_RATIO * float(np.median(ratio))
    with np.errstate(invalid="ignore"):  # (the first row's unknown duration: NaN, no gap)
        return dt > limit * count


def phase_break(count: np.ndarray, inc: np.ndarray, tol: float,
                ends_at_ref: bool) -> int | None:
    """Without times, a drop-out from the count pattern: the first row (index into
    ``count``, the rows after a face-0 anchor) where the sequence of faces jumps.

    The lost rows take their counts with them, so every logged interval is still one genuine
    face interval — before the gap they follow the faces 0, 1, 2, ... from the anchor, after
    it at another phase. A missing autocollimator pulse (two intervals merged) or a spurious
    one (an interval split) fits no single face, and is left to the walk. Needs faces whose
    intervals differ by more than ``tol`` (else the phase cannot be seen: None); a whole
    number of revolutions lost keeps the phase, and then the stitched revolution's intervals
    are the genuine ones (without times no Earth-rate correction carries the gap).
    """
    n = len(inc)
    d = np.abs(inc[:, None] - inc[None, :])
    if n < 2 or np.min(d[~np.eye(n, dtype=bool)]) <= 2 * tol:
        return None
    fits = np.abs(count[:, None] - inc[None, :]) <= tol
    one = fits.sum(1) == 1
    face = np.argmax(fits, 1)
    expect = 0  # the face interval the next row should be: 0 -> 1 first
    for i in range(len(count)):
        if not one[i]:
            return None  # a pulse fault first: the walk decides
        if face[i] != expect:
            # Lost rows (their number mod n: the phase jump), if the next rows go on at the
            # new phase; else it is something the walk handles.
            # (or the stretch ends there: at the reference mark the new phase predicts, or at
            # the end of the log).
            after = range(1, min(3, len(count) - i))
            if all(one[i + m] and face[i + m] == (face[i] + m) % n for m in after) and (
                    len(after) == 2 or not ends_at_ref
                    or (face[i] + len(after) + 1) % n == 0):
                return i
            return None
        expect = (expect + 1) % n
    return None


def revolution_hash(counts: np.ndarray) -> np.ndarray:
    """A 64-bit hash of each row of counts (polynomial, wrapping: numpy's uint64 arithmetic
    wraps without a word)."""
    c = np.asarray(counts).astype(np.int64).astype(np.uint64)
    h = np.zeros(len(c), np.uint64)
    for j in range(c.shape[1]):
        h = h * np.uint64(1000003) + c[:, j]
    return h


def repeated_block(h: np.ndarray, window: int = 16, least: int = 32
                   ) -> tuple[int, int, int] | None:
    """A log written twice: a block of half its revolutions (and at least ``least``)
    repeated count for count beside itself: (first revolution, first of its repeat,
    length), else None.

    Why half and not any block: a steady table turns a nearly constant fraction of a count
    further each revolution, so its counts (quantised, with the autocollimator's jitter on
    top, ~0.1 count) come back count for count after some near-period — over tens of
    revolutions by chance (29 of a 120-revolution log was seen). Jitter makes each
    revolution differ with probability ~0.1 at such a return, so a match over half a log
    of >= 64 revolutions (0.9^32 ~ 3 %, times the few-percent chance of a near-period that
    close) is no chance. A shorter block pasted again is not detected. Candidate offsets
    come from equal windows of ``window`` revolution hashes.
    """
    R = len(h)
    need = max(least, window, (R - 1) // 2)
    if R < window + need:
        return None
    key = np.zeros(R - window + 1, np.uint64)
    for k in range(window):
        key = key * np.uint64(0x9E3779B97F4A7C15) + h[k:R - window + 1 + k]
    order = np.argsort(key, kind="stable")  # (ties in position order)
    ks = key[order]
    same = ks[1:] == ks[:-1]
    if not same.any():
        return None
    offsets = (order[1:] - order[:-1])[same]
    vals, cnt = np.unique(offsets[offsets > 0], return_counts=True)
    if not len(vals):
        return None
    d = int(vals[np.argmax(cnt)])
    eq = np.concatenate([[False], h[:-d] == h[d:], [False]])
    edges = np.flatnonzero(np.diff(eq.astype(np.int8)))
    starts, ends = edges[::2], edges[1::2]
    k = int(np.argmax(ends - starts))
    run = int(ends[k] - starts[k])
    # A copy lies beside its block (d >= run); a log whose revolutions repeat with a short
    # period (a steady table, a whole number of counts a revolution, no jitter: every
    # revolution alike) matches itself at that period over nearly all of it (d < run) —
    # no sign of a copy, and nothing a copy could be told apart from.
    if run < need or d < run:
        return None
    return int(starts[k]), int(starts[k]) + d, run


def rowsum(a: np.ndarray) -> np.ndarray:
    """Sum over the (few) faces of each revolution: numpy's axis-1 reduction over 4 columns
    costs ~5x more per row than adding the columns."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out += a[:, j]
    return out


def rowall(a: np.ndarray) -> np.ndarray:
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out &= a[:, j]
    return out


def rowany(a: np.ndarray) -> np.ndarray:
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out |= a[:, j]
    return out


@dataclass
class Exclusions:
    """What was excluded or repaired, by reason, with line numbers (the first 1000)."""

    counts: Counter = field(default_factory=Counter)
    lines: dict = field(default_factory=dict)

    def add(self, reason: str, line: int) -> None:
        self.counts[reason] += 1
        got = self.lines.setdefault(reason, [])
        if len(got) < LINES_KEPT:
            got.append(int(line))


@dataclass
class AllanAccumulator:
    """Non-overlapping Allan variance of a vector series at octave averaging lengths
    (1, 2, 4, ... 2^(levels-1) revolutions), accumulated batch by batch with bounded memory
    (at most one pending block mean per level). Columns are [a (n), g (n)]: the cross sums
    a_k g_k give the Allan variance of a - rho g for any rho afterwards."""

    n: int
    levels: int = 16
    pending: list = field(init=False)
    prev: list = field(init=False)
    sq: np.ndarray = field(init=False)
    cross: np.ndarray = field(init=False)
    pairs: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.pending = [None] * self.levels
        self.prev = [None] * self.levels
        self.sq = np.zeros((self.levels, 2 * self.n))
        self.cross = np.zeros((self.levels, self.n))
        self.pairs = np.zeros(self.levels, int)

    def add(self, x: np.ndarray) -> None:
        # Level m's stream is the means of blocks of 2^m rows, aligned from the first row;
        # level m+1's is the pairwise means of level m's (a cascade: the work halves per
        # level, instead of re-averaging the raw rows at every level). The sums of squares
        # and the cross products come from one Gram matrix of the differences (one read of
        # them), the pair across the batch boundary and the odd row left over are handled
        # apart: no copies of a whole level.
        n = self.n
        data = x
        for m in range(self.levels):
            if not len(data):
                break
            d = data[1:] - data[:-1]
            gram = d.T @ d
            pairs = len(d)
            if self.prev[m] is not None:  # the pair across the batch boundary
                b = data[0] - self.prev[m]
                gram += np.outer(b, b)
                pairs += 1
            self.sq[m] += np.diagonal(gram)
            self.cross[m] += np.diagonal(gram[:n, n:])
            self.pairs[m] += pairs
            self.prev[m] = data[-1].copy()
            head = None
            if self.pending[m] is not None:  # the odd row of the last batch pairs with row 0
                head = (self.pending[m] + data[0]) * 0.5
                data = data[1:]
            k = len(data) // 2
            self.pending[m] = data[2 * k].copy() if len(data) > 2 * k else None
            nxt = data[0:2 * k:2] + data[1:2 * k:2]
            nxt *= 0.5
            data = nxt if head is None else np.concatenate([head[None], nxt])

    def deviation(self, rate: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Averaging lengths [revolutions] and Allan deviation per face of a - rate g
        (levels with >= 3 pairs)."""
        ok = self.pairs >= 3
        n = self.n
        taus = 2.0 ** np.arange(self.levels)[ok]
        var = (self.sq[ok, :n] - 2 * rate * self.cross[ok] + rate**2 * self.sq[ok, n:])
        return taus, np.sqrt(np.maximum(var, 0) / (2 * self.pairs[ok, None]))


def fill_first_interval(counts: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Durations with the unknown ones (the log's first interval, started by the unlogged
    arming pulse) taken from the revolution's own count rate."""
    if np.isfinite(dt.sum()):  # (one reduction; the mask only when something is missing)
        return dt
    miss = ~np.isfinite(dt)
    known_c = np.where(miss, 0.0, counts).sum(1, keepdims=True)
    known_t = np.where(miss, 0.0, dt).sum(1, keepdims=True)
    return np.where(miss, counts * known_t / np.maximum(known_c, 1.0), dt)


@dataclass
class RevolutionStats:
    """Streaming sums over the usable revolutions of y = [a (n), g (n)]: angles a [rad] and
    rate sensitivities g [s] (zero without times); counts; the first ``keep`` kept whole."""

    n_faces: int
    keep: int = 50000
    n: int = 0
    s1: np.ndarray = field(init=False)
    s2: np.ndarray = field(init=False)
    total_sum: float = 0.0
    allan: AllanAccumulator = field(init=False)
    kept_counts: list = field(default_factory=list)
    kept_dt: list = field(default_factory=list)
    kept_tend: list = field(default_factory=list)
    n_kept: int = 0
    shift: np.ndarray | None = None
    pending: list = field(default_factory=list)
    n_pending: int = 0
    # Called once with the first ``on_kept_at`` kept revolutions (see read_revolutions).
    on_kept: Callable | None = None
    on_kept_at: int = 0
    # One 64-bit hash of each revolution's counts, in order (8 bytes a revolution; logs
    # without times only): a log written twice (see ``repeated_block``).
    hashes: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.s1 = np.zeros(2 * self.n_faces)
        self.s2 = np.zeros((2 * self.n_faces, 2 * self.n_faces))
        self.allan = AllanAccumulator(self.n_faces)

    def flush(self) -> None:
        """Fold the pending revolutions into the sums (batched: the per-call cost of the
        Allan cascade's 16 levels dominated at one call per parsed block)."""
        if not self.pending:
            return
        y = self.pending[0] if len(self.pending) == 1 else np.concatenate(self.pending)
        self.pending, self.n_pending = [], 0
        # Rows y - shift (see add). (A matrix product sums the columns: 7x faster than
        # numpy's column reduction of rows this short.)
        self.n += len(y)
        self.s1 += np.ones(len(y)) @ y
        self.s2 += y.T @ y
        self.allan.add(y)  # (differences and means: the shift does not matter)

    def add(self, counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
            correct=None) -> None:
        if len(counts) == 0:
            return
        if dt is None:  # (with times the reader refuses a copy: no hash needed)
            self.hashes.append(revolution_hash(counts))
        counts = counts.astype(float)
        if correct is not None and dt is not None:
            counts = correct(counts, dt)
        n = self.n_faces
        tot = rowsum(counts)
        y = np.empty((len(counts), 2 * n))
        a, g = y[:, :n], y[:, n:2 * n]
        np.multiply(counts, (2 * np.pi / tot)[:, None], out=a)
        if dt is None:
            g[...] = 0.0
        else:
            d = fill_first_interval(counts, dt)
            np.multiply(a, (rowsum(d) / (2 * np.pi))[:, None], out=g)
            np.subtract(d, g, out=g)
        if self.shift is None:
            self.shift = y[0].copy()  # sums about a first value stay accurate
        y -= self.shift
        self.total_sum += float(tot.sum())
        self.pending.append(y)
        self.n_pending += len(y)
        if self.n_pending >= FLUSH_ROWS:
            self.flush()
        room = self.keep - self.n_kept
        if room > 0:
            m = min(room, len(counts))
            self.kept_counts.append(counts[:m].copy())
            # Copies: the rows may be views into a whole chunk.
            self.kept_dt.append(None if dt is None else np.array(dt[:m], float))
            self.kept_tend.append(None if t_end is None else np.array(t_end[:m], float))
            self.n_kept += m
            if self.on_kept is not None and self.n_kept >= self.on_kept_at:
                self.hand_over()

    def kept(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The kept revolutions: counts (R, n), interval durations (R, n) [s] and end times
        [s] (None without times)."""
        if not self.kept_counts:
            return np.zeros((0, self.n_faces)), None, None
        c = np.vstack(self.kept_counts)
        if self.kept_dt[0] is None:
            return c, None, None
        return c, np.vstack(self.kept_dt), np.concatenate(self.kept_tend)

    def hand_over(self) -> None:
        """Give the first ``on_kept_at`` kept revolutions to ``on_kept``, once."""
        if self.on_kept is None:
            return
        hook, self.on_kept = self.on_kept, None
        m = self.on_kept_at
        c, d, te = self.kept()
        hook(c[:m], None if d is None else d[:m], None if te is None else te[:m])


@dataclass(frozen=True)
class LogSummary:
    """One pass over a log: ``stats`` (sums over the revolutions used), ``exclusions``
    (every fault and decision, with lines), ``rows``; ``incomplete_head``: rows before the
    first complete revolution (the log armed on face ``armed_face``, None when unknown);
    ``incomplete_tail``: rows after the last; ``sigma_counts``: the per-interval scatter of
    the clean revolutions [counts] (quantisation and jitter) that the 5-sigma screen uses;
    ``tolerance_counts``: the pulse-to-face match tolerance; ``excluded_revolutions``."""

    stats: RevolutionStats
    exclusions: Exclusions
    has_time: bool
    rows: int
    incomplete_tail: int
    incomplete_head: int = 0
    armed_face: int | None = 0
    sigma_counts: float = float("nan")
    tolerance_counts: float = float("nan")
    excluded_revolutions: int = 0


class _Pass:
    """State of the streaming pass (see the module docstring)."""

    def __init__(self, n: int, keep: int, correct, path=None) -> None:
        self.n = n
        self.path = path
        self.stats = RevolutionStats(n, keep)
        self.correct = correct
        self.exc = Exclusions()
        self.carry: dict | None = None
        self.carry_line0 = 0
        self.prev_t = np.nan
        self.started = False  # the first reference mark has been seen (head handled)
        self.pattern: np.ndarray | None = None
        self.sigma: float | None = None
        self.neigh = np.zeros((0, n))
        self.rows = 0
        self.has_time = False
        self.head = 0
        self.armed: int | None = 0
        self.excluded = 0
        self.screened: list[tuple[int, float]] = []  # (line, largest deviation [sigma])
        self.tail = 0
        self.chunks = 0
        self.seg_lengths = np.zeros(0, np.int64)  # rows between reference marks: how many
        self.faces_checked = False
        # The last PATTERN_WINDOW revolutions' face fractions and first lines (a pattern
        # change at a chunk boundary).
        self.last_fracs: tuple[np.ndarray, np.ndarray] | None = None

    # ------------------------------------------------------------------ thresholds
    @property
    def tol(self) -> float:
        """Pulse-to-face tolerance [counts]: +-1 of quantisation at each end, the neighbours'
        mean, and 5 sigma of the measured scatter."""
        return 2.0 + SCREEN_SIGMA * (self.sigma or np.sqrt(1 / 6))

    def _learn(self, frac: np.ndarray, N: np.ndarray) -> None:
        """Face pattern (median fractions) and sigma from this chunk's candidate revolutions."""
        if len(frac) < 8:
            return
        self.pattern = np.median(frac, axis=0)
        if self.sigma is None:
            dev = ((frac - self.pattern) * N[:, None]).ravel()
            s = np.sqrt(1 / 6)
            for _ in range(3):
                w = np.abs(dev) < max(8.0, 6 * s)
                if w.sum() < 8:
                    break
                s = max(np.sqrt(1 / 6), float(np.std(dev[w])))
            self.sigma = s

    def _screen(self, C: np.ndarray, N: np.ndarray | None = None) -> np.ndarray:
        """Revolutions (rows of counts; N their sums) within 5 sigma of the face pattern."""
        if self.pattern is None:
            return np.ones(len(C), bool)
        if N is None:
            N = rowsum(C)
        dev = np.abs(C - self.pattern[None, :] * N[:, None])
        thr = SCREEN_SIGMA * (self.sigma or np.sqrt(1 / 6))
        return rowall(dev <= thr)

    def _pattern_change(self, frac: np.ndarray, N: np.ndarray, lines: np.ndarray) -> None:
        """Refuse a log whose face pattern changes (two tables' logs concatenated): the
        median fractions of PATTERN_WINDOW consecutive revolutions before and after some
        revolution differ by more than the match tolerance on some face. A median of 8 is
        the pattern within 0.6 sigma and ignores up to 3 faulty revolutions; the faces of
        one table do not move by ``tol`` counts (several arc-seconds) within a run."""
        from numpy.lib.stride_tricks import sliding_window_view

        w = PATTERN_WINDOW
        if self.last_fracs is not None:
            frac = np.concatenate([self.last_fracs[0], frac])
            lines = np.concatenate([self.last_fracs[1], lines])
            N = np.concatenate([np.full(len(self.last_fracs[0]), np.median(N)), N])
        if len(frac) < 2 * w:
            return
        med = np.median(sliding_window_view(frac, (w, frac.shape[1]))[:, 0], axis=1)
        step = np.abs(med[w:] - med[:-w]) * np.median(N)  # window ending at m vs starting there
        k = int(np.argmax(step.max(1)))
        face = int(np.argmax(step[k]))
        if step[k, face] <= self.tol:
            return
        # The first revolution of the window after the change; say where and by how much.
        m = k + w
        counts = float((med[m, face] - med[k, face]) * np.median(N))
        arcsec = float((med[m, face] - med[k, face]) * 360 * 3600)
        raise LogError(f"{self.path}:{int(lines[m])}: the face pattern changes here (the "
                       f"interval after face {face} by {counts:+.0f} counts, {arcsec:+.1f}″; "
                       f"one table's faces stay within {self.tol:.1f} counts): two tables' "
                       "logs concatenated? Measure each log alone")

    # ------------------------------------------------------------------ streaming
    def feed(self, ch) -> None:
        n = self.n
        self.rows += len(ch.count)
        self.has_time = ch.t is not None
        dt = None
        if self.has_time:
            # (the reader has checked that time increases, across chunks too)
            dt = np.diff(ch.t, prepend=self.prev_t)
            self.prev_t = ch.t[-1]
        cur = {"count": ch.count, "counter": ch.counter, "ref": ch.ref, "t": ch.t, "dt": dt}
        line0 = ch.first_line
        if self.carry is not None:
            cur = {k: (None if v is None else np.concatenate([self.carry[k], v]))
                   for k, v in cur.items()}
            line0 = self.carry_line0
        cur["gap"] = dropouts(cur["count"], cur["dt"])
        refs = np.flatnonzero(cur["ref"])
        if not refs.size:
            self.carry, self.carry_line0 = cur, line0
            return
        X = np.cumsum(cur["count"])
        counter = cur["counter"]
        brk = np.zeros(len(counter), bool)
        brk[1:] = counter[1:] == counter[:-1]
        a0 = int(refs[0])  # anchor: the first reference mark (row 0 after the first chunk)
        starts, ends = refs[:-1] + 1, refs[1:]
        lengths = ends - starts + 1
        if not self.faces_checked:
            self._check_faces(lengths, self.path)
        normal = lengths == n
        used: list[tuple[int, np.ndarray, np.ndarray | None, np.ndarray | None]] = []
        seg_used = np.zeros(0, int)
        C_used = np.zeros((0, n))
        if normal.any():
            if normal.all():
                sl = slice(a0 + 1, int(refs[-1]) + 1)  # back to back: views, no gathers
                C = cur["count"][sl].reshape(-1, n)
                B = rowany((brk[sl] | cur["gap"][sl]).reshape(-1, n))
                D = None if dt is None else cur["dt"][sl].reshape(-1, n)
            else:
                idx = starts[normal][:, None] + np.arange(n)[None, :]
                C, B = cur["count"][idx], rowany(brk[idx] | cur["gap"][idx])
                D = None if dt is None else cur["dt"][idx]
            Nr = rowsum(C)
            # The pattern (fractions of a revolution) is constant: learnt from the first
            # chunk, refreshed every 16th (a median per chunk cost 0.3 s at 1e7 rows).
            self.chunks += 1
            if self.pattern is None or self.sigma is None or self.chunks % 16 == 0:
                good = ~B
                self._learn(C[good] / Nr[good, None], Nr[good])
            ok = ~B & self._screen(C, Nr)
            if int((~ok & ~B).sum()) >= PATTERN_WINDOW:  # (cheap gate: a change fails the screen)
                self._pattern_change(C[~B] / Nr[~B, None], Nr[~B],
                                     line0 + starts[normal][~B])
            if np.any(~B):
                keep = np.flatnonzero(~B)[-PATTERN_WINDOW:]
                self.last_fracs = (C[keep] / Nr[keep, None], line0 + starts[normal][keep])
            seg_used = np.flatnonzero(normal)[ok]
            C_used = C[ok]
            all_ok = bool(ok.all())
            ends_used = ends[seg_used]
            used.append((int(ends_used[-1]) if len(ends_used) else -1,
                         C if all_ok else C_used,
                         None if D is None else (D if all_ok else D[ok]),
                         None if dt is None else cur["t"][ends_used]))
            if len(C_used):
                self.neigh = C_used[-NEIGHBOURS:].astype(float)
        is_bad = np.ones(len(starts), bool)
        is_bad[seg_used] = False
        bad = np.flatnonzero(is_bad)
        if bad.size:
            # Consecutive bad segments form one stretch from the anchor before them.
            groups = np.split(bad, np.flatnonzero(np.diff(bad) > 1) + 1)
            for g in groups:
                s0, s1 = int(g[0]), int(g[-1])
                nb = np.concatenate([C_used[seg_used < s0][-NEIGHBOURS:],
                                     C_used[seg_used > s1][:NEIGHBOURS]])
                used += self._stretch(cur, X, brk, int(starts[s0]) - 1, int(ends[s1]), nb,
                                      line0)
        if not self.started:
            self.started = True
            nb = C_used[:NEIGHBOURS] if len(C_used) else self.neigh
            used += self._head(cur, X, brk, a0, nb, line0)
        if len(used) > 1:
            # One add in revolution order: the statistics' successive differences (Allan
            # variance, batch means) must see a repaired revolution where it was, not after
            # the chunk's clean ones (it changed u by up to 35 % for one repaired pulse).
            keys = []
            for j, (e, c, _, _) in enumerate(used):
                m = len(c)
                if j == 0 and normal.any():
                    keys.append(ends_used.astype(float))  # the clean block: one end per row
                else:  # a repaired stretch: consecutive revolutions ending at row e
                    keys.append(e - 1e-3 * (m - 1 - np.arange(m)))
            order = np.argsort(np.concatenate(keys), kind="stable")
            c = np.concatenate([np.asarray(u[1]).reshape(-1, n) for u in used])[order]
            d = (None if used[0][2] is None else
                 np.concatenate([np.asarray(u[2]).reshape(-1, n) for u in used])[order])
            te = (None if used[0][3] is None else
                  np.concatenate([np.asarray(u[3]).ravel() for u in used])[order])
            used = [(0, c, d, te)]
        for _, c, d, te in used:
            self.stats.add(c, d, te, self.correct)
        last = int(refs[-1])
        self.carry = {k: (None if v is None else v[last:]) for k, v in cur.items()}
        self.carry_line0 = line0 + last

    def _check_faces(self, lengths: np.ndarray, path, final: bool = False) -> None:
        """Refuse a log whose reference marks are mostly some other number of rows apart
        than the faces named: every revolution would be walked as a fault (slowly) and
        none completed. Decided once, from the first FACE_COUNT_SEGMENTS revolutions (or
        the whole log when shorter)."""
        if len(lengths):
            self.seg_lengths = np.concatenate([self.seg_lengths, lengths])
        m = len(self.seg_lengths)
        if not m or (m < FACE_COUNT_SEGMENTS and not final):
            return
        self.faces_checked = True
        vals, cnt = np.unique(self.seg_lengths, return_counts=True)
        k = int(np.argmax(cnt))
        mode, share = int(vals[k]), int(cnt[k])
        # A majority: faults (missing, spurious pulses) change a few lengths, never most; a
        # multiple of n is a reference signal that fails often (repaired by the walk) — if
        # some revolutions do have n rows.
        whole = mode % self.n == 0 and bool(np.any(self.seg_lengths == self.n))
        if mode != self.n and not whole and 2 * share > m:
            raise FaceCountError(path, mode, self.n, share, m)

    def finish(self, path) -> LogSummary:
        one = f"{self.n} rows from one reference pulse to the next"
        if self.rows <= self.n:
            raise LogError(f"{path}: {self.rows} rows, fewer than one revolution ({one})")
        if not self.started:
            raise LogError(f"{path}: no reference pulse at all (ref column never 1): faces "
                           "cannot be identified")
        if not self.faces_checked:
            self._check_faces(np.zeros(0, np.int64), path, final=True)
        cur = self.carry
        L = len(cur["count"]) - 1  # rows after the last reference mark
        if L > 0:
            X = np.cumsum(cur["count"])
            brk = np.zeros(L + 1, bool)
            brk[1:] = cur["counter"][1:] == cur["counter"][:-1]
            got = self._stretch(cur, X, brk, 0, L, self.neigh, self.carry_line0, tail=True)
            for _, c, d, te in got:
                self.stats.add(c, d, te, self.correct)
        self.stats.flush()
        if self.stats.hashes and not self.has_time:  # (with times the reader refuses a copy)
            rep = repeated_block(np.concatenate(self.stats.hashes))
            if rep is not None:
                a, b, m = rep
                line = 2 + self.head + b * self.n  # (exact when nothing was excluded before)
                raise LogError(
                    f"{path}:{line}: usable revolutions {b + 1}-{b + m} repeat revolutions "
                    f"{a + 1}-{a + m} count for count ({m} revolutions; chance never does "
                    "that): the log written twice, or a block of it pasted again? Remove "
                    "the copy")
        self.stats.hand_over()  # (a log shorter than on_kept_at: what there is)
        self._tails()
        if self.stats.n < MIN_REVOLUTIONS:
            raise LogError(f"{path}: only {self.stats.n} usable revolutions in {self.rows} "
                           f"rows ({self.excluded} excluded): at least {MIN_REVOLUTIONS} "
                           "are needed (to learn the face pattern that screens pulse faults, "
                           "and to estimate the uncertainty)")
        return LogSummary(self.stats, self.exc, self.has_time, self.rows, self.tail, self.head,
                          self.armed, float(self.sigma or np.sqrt(1 / 6)), self.tol,
                          self.excluded)

    def _tails(self) -> None:
        """Screened revolutions within the noise's reach in a log this long: moved from
        R_SCREEN to R_TAIL (still excluded; see ``TAIL_ALPHA``)."""
        reach = noise_reach(self.n * (self.stats.n + self.excluded))
        tail = [line for line, z in self.screened if z <= reach]
        if not tail:
            return
        faults = [line for line, z in self.screened if z > reach]
        self.exc.counts[R_SCREEN] -= len(tail)
        if self.exc.counts[R_SCREEN] <= 0:
            del self.exc.counts[R_SCREEN]
            self.exc.lines.pop(R_SCREEN, None)
        else:
            self.exc.lines[R_SCREEN] = faults[:LINES_KEPT]
        for line in tail:
            self.exc.add(R_TAIL, line)

    # ------------------------------------------------------------------ slow path
    def _inc(self, nb: np.ndarray) -> np.ndarray | None:
        """Predicted face-to-face counts: the mean of the neighbouring clean revolutions."""
        if len(nb) < 4:
            nb = np.concatenate([nb, self.neigh])
        if not len(nb):
            return None
        return np.asarray(nb, float).mean(0)

    def _stretch(self, cur: dict, X: np.ndarray, brk: np.ndarray, anchor: int, end: int,
                 nb: np.ndarray, line0: int, tail: bool = False) -> list:
        """Rows anchor+1 .. end, walked forward from the face-0 pulse of row ``anchor``.

        A drop-out (a row whose time spans lost rows, see ``dropouts``) cuts the stretch:
        the revolutions before it are walked, the rows from it to the next reference mark
        (the revolution it broke) are excluded and listed, and the walk starts again there.
        Stitched, the revolution's counts would fit the pattern (whole revolutions lost) but
        its time would carry the gap into the Earth-rate sensitivity.
        """
        gap = cur.get("gap")
        cut = (np.flatnonzero(gap[anchor + 1:end + 1]) + anchor + 1 if gap is not None
               else np.zeros(0, int))
        if cut.size:
            g = int(cut[0])
            out = []
            if g - 1 > anchor:
                out += self._stretch(cur, X, brk, anchor, g - 1, nb, line0, tail)
            elif tail:
                self.tail = 0
            self.exc.add(R_DROPOUT, line0 + g)
            self.excluded += 1
            later = np.flatnonzero(cur["ref"][g:end + 1]) + g
            if later.size and int(later[0]) < end:
                return out + self._stretch(cur, X, brk, int(later[0]), end, nb, line0, tail)
            if tail:
                self.tail += end - g + 1
            return out
        rows = np.arange(anchor + 1, end + 1)
        inc = self._inc(nb)
        if inc is None:
            self.exc.add(R_NOPATTERN, line0 + int(rows[0]))
            self.excluded += max(1, round(len(rows) / self.n))
            return []
        if gap is not None and cur["dt"] is None:
            g = phase_break(np.asarray(cur["count"][anchor + 1:end + 1], float), inc,
                            self.tol, not tail)
            if g is not None:
                gap[anchor + 1 + g] = True  # (cur is this chunk's: the mark stays with it)
                return self._stretch(cur, X, brk, anchor, end, nb, line0, tail)
        w = walk(X[rows] - X[anchor], cur["ref"][rows] > 0, brk[rows], inc, self.tol)
        good, bad = revolutions_of(w, self.n)
        pulse_rows = np.append(rows, anchor)  # index -1 -> the anchor row
        out = self._report(w, good, bad, rows, cur, brk, line0, tail)
        for _, pulses in good:
            r = pulse_rows[pulses]
            out.append(self._revolution(cur, X, r, line0))
        if tail:
            done = max((p[-1] for _, p in good), default=-1)
            self.tail = len(rows) - (done + 1)
        return [u for u in out if u is not None]

    def _head(self, cur: dict, X: np.ndarray, brk: np.ndarray, a0: int, nb: np.ndarray,
              line0: int) -> list:
        """Rows 0..a0 (before the first reference mark), walked backwards from it: the log
        may be armed on any face; the arming pulse (row -1, position 0) closes the head."""
        inc = self._inc(nb)
        if inc is None:
            self.head = a0 + 1
            self.armed = None
            return []
        Xe = np.concatenate([[0], X])  # Xe[r + 1]: position of the pulse ending row r
        gap = cur.get("gap")
        if gap is not None and cur["dt"] is None and a0 > 0:
            # Backwards from the anchor: the first row off the faces' sequence is the one
            # before the gap.
            i = phase_break(np.asarray(cur["count"][a0::-1], float), inc[::-1].copy(),
                            self.tol, False)
            if i is not None:
                gap[a0 - i + 1] = True
        cut = np.flatnonzero(gap[:a0 + 1]) if gap is not None else np.zeros(0, int)
        if cut.size:
            # A drop-out in the head: the pulses before its row are at unknown positions
            # (the lost rows took their counts); walk back to the drop-out's row only.
            g = int(cut[-1])
            self.exc.add(R_DROPOUT, line0 + g)
            rows = np.arange(a0 - 1, g - 1, -1)
            if not rows.size:
                self.head, self.armed = a0 + 1, None
                return []
            isref = cur["ref"][rows] > 0
            bk = brk[rows + 1]
        else:
            rows = np.arange(a0 - 1, -2, -1)  # pulses before the anchor, the arming one last
            isref = np.append(cur["ref"][rows[:-1]] > 0, False)
            # Going backwards, the counter break between rows r and r+1 belongs to pulse r.
            bk = np.append(brk[rows[:-1] + 1], False)
        x = Xe[a0 + 1] - Xe[rows + 1]
        w = walk(x, isref, bk, inc[::-1].copy(), self.tol)
        good, bad = revolutions_of(w, self.n)
        arm = w.face[-1]
        self.armed = int((-arm) % self.n) if arm > 0 and not cut.size else None
        out = self._report(w, good, bad, rows, cur, brk, line0, tail=True, backward=True,
                           armed=not cut.size)
        pulse_rows = np.append(rows, a0)
        for _, pulses in good:
            r = pulse_rows[pulses][::-1]
            out.append(self._revolution(cur, X, r, line0))
        # Rows up to the earliest face pulse of a complete revolution are not used.
        q = max((p[-1] for _, p in good), default=None)
        self.head = a0 + 1 if q is None else int(pulse_rows[q]) + 1
        return [u for u in out if u is not None]

    def _revolution(self, cur: dict, X: np.ndarray, r: np.ndarray, line0: int):
        """One revolution from the rows of its n+1 face pulses (row -1: the arming pulse),
        screened against the pattern."""
        Xe = np.concatenate([[0], X])
        c = np.diff(Xe[r + 1]).astype(float)[None]
        if not self._screen(c)[0]:
            self.exc.add(R_SCREEN, line0 + int(r[-1]))
            self.excluded += 1
            if len(self.screened) < SCREENED_KEPT:
                dev = np.abs(c[0] - self.pattern * c.sum()).max()
                self.screened.append((line0 + int(r[-1]),
                                      float(dev / (self.sigma or np.sqrt(1 / 6)))))
            return None
        d = te = None
        if cur["t"] is not None:
            te_all = np.concatenate([[np.nan], cur["t"]])
            tr = te_all[r + 1]
            d = np.diff(tr)[None]
            te = tr[-1:]
        return (int(r[-1]), c, d, te)

    def _report(self, w, good, bad, rows, cur, brk, line0, tail, backward=False,
                armed=True) -> list:
        """List every fault of a walk with its line (row -1: the arming pulse, line0 - 1)."""
        n = self.n
        line = (lambda i: line0 + int(rows[i])) if not backward else (
            lambda i: line0 + max(int(rows[i]), 0))
        in_good = set()
        for _, pulses in good:
            in_good.update(p for p in pulses if p >= 0)
        for i, f in enumerate(w.face):
            r = int(rows[i])
            isref = r >= 0 and cur["ref"][r] > 0
            if f == SPURIOUS and backward and armed and i == len(rows) - 1:
                # The arming pulse fits no face: the log was armed between faces (the lead-in
                # to the first face is not a revolution, and not a fault: incomplete_head).
                continue
            if f == SPURIOUS:
                self.exc.add(R_SPURIOUS, line(i))
                if isref:
                    self.exc.add(R_REF_WRONG, line(i))
            elif (f > 0 and f % n == 0 and not isref
                  and not (backward and armed and i == len(rows) - 1)):
                self.exc.add(R_REF_FAILED, line(i))
            elif f > 0 and f % n and isref:
                self.exc.add(R_REF_WRONG, line(i))
        for _, idx in w.ambiguous:
            self.exc.add(R_AMBIGUOUS, line(idx[-1]))
        for _, i in w.missing:
            self.exc.add(R_MISSING, line(i))
        for i in w.reanchored:
            self.exc.add(R_REANCHOR, line(i))
        # Counter breaks: a mislabelled row when its revolution is complete, else a lost row.
        for i in range(len(rows)):
            r = int(rows[i])
            if r < 0:
                continue
            if (brk[r] if not backward else (r + 1 < len(brk) and brk[r + 1])):
                if i in in_good:
                    self.exc.add(R_LABEL, line(i))
                else:
                    self.exc.add(R_LOST, line(i))
        if not tail:
            self.excluded += len(bad)
        else:
            self.excluded += sum(1 for _, why in bad if why)
        return []


def read_revolutions(path: str | Path, n_faces: int, keep: int = 50000,
                     block_bytes: int = 1 << 20, correct=None,
                     columns: Mapping[str, str] | None = None,
                     on_kept: Callable | None = None, on_kept_at: int = 0,
                     on_bytes: Callable[[int], None] | None = None) -> LogSummary:
    """Stream a log into revolution statistics in one pass (see module docstring).

    ``correct(counts, dt) -> counts``: applied to each revolution before the statistics
    (e.g. removing the Earth's rotation when the latitude and times are known; the pipeline
    uses the accumulated sensitivities instead, see :func:`goniometry.face_angles`).
    ``on_kept(counts, dt, t_end)``: called once, during the pass, as soon as the first
    ``on_kept_at`` (<= ``keep``) revolutions are kept (at the end for a shorter log), with
    them — work on the head of a log (the loop) can then run while the rest is read.
    ``on_bytes(n)``: called after each chunk with about how many bytes of the file it held
    (``block_bytes``; for a progress bar).
    """
    reuse_freed_memory()  # the pass frees and reallocates MB-sized temporaries per chunk
    if on_kept is not None and not 0 < on_kept_at <= keep:
        raise ValueError(f"on_kept_at {on_kept_at}: must be in 1..keep ({keep})")
    p = _Pass(n_faces, keep, correct, path)
    p.stats.on_kept, p.stats.on_kept_at = on_kept, on_kept_at
    for ch in iter_log(path, block_bytes, columns):
        p.feed(ch)
        if on_bytes is not None:
            on_bytes(block_bytes)
    return p.finish(path)
