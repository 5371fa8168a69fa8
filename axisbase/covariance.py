"""Covariances indexed by name: the one place a covariance matrix is indexed by the names of
its quantities (a result's ``cov_of(...)`` method calls this), so no call site builds
parameter names or counts positions."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def cov_of(cov: np.ndarray, names: Sequence[str], want: Sequence[str]) -> np.ndarray:
    """The rows and columns of ``cov`` (its quantities named by ``names``, in order) of the
    quantities ``want``, in that order; same unit as ``cov`` (the product of the two
    quantities' units). ``KeyError`` names an unknown quantity and the names there are.

    Examples
    --------
    >>> import numpy as np
    >>> c = np.diag([1.0, 4.0, 9.0])
    >>> cov_of(c, ("k_x", "beta_y", "bias_z"), ("bias_z", "k_x"))
    array([[9., 0.],
           [0., 1.]])
    """
    pos = {n: i for i, n in enumerate(names)}
    missing = [n for n in want if n not in pos]
    if missing:
        raise KeyError(f"{', '.join(map(repr, missing))} not among {', '.join(names)}")
    idx = [pos[n] for n in want]
    return np.asarray(cov)[np.ix_(idx, idx)]
