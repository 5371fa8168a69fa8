"""Sums of per-pixel values over fixed groups of pixels, taken many times over the same groups.

A mark's measurement sums dozens of per-pixel products over the same grouping (the segments
of its band: every Gauss–Newton step's normal equations, the texture's replicas, the ring's
slopes). ``np.bincount(labels, x, minlength=n)`` does each in ~0.17 ms at a 5 MP mark's
~56k band pixels; the same sums as a sparse row-indicator matrix times the values take
~0.04 ms (the labels' grouping is done once, not re-validated and re-scattered per call).
scipy's CSR product adds each row's entries in the order of their columns, here the pixels'
order, from 0: the very sums np.bincount makes (its products with the indicator's ones are
exact), so the numbers are the same to the bit (tests/imaging/test_groupsum.py).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_array

try:  # scipy's own kernel of ``csr_array @ vector`` (see GroupSums.__call__)
    from scipy.sparse._sparsetools import csr_matvec
except ImportError:  # (a scipy that moved it: the product through the operator, as before)
    csr_matvec = None


def _kernel_agrees() -> bool:
    """Whether the private kernel still takes the arguments it took when this was written and
    gives the operator's sums (checked once at import on a small grouping: a scipy that
    changed it falls back to the operator instead of failing or summing wrongly)."""
    labels = np.array([2, 0, 1, 2, 0])
    x = np.array([1.5, -2.0, 0.25, 4.0, 8.0])
    op = csr_array((np.ones(5), (labels, np.arange(5))), shape=(3, 5))
    out = np.zeros(3)
    try:
        csr_matvec(3, 5, op.indptr, op.indices, op.data, x, out)
    except (TypeError, ValueError):  # (a changed signature or argument types)
        return False
    return bool(np.array_equal(out, op @ x))


if csr_matvec is not None and not _kernel_agrees():
    csr_matvec = None

LARGE = 4096
"""Fewest values for which the grouping is worth building (below, np.bincount is as fast)."""

LAZY = 3
"""Sums made by np.bincount before the grouping is built (it costs ~4 of them)."""


class GroupSums:
    """``np.bincount(labels, x, minlength=n)`` for many ``x`` over the same ``labels``.

    Parameters
    ----------
    labels : ndarray
        Each value's group (non-negative integers).
    n : int
        Number of groups (at least; more when a label is larger, as np.bincount).
    eager : bool
        Build the grouping at once (the caller takes many sums): the first :data:`LAZY`
        sums by np.bincount cost ~4x one through the grouping each (~0.45 ms at a 5 MP
        mark's ~56k band pixels).

    Attributes
    ----------
    counts : ndarray
        Each group's number of values (int).
    n : int
        The number of groups.
    """

    def __init__(self, labels: np.ndarray, n: int, eager: bool = False):
        self.labels = np.asarray(labels)
        self.counts = np.bincount(self.labels, minlength=n)
        self.n = self.counts.size
        self._op = self._build() if eager and self.labels.size >= LARGE else None
        self._calls = 0

    def _build(self) -> csr_array:
        indptr = np.zeros(self.n + 1, np.int64)
        np.cumsum(self.counts, out=indptr[1:])
        # A stable order keeps each group's values in their order in ``labels`` (on 16-bit
        # labels numpy's stable sort is a radix sort: ~0.5 ms, not ~1.1, at 56k values).
        key = self.labels.astype(np.uint16) if self.n <= 1 << 16 else self.labels
        order = np.argsort(key, kind="stable")
        return csr_array((np.ones(self.labels.size), order, indptr),
                         shape=(self.n, self.labels.size))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Each group's sum of ``x`` (float64, as np.bincount's); ``x`` (values, m): each
        of its m columns' sums, (n, m), each column's the same to the bit as alone (the
        product adds a row's entries column by column in the values' order, as for one)."""
        if np.ndim(x) > 1:
            if self._op is None:
                self._op = self._build()
            return self._op @ np.asarray(x, dtype=np.float64)
        if self._op is None:
            self._calls += 1
            if self.labels.size < LARGE or self._calls <= LAZY:
                return np.bincount(self.labels, x, minlength=self.n)
            self._op = self._build()
        x = np.asarray(x, dtype=np.float64)
        if csr_matvec is None or x.shape != (self.labels.size,):
            return self._op @ x
        # The kernel scipy's product calls (the same sums, to the bit), without its dispatch
        # (~5-10 us a call against the kernel's ~40 at a 5 MP mark's 56k pixels, and a
        # 5 MP frame takes ~220 such sums).
        out = np.zeros(self.n)
        csr_matvec(self.n, self.labels.size, self._op.indptr, self._op.indices,
                   self._op.data, x, out)
        return out
