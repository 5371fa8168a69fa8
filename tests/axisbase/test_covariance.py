"""Covariances by name (``axisbase.covariance.cov_of``, which every result's ``cov_of`` calls)."""

from __future__ import annotations

import numpy as np
import pytest

from axisbase.covariance import cov_of


def test_cov_of_picks_rows_and_columns_in_the_order_asked():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(5, 5))
    c = a @ a.T
    names = ("k_x", "k_y", "beta_x", "beta_y", "bias_z")
    got = cov_of(c, names, ("bias_z", "k_x", "beta_y"))
    want = c[[4, 0, 3]][:, [4, 0, 3]]
    assert np.array_equal(got, want)
    with pytest.raises(KeyError, match="'beta_z' not among k_x, k_y"):
        cov_of(c, names, ("k_x", "beta_z"))
