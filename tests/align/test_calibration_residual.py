"""The calibration fit's written-out Jacobian (:func:`align.calibration.residual.stage_jacobian`)
against central differences of its residual, for every effect of the effect table at once, at
random parameters, with and without the walk's whitening and the warm-up's time constant."""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration.effects import EFFECTS
from align.calibration.model import CalibrationStage
from align.calibration.residual import stage_jacobian, stage_residual
from synth.tumble import TumbleSpec, tumble
from tests.align.effects_cases import plan28, poses_of, triad_of


def _differences(resid, theta: np.ndarray, tau: float, h: np.ndarray) -> np.ndarray:
    cols = []
    for j, hj in enumerate(h):
        tp, tm = theta.copy(), theta.copy()
        tp[j] += hj
        tm[j] -= hj
        cols.append((resid(tp, tau) - resid(tm, tau)) / (2 * hj))
    return np.column_stack(cols)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("whiten", [False, True])
def test_stage_jacobian_is_the_differences(seed, whiten):
    """Each column within 1e-6 (relative, its norm) of central differences; a column the
    residual does not depend on (the warm-up's amplitude without a time constant) is zero."""
    rng = np.random.default_rng(seed)
    tr = triad_of("scale_drift")
    p = poses_of(tumble(TumbleSpec(triad=tr, seed=seed, up=tuple(map(tuple, plan28())))))
    # A temperature that is not the time (the temperature columns apart from the drift's).
    p = type(p)(p.u, p.t, 300 + 0.01 * p.t + 0.2 * np.sin(p.t / 50), p.sigma_u, p.count,
                p.labels)
    st = CalibrationStage(p, np.sign(tr.k), walk=False)
    if whiten:
        a = rng.normal(size=(len(p.u), len(p.u))) * 0.1 + np.eye(len(p.u))
        st.whiten = np.tril(a) / st.sigma[:, None]
    effects = list(EFFECTS)
    scale = st._scale(effects)
    theta = np.concatenate([st.start.k, st.start.beta, st.start.bias, np.zeros(len(scale) - 9)])
    # Effects tens of their typical size (the nonlinear terms' products matter), beta of
    # degrees (R^-1's terms beyond the small-angle ones).
    theta = theta + 30 * scale * rng.normal(size=len(theta))
    theta[3:6] = rng.normal(size=3) * 0.05
    resid, jac = stage_residual(st, effects), stage_jacobian(st, effects)
    for tau in (0.0, float(rng.uniform(20, 200))):
        ja = jac(theta, tau)
        jd = _differences(resid, theta, tau, 0.1 * scale)
        norm = np.linalg.norm(jd, axis=0)
        dead = norm == 0
        assert np.all(dead == (np.linalg.norm(ja, axis=0) == 0))
        assert dead.sum() == (3 if tau == 0 else 0)
        err = np.linalg.norm(ja - jd, axis=0)[~dead] / norm[~dead]
        assert err.max() < 1e-6, (tau, int(np.argmax(err)), err.max())
