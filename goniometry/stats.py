"""Streaming statistics of the usable revolutions: sums, Allan variance, the kept head.

Per revolution y = [a (n), g (n)]: closure-normalised angles a_k = 2 pi c_k / sum(c) [rad] and
the rate sensitivities g_k = dt_k - a_k T / 2 pi [s] (zero without times). Sums of y and
y y^T and the Allan cascade take memory independent of the log's length; the first ``keep``
revolutions are also kept whole (for the loop and the plots).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from goniometry.repeats import revolution_hash

FLUSH_ROWS = 1 << 15


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
    # Lines of each kept revolution's first and closing face pulses (see kept_links).
    kept_lines: list = field(default_factory=list)
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
            correct=None, lines: np.ndarray | None = None) -> None:
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
            self.kept_lines.append(None if lines is None else np.array(lines[:m], np.int64))
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

    def kept_links(self) -> np.ndarray | None:
        """Whether each kept revolution after the first starts on the pulse that closed the
        one before (shape (R - 1,)): False where revolutions were excluded between them (a
        drop-out, a fault). None when the lines were not given."""
        if not self.kept_lines or any(x is None for x in self.kept_lines):
            return None
        span = np.vstack(self.kept_lines)
        return span[1:, 0] == span[:-1, 1]

    def hand_over(self) -> None:
        """Give the first ``on_kept_at`` kept revolutions to ``on_kept``, once."""
        if self.on_kept is None:
            return
        hook, self.on_kept = self.on_kept, None
        m = self.on_kept_at
        c, d, te = self.kept()
        hook(c[:m], None if d is None else d[:m], None if te is None else te[:m])

