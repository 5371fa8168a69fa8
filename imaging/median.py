"""np.median of a 1-D float array: the same number in less time.

np.median copies the values, selects the middle rank(s) and the last (its NaN check), and
takes the middle values' mean through np.mean's reduction (~10 us of dispatch a call; the
measurement of a 5 MP frame takes ~110 medians, most of a few hundred values). Here one
selection of the upper middle rank, the lower one the largest value left of it, and their
mean as np.mean makes it ((a + b) / 2: its sum of two values is a + b); NaN, which makes
np.median's answer NaN, is sought only among the upper half, where the selection puts it.
"""

from __future__ import annotations

import numpy as np


def median_inplace(d: np.ndarray) -> np.floating:
    """``np.median(d)`` of a 1-D float32 or float64 array, the same number, reordering
    ``d`` (anything else, or a NaN among the values: np.median's own answer)."""
    if d.ndim != 1 or d.dtype not in (np.float64, np.float32) or not d.size:
        return np.median(d)
    h = d.size // 2
    d.partition(h)
    if np.isnan(d[h:]).any():  # (a selection orders NaN last)
        return np.median(d)
    if d.size % 2:
        return d[h]
    return (d[:h].max() + d[h]) / 2


def median(a: np.ndarray) -> np.floating:
    """``np.median(a)`` of a 1-D float array, the same number (see :func:`median_inplace`;
    ``a`` is left as it is)."""
    a = np.asarray(a)
    return median_inplace(a.copy()) if a.ndim == 1 else np.median(a)
