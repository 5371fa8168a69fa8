"""synth.profiles: the groove's profiles across and along a mark."""

from __future__ import annotations

import numpy as np
from scipy.special import erf

from synth.profiles import ERF_ONE, saturating_erf


def test_the_saturating_erf_is_scipys_to_the_last_bit():
    """The renders' erf (evaluated only where it is not +-1): scipy's values, across the
    point where scipy's erf reaches 1.0 exactly (5.92) and beyond."""
    z = np.concatenate([np.linspace(-40, 40, 200001), np.linspace(5.8, 6.2, 4001),
                        -np.linspace(5.8, 6.2, 4001), [0.0, -0.0, np.nan, np.inf, -np.inf]])
    assert np.array_equal(saturating_erf(z), erf(z), equal_nan=True)
    assert np.all(np.abs(erf(z[np.abs(z) >= ERF_ONE])) == 1.0)
