"""The marks' loop's decisions on the edge (align.mark_choice): the reading is continuous
across a threshold, and u covers both sides there."""

import numpy as np
from scipy import special

from align.mark_choice import CHOICE_BAND, blend, flip_weight


def test_flip_weight_is_half_at_the_threshold_and_zero_at_the_band_edge():
    assert flip_weight(0.0) == 0.5
    assert flip_weight(CHOICE_BAND) == 0.0 and flip_weight(-CHOICE_BAND) == 0.0
    assert flip_weight(CHOICE_BAND - 1e-9) < 1e-8  # no jump at the edge
    m = np.linspace(0, CHOICE_BAND, 50)
    w = [flip_weight(x) for x in m]
    assert np.all(np.diff(w) < 0)  # the farther from the threshold, the less the other side
    # Inside the band it is the chance the statistic's normal score (spread 1) lands on the
    # other side, renormalised: within the renormalisation's few percent of Phi(-|m|).
    assert abs(flip_weight(1.0) - special.ndtr(-1.0)) < 0.03


def test_the_reading_is_continuous_across_the_threshold_and_u_covers_both():
    a_in, u_in = 1e-3, 2e-4  # an effect in: its angle and u [rad]
    a_out, u_out = 1.6e-3, 1e-4  # the effect out
    # Just above the threshold the loop takes the effect; just below, it does not.
    above = blend(a_in, u_in, [(flip_weight(+1e-9), a_out, u_out)])
    below = blend(a_out, u_out, [(flip_weight(-1e-9), a_in, u_in)])
    ua = np.hypot(u_in, above[1])
    ub = np.hypot(u_out, below[1])
    assert abs(above[0] - below[0]) < 1e-12 and abs(ua - ub) < 1e-12
    # At the threshold: the middle of the two readings, u the larger's with half the gap.
    assert abs(above[0] - (a_in + a_out) / 2) < 1e-12
    assert abs(ua - np.hypot(max(u_in, u_out), (a_out - a_in) / 2)) < 1e-12
    # Both readings inside the interval: each within its own u of the reported one's reach.
    assert abs(a_in - above[0]) < ua and abs(a_out - above[0]) < ua
    # Far from the threshold: the decided reading alone.
    far = blend(a_in, u_in, [(flip_weight(CHOICE_BAND + 0.1), a_out, u_out)])
    assert far == (a_in, 0.0)
