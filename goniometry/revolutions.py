"""Counter log -> revolutions -> face angles, streaming, with missing/spurious pulse handling.

Each revolution is the run of rows from the one after a reference pulse up to and including
the next reference pulse: n_faces intervals, face k -> k+1, the last one closing on the
reference face. Normal revolutions are handled vectorised; the rare abnormal ones go through
a slow path that repairs with evidence or excludes, and every decision is recorded:

* n_faces + 1 intervals whose two neighbours add up to the expected pattern: a spurious
  pulse split one interval; counts add exactly, so the merge is a repair;
* 2 n_faces intervals matching the pattern twice: the reference signal failed once; split;
* n_faces - 1 intervals: a missing pulse; where it was cannot be known: excluded;
* a counter that does not alternate: a row is missing from the log itself: excluded;
* anything else, or counts off the pattern: excluded.

Per revolution the angles are closure-normalised: a_k = 2 pi c_k / sum(c) (the counts of a
whole revolution are 360 deg, whatever the ring laser's scale factor). Statistics are
accumulated as sums (memory independent of the log's length); the first ``keep``
revolutions are also kept whole for the residual loop and plots.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from goniometry.errors import LogError
from goniometry.reader import iter_log


def _rows(a: np.ndarray, idx: np.ndarray | None, end: int, n: int) -> np.ndarray:
    """Revolutions as rows: a reshaped view when they are back to back (``idx`` None), else
    gathered by ``idx``."""
    return a[:end].reshape(-1, n) if idx is None else a[idx]


def rowsum(a: np.ndarray) -> np.ndarray:
    """Sum over the (few) faces of each revolution: numpy's axis-1 reduction over 4 columns
    costs ~5x more per row than adding the columns."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out += a[:, j]
    return out


def rowany(a: np.ndarray) -> np.ndarray:
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out |= a[:, j]
    return out


@dataclass
class Exclusions:
    """What was excluded or repaired, by reason (with the first few line numbers)."""

    counts: Counter = field(default_factory=Counter)
    lines: dict = field(default_factory=dict)

    def add(self, reason: str, line: int) -> None:
        self.counts[reason] += 1
        self.lines.setdefault(reason, [])
        if len(self.lines[reason]) < 10:
            self.lines[reason].append(line)


@dataclass
class AllanAccumulator:
    """Non-overlapping Allan variance of a vector series at octave averaging lengths
    (1, 2, 4, ... 2^(levels-1) revolutions), accumulated batch by batch with bounded memory
    (at most one pending block mean per level)."""

    n: int
    levels: int = 16
    pending: list = field(init=False)
    prev: list = field(init=False)
    sq: np.ndarray = field(init=False)
    pairs: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.pending = [np.zeros((0, self.n)) for _ in range(self.levels)]
        self.prev = [None] * self.levels
        self.sq = np.zeros((self.levels, self.n))
        self.pairs = np.zeros(self.levels, int)

    def add(self, x: np.ndarray) -> None:
        # Level m's stream is the means of blocks of 2^m rows, aligned from the first row;
        # level m+1's is the pairwise means of level m's (a cascade: the work halves per
        # level, instead of re-averaging the raw rows at every level).
        data = x
        for m in range(self.levels):
            if not len(data):
                break
            d = data[1:] - data[:-1]
            self.sq[m] += np.einsum("ij,ij->j", d, d)
            self.pairs[m] += len(d)
            if self.prev[m] is not None:  # the pair across the batch boundary
                e = data[0] - self.prev[m]
                self.sq[m] += e * e
                self.pairs[m] += 1
            self.prev[m] = data[-1]
            if len(self.pending[m]):
                data = np.concatenate([self.pending[m], data])
            k = len(data) // 2
            self.pending[m] = data[2 * k:].copy()
            data = (data[0:2 * k:2] + data[1:2 * k:2]) * 0.5

    def deviation(self) -> tuple[np.ndarray, np.ndarray]:
        """Averaging lengths [revolutions] and Allan deviation per face (levels with >= 3
        pairs)."""
        ok = self.pairs >= 3
        taus = 2.0 ** np.arange(self.levels)[ok]
        return taus, np.sqrt(self.sq[ok] / (2 * self.pairs[ok, None]))


