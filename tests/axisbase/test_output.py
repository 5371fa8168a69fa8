"""axisbase.output.csv_text: carried-through columns (times) are never rounded."""

import numpy as np

from axisbase.output import csv_text


def test_exact_columns_read_back_to_the_same_float64():
    rng = np.random.default_rng(5)
    t = 1763980000.0 + np.cumsum(rng.uniform(1e-6, 1e-3, 500))   # Unix-epoch times, ~µs apart
    x = rng.normal(size=500)
    text = csv_text(["t", "x"], [t, x], exact=("t",))
    back = np.genfromtxt(text.splitlines(), delimiter=",", names=True)
    assert np.array_equal(back["t"], t)                 # bit for bit, every time distinct
    assert len(np.unique(back["t"])) == 500
    assert np.allclose(back["x"], x, rtol=1e-9, atol=0)  # the others keep fmt's 10 digits


def test_none_column_is_blank_and_nan_stays_nan():
    text = csv_text(["t", "a"], [None, [1.0, np.nan]], exact=("t",))
    assert text == "t,a\n,1\n,nan\n"
    assert csv_text(["t", "a"], [[np.nan, 2.5], [3, 4]], exact=("t",)) == "t,a\nnan,3\n2.5,4\n"
