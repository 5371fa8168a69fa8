"""synth.tumble: the continuous recording renders the bias hysteresis as the tumble does."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from synth.tumble import HYSTERESIS_MOVE_G, Triad, TumbleSpec, recording

H_G = 50e-6


def _static_means(spec: TumbleSpec) -> np.ndarray:
    t, u, intervals = recording(spec)
    return np.array([u[(t >= a) & (t <= b)].mean(0) for a, b in intervals])


def test_recording_has_the_tumbles_hysteresis():
    """Same seed with and without hysteresis (the noise draws are the same): each static
    pose's output differs by k R h_p, h_p = 50 µg x the sign of the last change of each axis's
    input larger than 0.02 g (0 at the first pose), as synth.tumble.hysteresis renders it."""
    spec = TumbleSpec(triad=Triad(noise_v=2.4e-5), rate_hz=50.0, dwell_s=2.0, move_s=2.0,
                      seed=6)
    clean = _static_means(spec)
    hyst = _static_means(replace(spec, triad=replace(spec.triad, hysteresis_g=(H_G,) * 3)))
    k = np.asarray(spec.triad.k)
    x = clean / k  # each pose's input along the sensing axes [g] (to 1e-3 g)
    side = np.zeros(3)
    expected = np.zeros_like(x)
    for p in range(1, len(x)):
        d = x[p] - x[p - 1]
        side = np.where(np.abs(d) > HYSTERESIS_MOVE_G, np.sign(d), side)
        expected[p] = side * H_G
    got = (hyst - clean) / k
    # R differs from I by beta ~ 6e-4 rad: 3e-8 g of 50 µg.
    np.testing.assert_allclose(got, expected, atol=1e-7)
    assert np.count_nonzero(expected[1:] > 0) > 5 and np.count_nonzero(expected < 0) > 5