@dataclass
class RevolutionStats:
    """Streaming sums over the usable revolutions (angles [rad], counts, durations [s])."""

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

    def __post_init__(self) -> None:
        self.s1 = np.zeros(self.n_faces)
        self.s2 = np.zeros((self.n_faces, self.n_faces))
        self.allan = AllanAccumulator(self.n_faces)

    def add(self, counts: np.ndarray, dt: np.ndarray | None, t_end: np.ndarray | None,
            correct=None) -> None:
        if len(counts) == 0:
            return
        if correct is not None and dt is not None:
            counts = correct(counts, dt)
        tot = rowsum(counts)
        a = counts * (2 * np.pi / tot)[:, None]
        if self.shift is None:
            self.shift = a[0].copy()  # sums about a first value keep the variance accurate
        d = a - self.shift
        self.n += len(a)
        self.s1 += d.sum(0)
        self.s2 += d.T @ d
        self.total_sum += float(tot.sum())
        self.allan.add(a)
        room = self.keep - self.n_kept
        if room > 0:
            m = min(room, len(a))
            self.kept_counts.append(counts[:m].astype(float))
            # Copies: the rows may be views into a whole chunk.
            self.kept_dt.append(None if dt is None else dt[:m].copy())
            self.kept_tend.append(None if t_end is None else t_end[:m].copy())
            self.n_kept += m


def _pattern_ok(c: np.ndarray, pattern: np.ndarray | None, rel: float = 2e-3) -> bool:
    if pattern is None:
        return True
    return bool(np.all(np.abs(c / c.sum() - pattern) < rel))


@dataclass(frozen=True)
class LogSummary:
    stats: RevolutionStats
    exclusions: Exclusions
    has_time: bool
    rows: int
    incomplete_tail: int


