"""Saturation judged per pose and per axis.

A pose whose samples pile up at one value on an axis has been clipped there (the ADC's rail,
a sensor's full scale) or is stuck: its mean is not the reading of that attitude, and a fit
through it moves the scale factor without the residual showing why. Judged pose by pose:
a file-wide rule misses a pose at the rail among thousands of samples of others.

A pose's axis is saturated when

* a declared rail (``adc_range`` LO, HI) is reached by at least :data:`RAIL_FRACTION` of
  its samples (at least one sample); or, without a declared rail,
* its extreme value (top or bottom) holds at least :data:`PILE_FRACTION` of its samples (at
  least :data:`PILE_MIN`) and significantly more than the next value inward (one-sided
  binomial test of the two counts at :data:`PILE_ALPHA`): quantised noise has a tail that
  thins towards its end; a rail makes it rise. Judged only when the pose shows
  at least :data:`MIN_LEVELS` distinct values (coarser data have no tail to read); or
* all its samples are one value while the file's typical pose shows at least
  :data:`MIN_LEVELS` distinct values on that axis (stuck, or clipped for the whole pose).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

PILE_FRACTION = 0.05
"""Least share of a pose's samples at its extreme value to call it a pile-up."""
PILE_MIN = 5
"""... and least count."""
PILE_ALPHA = 1e-4
"""Significance of 'more at the extreme than next to it' (a tail's counts are small: a
plain 'more than' calls 10 against 7 a pile-up)."""
RAIL_FRACTION = 0.01
"""Least share of a pose's samples at a declared rail to call the pose clipped."""
MIN_LEVELS = 4
"""Fewest distinct values of a pose on an axis for its tail shape to be read."""
MIN_JUDGED = 20
"""Fewest samples of a pose for the undeclared rules (fewer: no tail to read)."""


@dataclass(frozen=True)
class Saturated:
    """A pose's axis at a rail: pose index and label, axis (0..2), the value and how many of the
    pose's ``samples`` sit there; ``why``: 'at the declared rail', 'piled at its extreme',
    'one value throughout'."""

    index: int
    pose: str
    axis: int
    value: float
    count: int
    samples: int
    why: str

    def text(self) -> str:
        return (f"pose {self.pose}: u{'xyz'[self.axis]} {self.why} ({self.count} of its "
                f"{self.samples} samples at {self.value:g}): saturated or clipped")


def _levels(x: np.ndarray) -> int:
    return len(np.unique(x))


def find_saturated(samples: Sequence[np.ndarray], labels: Sequence[str],
                   adc_range: tuple[float, float] | None = None) -> list[Saturated]:
    """Every (pose, axis) at a rail.

    Parameters
    ----------
    samples : per pose, its samples (n_p, 3) [output units], in any order.
    labels : the poses' labels.
    adc_range : the ADC's rails (LO, HI) in the same unit, when declared.
    """
    out: list[Saturated] = []
    typical = [np.median([_levels(s[:, ax]) for s in samples]) for ax in range(3)]
    for i, (s, lab) in enumerate(zip(samples, labels, strict=True)):
        n = len(s)
        for ax in range(3):
            x = s[:, ax]
            hit = _at_rail(x, adc_range) if adc_range is not None else None
            if hit is None and n >= MIN_JUDGED:
                hit = _piled(x, typical[ax])
            if hit is not None:
                out.append(Saturated(i, str(lab), ax, hit[0], hit[1], n, hit[2]))
    return out


def _at_rail(x: np.ndarray, rails: tuple[float, float]) -> tuple[float, int, str] | None:
    lo, hi = rails
    for v, c in ((hi, int(np.sum(x >= hi))), (lo, int(np.sum(x <= lo)))):
        if c >= max(1.0, RAIL_FRACTION * len(x)):
            return float(v), c, "at the declared rail"
    return None


def _piled(x: np.ndarray, typical_levels: float) -> tuple[float, int, str] | None:
    values, counts = np.unique(x, return_counts=True)
    if len(values) == 1:
        if typical_levels >= MIN_LEVELS:
            return float(values[0]), len(x), "one value throughout"
        return None
    if len(values) < MIN_LEVELS:
        return None
    need = max(PILE_MIN, PILE_FRACTION * len(x))
    for end, inner in ((-1, -2), (0, 1)):
        c, ci = int(counts[end]), int(counts[inner])
        if c >= need and special.bdtrc(c - 1, c + ci, 0.5) < PILE_ALPHA:
            return float(values[end]), c, "piled at its extreme"
    return None
