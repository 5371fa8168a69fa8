"""synth.session: a lens on one camera only bows that camera's images and no other."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from synth.session import SessionSpec, write_session

FAST = dict(views=("A", "B"), platform_poses=("L000",), revolutions=3, samples_per_pose=20)


def _pixels(folder, name):
    return np.asarray(Image.open(folder / name), float)


def test_lens_on_camera_a_only(tmp_path):
    plain = write_session(tmp_path / "plain", SessionSpec(seed=4, **FAST))
    lens = write_session(tmp_path / "lens", SessionSpec(
        seed=4, effects={"lens_k1_A": -0.3}, undeclared=frozenset({"lens_k1_A"}), **FAST))
    assert lens["effects"] == {"lens_k1_A": -0.3}
    for im in lens["images"]:
        a, b = _pixels(tmp_path / "plain", im["file"]), _pixels(tmp_path / "lens", im["file"])
        if im["view"] == "B":  # camera B: the same scene, pixel for pixel
            assert np.array_equal(a, b), im["file"]
        else:  # camera A: the same scene seen through a barrel lens
            assert np.mean(np.abs(a - b)) > 0.5, im["file"]
    # The lens moves no true angle (only the image of it).
    assert [i["image_angle_rad"] for i in lens["images"]] == [
        i["image_angle_rad"] for i in plain["images"]]


def test_a_lens_can_only_be_undeclared(tmp_path):
    with pytest.raises(ValueError, match="lens_k1_B can only be undeclared"):
        write_session(tmp_path / "s", SessionSpec(effects={"lens_k1_B": 0.1}, **FAST))


def test_imageless_session_is_the_full_session_without_its_images(tmp_path):
    """tests.conftest.imageless_session skips drawing the mark images it drops: the tumble,
    the counter log, the platform poses and session.toml stay byte for byte those written
    with the images drawn (small images here: the random draws, not the pixels, matter)."""
    import filecmp

    from tests.conftest import imageless_session

    spec = SessionSpec(seed=8, effects={"reference_offset": 20.0}, image_size=(320, 240),
                       mark_length_px=200.0, revolutions=3, samples_per_pose=20)
    quick = imageless_session(tmp_path / "quick", spec)
    drawn = imageless_session(tmp_path / "drawn", spec, render=True)
    names = sorted(p.name for p in drawn.iterdir())
    assert names == ["gonio.csv", "platform.csv", "session.toml", "tumble.csv"]
    assert sorted(p.name for p in quick.iterdir()) == names
    for n in names:
        assert filecmp.cmp(quick / n, drawn / n, shallow=False), n
    assert len(list((tmp_path / "drawn" / "full").glob("*.png"))) == 8


def test_added_views_and_images_leave_the_rest_of_the_session_bit_identical(tmp_path):
    """What the plan's check relies on (tests/align/test_plan.py): a session with a reversed
    view, a repeated image and its tumble held twice added has every other file the same."""
    small = SessionSpec(seed=4, views=("A",), image_size=(240, 180), mark_length_px=120.0,
                        revolutions=8, samples_per_pose=10)
    write_session(tmp_path / "a", small)
    write_session(tmp_path / "b", replace(small, added_views=("Ar",),
                                          repeat_images=(("x", "A"),)))
    for name in ("x_A.png", "z_A.png", "gonio.csv", "tumble.csv", "platform.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert (tmp_path / "b" / "x_Ar.png").exists() and (tmp_path / "b" / "x_A_2.png").exists()
    write_session(tmp_path / "c", replace(small, tumble_repeats=2))
    for name in ("x_A.png", "gonio.csv", "platform.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()
    n = [sum(1 for _ in open(tmp_path / f / "tumble.csv")) for f in "ac"]
    assert n[1] - 1 == 2 * (n[0] - 1)
