"""The fusion names the source that disagrees (leave-one-source-out) and finds a platform
that is not level: a 30″ out-of-level platform (cameras and goniometer see the true E) is
found as the levelling effect, or — without that candidate — the static poses are named in
E_xZ, E_yZ; a triad that crept 30″ about Y between the images and the static readings is
named as the cameras seeing another E in E_xZ, E_zX; a clean session names nothing."""

from __future__ import annotations

import numpy as np
import pytest

from align.fusion import E_INDEX
from align.fusion.diagnosis import leave_one_source_out, name_disagreement
from align.fusion.observations import LEVEL
from align.fusion.solve import FusionStage
from align.session import load_session, observation_blocks, run_session
from synth.session import SessionSpec, write_session
from tests.conftest import ARCSEC

TOL = 4.5


def _run(tmp_path, seed: int, eff: dict):
    folder = tmp_path / f"s{seed}"
    truth = write_session(folder, SessionSpec(seed=seed, effects=eff,
                                              undeclared=frozenset(eff)))
    s = load_session(folder)
    return s, run_session(s), np.array(truth["misalignment_rad"])


@pytest.mark.slow
def test_an_out_of_level_platform_is_found_as_levelling(tmp_path):
    s, res, truth = _run(tmp_path, 1, {"platform_level_x": 30.0, "platform_level_y": -20.0})
    f = res.fusion
    assert [e.name for e in f.loop.effects] == [LEVEL]
    comp = {c: (v, u) for c, v, u in f.loop.effects[0].components}
    for axis, true in (("x", 30.0), ("y", -20.0)):
        v, u = comp[axis]
        assert abs(v / ARCSEC - true) < TOL * u / ARCSEC
    z = [(f.E[i, j] - truth[i, j]) / f.E_u[i, j] for i, j in E_INDEX]
    assert np.max(np.abs(z)) < TOL, z
    # Without the candidate (the fused solve alone), the static poses are the source named,
    # in E_xZ and E_yZ, by the levelling offset.
    stage = FusionStage(observation_blocks(s, res))
    sol = stage.solve(())
    layout = stage._layout(())
    starts = np.cumsum([0, *(len(b.values) for b in stage.blocks)])
    rows_of = [(b.source, np.arange(starts[k], starts[k + 1]))
               for k, b in enumerate(stage.blocks)]
    named = name_disagreement(leave_one_source_out(lambda p: stage._residual(p, layout),
                                                   sol.params, rows_of), 1e-3)
    assert named is not None and "platform static" in (named.source, *named.also)
    sign = 1.0 if named.source == "platform static" else -1.0  # (the cameras' own E: opposite)
    got = {n: (d, u) for n, d, u in named.angles}
    assert set(got) == {"E_xZ", "E_yZ"}
    for n, true in (("E_xZ", 30.0), ("E_yZ", -20.0)):
        d, u = got[n]
        assert abs(d / ARCSEC - sign * true) < TOL * u / ARCSEC, (n, d / ARCSEC, u / ARCSEC)
    assert "platform not level?" in named.message()


@pytest.mark.slow
@pytest.mark.parametrize("seed, creep", [(3, 30.0), (700, -30.0)])
def test_creep_between_images_and_static_readings_names_the_sources(tmp_path, seed, creep):
    """Only the cameras and the static poses see E_xZ, E_zX absolutely: the two are named
    (either, given its own E, makes the rest agree), in those two angles, by the creep."""
    _, res, truth = _run(tmp_path, seed, {"creep_y": creep})
    f = res.fusion
    assert not f.consistent
    d = f.disagreement
    assert d is not None and {d.source, *d.also} == {"camera", "platform static"}
    got = {n: (v, u) for n, v, u in d.angles}
    assert set(got) == {"E_xZ", "E_zX"}
    # The images saw the triad before it crept by `creep` about Y: from them E_xZ +creep,
    # E_zX -creep against the static poses (the static poses' own E: the opposite).
    sign = 1.0 if d.source == "camera" else -1.0
    for n, true in (("E_xZ", creep), ("E_zX", -creep)):
        v, u = got[n]
        assert abs(v / ARCSEC - sign * true) < TOL * u / ARCSEC, (n, v / ARCSEC, u / ARCSEC)
    from align.warnings import session_warnings

    assert any("sources see different E" in w and "camera images" in w
               and "platform static poses" in w for w in session_warnings(res))
    back = type(f).from_dict(f.to_dict())
    assert back.disagreement is not None and back.disagreement.message() == d.message()
    # u covers the images' E, but which instrument is right is the user's to find out: the
    # result is not ok (exit 2, NOT MEASURED), saying why (README's exit-status contract).
    assert not res.ok and any("instruments disagree" in p for p in res.problems)
    assert res.disposition().verdict == "NOT MEASURED"
    assert "instruments disagree" in res.disposition().reason


@pytest.mark.slow
def test_a_clean_session_names_no_source(tmp_path):
    _, res, _ = _run(tmp_path, 4, {})
    f = res.fusion
    assert f.consistent and f.disagreement is None
    assert not f.loop.effects
    assert res.ok and res.problems == []
