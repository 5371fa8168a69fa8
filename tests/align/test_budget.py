"""The uncertainty budget: shares add up to u², and leaving a source out of the solve moves u
as the linearisation predicts."""

from dataclasses import replace

import numpy as np
import pytest

from align.fusion import E_INDEX, E_NAMES, NOT_EXCLUDED_TAG, fuse
from align.fusion.budget import Budget
from align.session import load_session, observation_blocks, run_session
from synth.session import SessionSpec, write_session


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("budget") / "s"
    write_session(folder, SessionSpec(
        seed=5, effects={"camera_roll_A": 40.0}, undeclared=frozenset({"camera_roll_A"}),
        views=("A", "Ar", "B"), image_size=(400, 300), mark_length_px=240.0))
    s = load_session(folder)
    res = run_session(s)
    assert res.ok
    return s, res


def test_shares_add_up_to_u2_and_name_every_input(run):
    s, res = run
    f = res.fusion
    b = f.budget
    assert any(e.name.startswith("camera_roll") for e in f.loop.effects)  # a nuisance to split
    for n, (i, j) in zip(E_NAMES, E_INDEX, strict=True):
        u, cs = b.angles[n]
        total = sum(c.u2 for c in cs)
        assert total == pytest.approx(u**2, rel=0.01), n
        assert u == pytest.approx(f.E_u[i, j], rel=0.01), n  # the solve's own u
        assert sum(c.fraction for c in cs) == pytest.approx(1.0, rel=0.01)
        assert [c.u2 for c in cs] == sorted((c.u2 for c in cs), reverse=True)
        assert min(c.u2 for c in cs) > -1e-6 * u**2  # no negative share beyond rounding
    sources = {c.source for c in b.angles["E_xY"][1]}
    assert {f"image {im.file.name}" for im in s.images} <= sources
    assert {"goniometer gonio.csv", "calibration", "static poses"} <= sources
    assert "nuisance: camera roll A" in sources
    back = Budget.from_dict(b.to_dict())
    assert back.angles["E_xZ"][0] == pytest.approx(b.angles["E_xZ"][0])


def _u(f):
    return np.array([f.E_u[i, j] for i, j in E_INDEX])


def _u_data(f):
    """u without the Type B terms of the nuisances the data cannot determine (carried over
    their plausible range: align/fusion/undetermined.py)."""
    carried = sum((np.outer(c.shift, c.shift) for c in f.undetermined), np.zeros((6, 6)))
    return np.sqrt(np.diag(f.cov - carried))


@pytest.mark.parametrize("drop", ["image x_A.png", "image z_Ar.png", "goniometer gonio.csv",
                                  "static poses"])
def test_leaving_a_source_out_matches_its_predicted_effect(run, drop):
    s, res = run
    lin = res.fusion.budget.model
    predicted = lin.u_with(drop=[drop])
    if drop.startswith("image "):
        r2 = replace(res, marks=[(im, m) for im, m in res.marks
                                 if f"image {im.file.name}" != drop])
        blocks = observation_blocks(s, r2)
    elif drop == "static poses":  # (the calibration's bias prior goes with them)
        blocks = observation_blocks(s, replace(res, platform=[]))
    else:
        blocks = [b for b in observation_blocks(s, res) if b.source != "goniometer"]
    refit = fuse(blocks)
    assert [e.name for e in refit.loop.effects] == [e.name for e in res.fusion.loop.effects]
    before = _u(res.fusion)
    obtained = _u(refit)
    assert not res.fusion.undetermined
    if drop == "static poses":
        # The X/Y-up poses were the azimuth datum and the levelled ones separated camera B's
        # roll (its reversal view is not in this session): without them both are carried over
        # their plausible range (Type B, beside the linearisation, which the plan's algebra
        # does not predict); it predicts the rest.
        assert {c.name for c in refit.undetermined} == {"reference_face_offset",
                                                        "camera_roll[B]"}
        obtained = _u_data(refit)
    assert np.max(obtained / before) > 1.0 + 1e-6 or drop.startswith("image ")
    np.testing.assert_allclose(predicted, obtained, rtol=0.02)


def test_a_type_b_term_of_the_log_is_its_own_share(tmp_path):
    """Without a latitude the goniometer carries the Earth-rate bound as a Type B term: it is
    named in the budget, and the shares still add up to u²."""
    import re

    folder = tmp_path / "s"
    write_session(folder, SessionSpec(seed=4, views=("A",), image_size=(400, 300),
                                      mark_length_px=240.0))
    toml = folder / "session.toml"
    toml.write_text(re.sub(r"latitude_deg = [0-9.]+", "latitude_range_deg = [40.0, 60.0]",
                           toml.read_text()))
    res = run_session(load_session(folder))
    assert res.ok
    (name,) = res.gonio.angles.type_b_terms
    for n in ("E_xY", "E_yX"):
        u, cs = res.fusion.budget.angles[n]
        # (a fusion candidate carried as not excluded is another Type B share: not the log's)
        tb = [c for c in cs if c.kind == "typeB" and NOT_EXCLUDED_TAG not in c.source]
        assert [c.source for c in tb] == [f"Type B: {name}"]
        assert sum(c.u2 for c in cs) == pytest.approx(u**2, rel=0.01)


def test_a_known_roll_removes_exactly_its_nuisance_share(run):
    """The plan's algebra and the budget's agree: the camera roll known (a prior of ~0 u)
    lowers u² by the roll's share (the last nuisance freed), for every angle."""
    from align.fusion.budget import Group
    from align.fusion.observations import ROLL

    _, res = run
    b = res.fusion.budget
    lin = b.model
    label, idx = lin.nuisances[-1]
    assert label == "camera roll A" and lin.params[idx[0]] == f"{ROLL}[A]"
    A = np.zeros((1, len(lin.params)))
    A[0, idx[0]] = 1.0
    known = Group("roll known", "calibration", A, np.array([[1e-30]]))
    u_known = lin.u_with(add=[known])
    for k, n in enumerate(E_NAMES):
        u, cs = b.angles[n]
        share = next(c.u2 for c in cs if c.source == "nuisance: camera roll A")
        assert u_known[k] ** 2 == pytest.approx(u**2 - share, rel=1e-6, abs=1e-9 * u**2)


@pytest.mark.parametrize("drop", ["image x_A.png", "image z_Ar.png", "image y_B.png"])
def test_leaving_an_image_out_where_images_matter(run, drop):
    """Without the platform static poses the images carry the tilts of the axes: leaving
    one out raises u, by what the linearisation predicts."""
    s, res = run
    nostatic = replace(res, platform=[])
    base = fuse(observation_blocks(s, nostatic))
    predicted = base.budget.model.u_with(drop=[drop])
    refit = fuse(observation_blocks(s, replace(nostatic, marks=[
        (im, m) for im, m in res.marks if f"image {im.file.name}" != drop])))
    assert [e.name for e in refit.loop.effects] == [e.name for e in base.loop.effects]
    # (camera B's roll, without its reversal view or the static poses, is carried over its
    # plausible range and sets E_yZ's and E_zY's u, as the reference face's offset sets
    # E_xY's and E_yX's: whether the image mattered is judged on what the data give)
    assert {c.name for c in base.undetermined} == {"reference_face_offset", "camera_roll[B]"}
    assert np.max(_u_data(refit) / _u_data(base)) > 1.05  # the image mattered
    # (the linearisation holds what the data give: the carried ranges are Type B beside it)
    np.testing.assert_allclose(predicted, _u_data(refit), rtol=0.02)
