"""synth.handheld renders what it says: unit gravity at rest, the stated noise, poses and
moves of the stated lengths, real turns between poses, and files it never overwrites."""

from __future__ import annotations

import numpy as np
import pytest

from synth.handheld import HandheldSpec, handheld
from synth.tumble import Triad


def test_rest_is_gravity_and_noise_as_stated():
    tr = Triad(k=(1.0, 1.0, 1.0), beta=(0.0, 0.0, 0.0), bias=(0.0, 0.0, 0.0), noise_v=0.0)
    rec = handheld(HandheldSpec(triad=tr, rate_hz=200.0, noise_g=1e-3, n_poses=8, seed=1))
    for (a, b), up in zip(rec.poses, rec.up, strict=True):
        sel = (rec.t >= a) & (rec.t <= b)
        x = rec.u[sel]
        assert np.allclose(x.mean(0), up, atol=5 * 1e-3 / np.sqrt(sel.sum()))
        assert np.allclose(x.std(0, ddof=1), 1e-3, rtol=0.25)
        assert 1.0 - 1e-9 <= (b - a) + 1 / 200 <= 3.0 + 1e-9 + 1 / 200
    # consecutive poses are turns of at least 30°, and the moves in between do move
    cos = np.sum(rec.up[1:] * rec.up[:-1], axis=1)
    assert np.all(cos <= np.cos(np.deg2rad(30)) + 1e-12)


def test_seeded_and_never_overwrites(tmp_path):
    a = handheld(HandheldSpec(seed=4, n_poses=5))
    b = handheld(HandheldSpec(seed=4, n_poses=5))
    assert np.array_equal(a.u, b.u)
    p = a.write_csv(tmp_path / "r.csv")
    with pytest.raises(FileExistsError):
        a.write_csv(p)
    assert p.read_text().splitlines()[0] == "ux,uy,uz"
