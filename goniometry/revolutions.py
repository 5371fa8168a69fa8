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

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axisbase.memory import reuse_freed_memory
from goniometry.dropouts import dropouts
from goniometry.errors import FaceCountError, LogError
from goniometry.exclusions import LINES_KEPT, R_SCREEN, R_TAIL, Exclusions, noise_reach
from goniometry.pattern import PATTERN_WINDOW
from goniometry.reader import ROWS, iter_log, source_name, where
from goniometry.repeats import repeated_block
from goniometry.stats import RevolutionStats, rowany, rowsum
from goniometry.stretches import Walker

NEIGHBOURS = 16
# Fewest usable revolutions: the face pattern that screens pulse faults is learnt from >= 8
# clean revolutions (below that nothing is screened), and the uncertainty's batch means
# need >= 8 blocks (below that u rests on a handful of values and is not a standard
# uncertainty anyone can rely on).
MIN_REVOLUTIONS = 8
# Reference marks this many revolutions apart decide the log's faces per revolution early.
FACE_COUNT_SEGMENTS = 16


@dataclass(frozen=True)
class LogSummary:
    """One pass over a log.

    Attributes
    ----------
    stats : RevolutionStats
        Sums over the revolutions used (and the first ``keep`` kept whole).
    exclusions : Exclusions
        Every fault and decision, with lines.
    has_time : bool
        The log has pulse times.
    rows : int
        Rows read.
    incomplete_tail : int
        Rows after the last complete revolution.
    incomplete_head : int
        Rows before the first complete revolution.
    armed_face : int or None
        The face the log was armed on (None when unknown).
    sigma_counts : float
        Per-interval scatter of the clean revolutions [counts] (quantisation and jitter)
        that the 5-sigma screen uses.
    tolerance_counts : float
        The pulse-to-face match tolerance [counts].
    excluded_revolutions : int
        Revolutions excluded.
    """

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



class _Pass(Walker):
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
        # (last end row, counts, durations, end times, (start, end) pulse rows of each)
        used: list[tuple[int, np.ndarray, np.ndarray | None, np.ndarray | None,
                         np.ndarray]] = []
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
                         None if dt is None else cur["t"][ends_used],
                         np.column_stack([ends_used - n, ends_used])))
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
            for j, (e, c, _, _, _) in enumerate(used):
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
            span = np.concatenate([u[4] for u in used])[order]
            used = [(0, c, d, te, span)]
        for _, c, d, te, span in used:
            self.stats.add(c, d, te, self.correct, line0 + span)
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
            for _, c, d, te, span in got:
                self.stats.add(c, d, te, self.correct, self.carry_line0 + span)
        self.stats.flush()
        if self.stats.hashes and not self.has_time:  # (with times the reader refuses a copy)
            rep = repeated_block(np.concatenate(self.stats.hashes))
            if rep is not None:
                a, b, m = rep
                # (exact when nothing was excluded before; a file's rows start on line 2)
                line = (0 if path == ROWS else 2) + self.head + b * self.n
                raise LogError(
                    f"{where(path, line)}: usable revolutions {b + 1}-{b + m} repeat "
                    f"revolutions {a + 1}-{a + m} count for count ({m} revolutions; chance "
                    "never does that): the log written twice, or a block of it pasted again? "
                    "Remove the copy")
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


def read_revolutions(path: str | Path, n_faces: int, keep: int = 50000,
                     block_bytes: int = 1 << 20, correct=None,
                     columns: Mapping[str, str] | None = None,
                     on_kept: Callable | None = None, on_kept_at: int = 0,
                     on_bytes: Callable[[int], None] | None = None,
                     time_unit: str | None = None) -> LogSummary:
    """Stream a log into revolution statistics in one pass (see module docstring).

    ``correct(counts, dt) -> counts``: applied to each revolution before the statistics
    (e.g. removing the Earth's rotation when the latitude and times are known; the pipeline
    uses the accumulated sensitivities instead, see :func:`goniometry.face_angles`).
    ``on_kept(counts, dt, t_end)``: called once, during the pass, as soon as the first
    ``on_kept_at`` (<= ``keep``) revolutions are kept (at the end for a shorter log), with
    them — work on the head of a log (the loop) can then run while the rest is read.
    ``on_bytes(n)``: called after each chunk with about how many bytes of the file it held
    (``block_bytes``; for a progress bar).

    Parameters
    ----------
    path : str, Path, mapping of str to array-like, numpy structured array or pyarrow Table
        The counter log: its file, or its rows in memory (see :func:`iter_log`; lines are
        then the rows' indexes).
    n_faces : int
        Faces of the housing (pulses per revolution).
    keep : int
        Revolutions kept whole (the first ones).
    block_bytes : int
        Text per chunk [bytes].
    correct : callable, optional
        ``correct(counts, dt) -> counts``, see above.
    columns : mapping of str to str, optional
        Canonical name -> header name (``--columns``).
    on_kept, on_bytes : callable, optional
        See above.
    on_kept_at : int
        Revolutions handed to ``on_kept`` (1..``keep``).
    time_unit : str, optional
        The ``t`` column's unit when its header says none (``--time-unit``).

    Returns
    -------
    LogSummary
        The statistics, exclusions with their lines, and the pass's thresholds.

    Raises
    ------
    LogError
        A log that cannot be used (too few revolutions, no reference pulse, two tables'
        logs concatenated, a log written twice, a bad row), naming the file and line.
    """
    reuse_freed_memory()  # the pass frees and reallocates MB-sized temporaries per chunk
    if on_kept is not None and not 0 < on_kept_at <= keep:
        raise ValueError(f"on_kept_at {on_kept_at}: must be in 1..keep ({keep})")
    name = source_name(path)
    p = _Pass(n_faces, keep, correct, name)
    p.stats.on_kept, p.stats.on_kept_at = on_kept, on_kept_at
    for ch in iter_log(path, block_bytes, columns, time_unit=time_unit):
        p.feed(ch)
        if on_bytes is not None:
            on_bytes(block_bytes)
    return p.finish(name)
