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


def test_bias_walk_is_a_wiener_process_over_the_whole_run():
    """bias_walk(triad, t) over 400 seeds: the value at t has variance walk² t (turns
    included: t is the clock, not the sample count), independent increments, 0 at t = 0."""
    from synth.tumble import bias_walk

    tr = Triad(bias_walk_g=(2e-6, 1e-6, 0.0))
    t = np.array([1.0, 50.0, 200.0])
    w = np.array([bias_walk(tr, t, np.random.default_rng(s)) for s in range(400)])
    var = w.var(0)  # (3 times, 3 axes) [g²]
    expected = np.outer(t, np.square(tr.bias_walk_g))
    # 400 draws: the variance within 4 standard errors (sqrt(2/400) of itself).
    assert np.all(np.abs(var[:, :2] - expected[:, :2]) < 4 * np.sqrt(2 / 400) * expected[:, :2])
    assert np.all(w[:, :, 2] == 0)
    inc = np.diff(w[:, :, 0], axis=1)
    assert abs(np.corrcoef(inc[:, 0], inc[:, 1])[0, 1]) < 4 / np.sqrt(400)
