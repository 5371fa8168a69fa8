"""A synthetic production lot with known truth: session results (the JSON 'align run'
writes) made from one real result by replacing its six misalignment angles with draws from a
known process, optionally with units shifted off it, and session metadata.

The process per angle is normal with mean ``mean_rad`` and standard deviation ``sigma_rad``
in run order; ``shifts`` moves given units by a multiple of sigma on one angle (truth for
the outlier flags). Only the angles, their arc-second copies, the session's name and its
metadata change: every other block of the template is kept, so the files are as large and
as complex as real ones. Imports nothing from the pipeline.
"""

from __future__ import annotations

import copy
import datetime as _dt
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

ARCSEC_RAD = np.pi / 180 / 3600
INDEX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
"""The six angles E_ij in the order of a result's ``angle_names``."""
SMALL_DROPS = {"observations", "stages", "platform_calibration", "nuisances", "axes"}
"""Blocks of a result left out of a small one (``stages`` is kept, empty)."""


def lot_results(template: Mapping[str, Any], n: int, seed: int,
                mean_rad: Sequence[float] | float = 0.0,
                sigma_rad: Sequence[float] | float = 2 * ARCSEC_RAD,
                shifts: Mapping[int, tuple[int, float]] | None = None,
                metadata: Mapping[str, Sequence[Any]] | None = None,
                start: _dt.datetime | None = None, small: bool = False
                ) -> tuple[list[dict], np.ndarray]:
    """``n`` results and the true angles [rad] (n × 6, shifts included).

    Parameters
    ----------
    template : a real session result (fused).
    mean_rad, sigma_rad : the process per angle [rad] (scalars apply to all six).
    shifts : unit index -> (angle index 0..5, shift in units of sigma).
    metadata : key -> values cycled over the units (e.g. ``{"camera": ["A", "B"]}``).
    start : if given, unit k gets ``date`` start + k hours (ISO text), in run order.
    small : leave out the per-observation and per-stage blocks (still a valid result; what
        a lot reads is all kept).
    """
    rng = np.random.default_rng(seed)
    mean = np.broadcast_to(np.asarray(mean_rad, float), (6,))
    sigma = np.broadcast_to(np.asarray(sigma_rad, float), (6,))
    truth = mean + sigma * rng.standard_normal((n, 6))
    for k, (a, s) in (shifts or {}).items():
        truth[k, a] += s * sigma[a]
    out = []
    drop = {"misalignment_rad", "misalignment_arcsec", "disposition", "budget"}  # (of E)
    if small:
        drop |= SMALL_DROPS
    base = {k: v for k, v in template.items() if k not in drop}
    if small:
        base["stages"] = {}
    for k in range(n):
        d = copy.copy(base)  # shallow: the large blocks are shared, never modified
        e = np.zeros((3, 3))
        for v, (i, j) in zip(truth[k], INDEX, strict=True):
            e[i, j] = v
        d["misalignment_rad"] = e.tolist()
        d["misalignment_arcsec"] = (e / ARCSEC_RAD).tolist()
        d["session"] = f"unit{k:05d}"
        meta = {"unit": f"SN{k:05d}"}
        for key, values in (metadata or {}).items():
            meta[key] = values[k % len(values)]
        if start is not None:
            meta["date"] = (start + _dt.timedelta(hours=k)).isoformat()
        d["metadata"] = meta
        out.append(d)
    return out, truth
