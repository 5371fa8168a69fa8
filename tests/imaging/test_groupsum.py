"""GroupSums: the same per-group sums as np.bincount, to the bit, built or not."""

import numpy as np
import pytest

from imaging.groupsum import LARGE, LAZY, GroupSums


@pytest.mark.parametrize("eager", [False, True])
@pytest.mark.parametrize("n", [LARGE // 2, 3 * LARGE])
def test_sums_are_bincounts_to_the_bit(n, eager):
    rng = np.random.default_rng(n)
    # Labels as a mark's segments: mostly in order along the band, some out of order, and
    # groups left empty (minlength beyond the largest label).
    labels = np.sort(rng.integers(0, 300, n))
    labels[::7] = rng.integers(0, 300, labels[::7].size)
    groups = GroupSums(labels, 320, eager)
    assert groups.n == 320
    assert np.array_equal(groups.counts, np.bincount(labels, minlength=320))
    values = [rng.standard_normal(n) * 10.0 ** rng.integers(-8, 8, n),  # cancellations
              rng.standard_normal(n).astype(np.float32), rng.random(n) < 0.3,
              np.where(rng.random(n) < 0.01, np.nan, rng.standard_normal(n))]
    for x in values * (LAZY + 1):  # past the calls made by np.bincount, into the built form
        got, want = groups(x), np.bincount(labels, x, minlength=320)
        assert got.dtype == want.dtype and got.shape == want.shape
        assert np.array_equal(got, want, equal_nan=True)


def test_labels_beyond_n_extend_the_groups_as_bincount():
    labels = np.arange(LARGE + 10) % 50
    groups = GroupSums(labels, 10)
    x = np.linspace(-1, 1, labels.size)
    for _ in range(LAZY + 2):
        assert np.array_equal(groups(x), np.bincount(labels, x, minlength=10))


def test_columns_are_summed_each_as_alone():
    """Values (n, m): each of the m columns' sums the same to the bit as that column's own
    (the JPEG term's draws summed together, imaging.centres.sample_centres_batch)."""
    rng = np.random.default_rng(3)
    labels = np.sort(rng.integers(0, 40, 900))
    labels[::5] = rng.integers(0, 40, labels[::5].size)
    x = rng.standard_normal((900, 7)) * 10.0 ** rng.integers(-8, 8, (900, 7))
    got = GroupSums(labels, 45)(x)
    assert got.shape == (45, 7)
    for j in range(7):
        assert np.array_equal(got[:, j], np.bincount(labels, x[:, j], minlength=45))
