"""The log's face pattern, learnt from its clean revolutions, and the screen against it.

The pattern is the median fraction of a revolution each face interval takes; sigma the
per-interval scatter of the counts about it (quantisation and jitter, measured). A revolution
within ``SCREEN_SIGMA`` sigma of the pattern on every face is clean; the pulse-to-face
tolerance of the walk is :attr:`FacePattern.tol`. A pattern that changes within the log (two
tables' logs concatenated) is refused.
"""

from __future__ import annotations

import numpy as np

from goniometry.errors import LogError
from goniometry.exclusions import SCREEN_SIGMA
from goniometry.reader import where
from goniometry.stats import rowall, rowsum

# Revolutions on each side of a face-pattern change (see FacePattern._pattern_change).
PATTERN_WINDOW = 8


class FacePattern:
    """The face pattern and its scatter, as the streaming pass learns them (a base of
    :class:`goniometry.revolutions._Pass`, which sets the attributes)."""

    n: int
    path: object
    pattern: np.ndarray | None
    sigma: float | None
    last_fracs: tuple[np.ndarray, np.ndarray] | None

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
        raise LogError(f"{where(self.path, int(lines[m]))}: the face pattern changes here (the "
                       f"interval after face {face} by {counts:+.0f} counts, {arcsec:+.1f}″; "
                       f"one table's faces stay within {self.tol:.1f} counts): two tables' "
                       "logs concatenated? Measure each log alone")

