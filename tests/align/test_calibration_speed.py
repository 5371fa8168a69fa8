"""The calibration loop's screen (a linearised score test before each refit,
``CalibrationStage.screen``): it saves the refits of candidates that cannot pass, and never
changes what the loop adds."""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration.model import CANDIDATES, CalibrationStage, admissible
from align.loop import run_loop
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import CLASSES, poses_of, triad_of


class Unscreened(CalibrationStage):
    """The stage without its screen: every candidate refitted (as before the screen)."""

    screen = None


def _loops(name: str, seed: int):
    tr = triad_of(name)
    p = poses_of(tumble(TumbleSpec(triad=tr, seed=seed)))
    out = []
    for cls in (CalibrationStage, Unscreened):
        st = cls(p, np.sign(tr.k))
        out.append((st, run_loop(st, CANDIDATES, admissible=admissible(st))))
    return out


def assert_same_choice(a, b) -> None:
    assert [e.name for e in a.effects] == [e.name for e in b.effects]
    assert [r.name for r in a.refused] == [r.name for r in b.refused]
    np.testing.assert_allclose(a.after.chi2, b.after.chi2, rtol=1e-9)


@pytest.mark.parametrize("seed", [2, 5])
def test_screen_refits_almost_nothing_on_clean_data(seed):
    """Clean 14 poses: the declared model is fitted, and at most the bias hysteresis (so
    ill-conditioned on these poses that its Gauss-Newton step leaves the region where the
    model is quadratic: the screen does not trust its prediction) — 15 refits unscreened."""
    (st, rep), (st0, rep0) = _loops("clean", seed)
    assert_same_choice(rep, rep0)
    assert set(st.fits) <= {(), ("bias_hysteresis",)} and len(st0.fits) >= 15


@pytest.mark.parametrize("name", ["cross", "hysteresis"])
def test_screen_keeps_the_loops_choice(name):
    (_, rep), (_, rep0) = _loops(name, 13)
    assert rep.effects  # an effect was added: the screen let its refit through
    assert_same_choice(rep, rep0)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CLASSES))
def test_screen_keeps_the_loops_choice_sweep(name):
    for seed in range(20):
        (_, rep), (_, rep0) = _loops(name, seed)
        assert_same_choice(rep, rep0)