def read_revolutions(path: str | Path, n_faces: int, keep: int = 50000,
                     block_bytes: int = 1 << 20, correct=None,
                     columns: Mapping[str, str] | None = None) -> LogSummary:
    """Stream a log into revolution statistics (see module docstring).

    ``correct(counts, dt) -> counts``: applied to each revolution before the statistics
    (e.g. removing the Earth's rotation when the latitude and times are known).
    """
    stats = RevolutionStats(n_faces, keep)
    exc = Exclusions()
    pattern: np.ndarray | None = None
    carry = None  # rows after the last reference pulse of the previous chunk
    prev_counter = None
    prev_t = np.nan
    rows = 0
    seen_ref = False
    has_time = False
    for ch in iter_log(path, block_bytes, columns):
        rows += len(ch.count)
        has_time = ch.t is not None
        dt = None
        if has_time:
            # (the reader has checked that time increases, across chunks too)
            dt = np.diff(ch.t, prepend=prev_t)
            prev_t = ch.t[-1]
        brk = np.zeros(len(ch.count), bool)
        brk[1:] = ch.counter[1:] == ch.counter[:-1]
        if prev_counter is not None:
            brk[0] = ch.counter[0] == prev_counter
        prev_counter = ch.counter[-1]
        cur = {"count": ch.count, "brk": brk, "dt": dt, "t": ch.t, "ref": ch.ref}
        if carry is not None:
            cur = {k: (None if v is None else np.concatenate([carry[k], v]))
                   for k, v in cur.items()}
        # File line of row i of ``cur``: rows are consecutive lines.
        line0 = ch.first_line - (0 if carry is None else len(carry["count"]))
        refs = np.flatnonzero(cur["ref"])
        if refs.size:
            seen_ref = True
        starts = np.concatenate([[0], refs[:-1] + 1]) if refs.size else np.array([], int)
        lengths = refs - starts + 1 if refs.size else np.array([], int)
        normal = lengths == n_faces
        if normal.any():
            idx = starts[normal][:, None] + np.arange(n_faces)[None, :]
            # The usual chunk has every revolution normal, back to back: views, no gathers.
            sel = None if normal.all() else idx
            end = int(refs[-1]) + 1
            c = _rows(cur["count"], sel, end, n_faces)
            bad = rowany(_rows(cur["brk"], sel, end, n_faces))
            if pattern is None:
                good = c[~bad]
                if len(good):
                    frac = good / rowsum(good)[:, None]
                    pattern = np.median(frac, axis=0)
            frac = c * (1.0 / rowsum(c))[:, None]
            off = (rowany(np.abs(frac - pattern) >= 2e-3) if pattern is not None
                   else np.zeros_like(bad))
            use = ~bad & ~off
            for i in np.flatnonzero(bad):
                exc.add("a row is missing from the log (counter did not alternate): "
                        "revolution excluded", line0 + int(idx[i, 0]))
            for i in np.flatnonzero(off & ~bad):
                exc.add("counts do not match the face pattern: revolution excluded",
                        line0 + int(idx[i, 0]))
            all_used = bool(use.all())
            d_rev = None if dt is None else _rows(cur["dt"], sel, end, n_faces)
            stats.add(c if all_used else c[use],
                      None if d_rev is None else (d_rev if all_used else d_rev[use]),
                      None if dt is None else _rows(cur["t"], sel, end, n_faces)[:, -1][use],
                      correct)
        for s, L in zip(starts[~normal], lengths[~normal], strict=True):
            sl = slice(s, s + L)
            fixed = _repair(cur["count"][sl], cur["brk"][sl], n_faces, pattern,
                            line0 + int(s), exc)
            if fixed is not None:
                for c_rev, parts in fixed:
                    d = None
                    if dt is not None:
                        dd = cur["dt"][sl]
                        d = np.array([dd[p].sum() for p in parts])[None]
                    stats.add(c_rev[None], d, None if dt is None else cur["t"][sl][-1:],
                              correct)
        last = refs[-1] + 1 if refs.size else 0
        carry = {k: (None if v is None else v[last:]) for k, v in cur.items()}
    if not seen_ref:
        raise LogError(f"{path}: no reference pulse at all (ref column never 1): faces cannot "
                       "be identified")
    tail = 0 if carry is None else len(carry["count"])
    return LogSummary(stats, exc, has_time, rows, tail)


def _repair(c: np.ndarray, brk: np.ndarray, n: int, pattern: np.ndarray | None, line: int,
            exc: Exclusions) -> list[tuple[np.ndarray, list]] | None:
    """Slow path for one abnormal revolution: repaired revolutions or None (excluded)."""
    L = len(c)
    if brk.any():
        exc.add("a row is missing from the log (counter did not alternate): revolution "
                "excluded", line)
        return None
    if L == n + 1 and pattern is not None:
        for j in range(L - 1):
            merged = np.concatenate([c[:j], [c[j] + c[j + 1]], c[j + 2:]])
            if _pattern_ok(merged, pattern):
                exc.add("spurious pulse: the two intervals it split were merged (repaired)",
                        line)
                parts = [[i] for i in range(j)] + [[j, j + 1]] + [[i] for i in range(j + 2, L)]
                return [(merged, parts)]
    if L == 2 * n and pattern is not None and _pattern_ok(c[:n], pattern) and _pattern_ok(
            c[n:], pattern):
        exc.add("reference signal failed once: split by the face pattern (repaired)", line)
        return [(c[:n], [[i] for i in range(n)]), (c[n:], [[i] for i in range(n, 2 * n)])]
    if L == n - 1:
        exc.add("missing autocollimator pulse: revolution excluded", line)
    elif L == n + 1:
        exc.add("extra pulse that no merge explains: revolution excluded", line)
    else:
        exc.add(f"{L} intervals between reference pulses (expected {n}): revolution excluded",
                line)
    return None
