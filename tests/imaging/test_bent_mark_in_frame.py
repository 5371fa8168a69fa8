"""A slightly bent mark through a calibrated camera (user 13: 250 px bowed 0.5 px, the exact
lens given): alone in its frame it cannot be told from a lens that is not its calibration
(not ok, both readings named, and the advice says what tells them apart, not "give it with
--camera"); with two straight marks elsewhere in the same frame it is read as a bent mark,
the calibration kept: ok, each angle within 3 u. Renderer: user 13's (the real chessboard
lens, each sensor sample mapped back through it).

Beside the straight marks, a principal point's move of 32-35 px explains the frame as well in
two of three seeds: with the camera's stability declared (``pp_stability_px``, 0 or 0.5 px)
the move is beyond it and the bend is read; with it not declared both readings stand (not ok,
u covering both) where the straight marks cannot separate them (align/lens_bump.py)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from align.lens import LensRanges
from align.marks import measure_image
from imaging import CameraModel

UNDECIDED = "cannot tell whether the principal point moved"
cv2 = pytest.importorskip("cv2")
ui = pytest.importorskip("tests.imaging.user13_inputs")
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not __import__("os").path.isdir(ui.CHESS),
                                 reason="real data not found")]


@functools.cache
def _camera() -> CameraModel:
    K, d, size, _ = ui.real_lens("left")
    return CameraModel.from_dict({"camera_matrix": K.tolist(), "dist_coeffs": d.tolist(),
                                  "image_size": list(size), "rms_px": 0.0, "views": 0})


def _frame(seed: int, straight: bool):
    """The bent mark (250 px, sagitta 0.5 px) off-centre, where a lens change bows a line as
    much (at the centre none can: read bent alone); with ``straight``, two straight 250 px
    marks on the frame's other side. Returns the image and each mark's true angle."""
    K, d, size, _ = ui.real_lens("left")
    X, Y = ui._points(K, d, size, 3)
    rng = np.random.default_rng([seed, 13])
    specs = [((200.0, 240.0), rng.uniform(60, 85) * rng.choice([-1, 1]), 0.5)]
    if straight:
        specs += [((460.0, 110.0), rng.uniform(-20, 20), 0.0),
                  ((460.0, 380.0), rng.uniform(-20, 20), 0.0)]
    g = np.zeros(X.shape)
    for c, a, sag in specs:
        g = np.maximum(g, ui.groove(X, Y, c, np.radians(a), 250.0, 3.0, 1.0, sagitta=sag))
    img = ui.expose(0.55 * (1 - 0.3 * g.mean(-1)), rng, contrast=0.55 * 0.3)
    return img, [a for _, a, _ in specs]


def _z(r, angles):
    err = min((((r.angle_rad * 180 / np.pi - a + 90) % 180) - 90 for a in angles), key=abs)
    return err / (r.angle_u_rad * 180 / np.pi)


def _bent_read(found, angles):
    """The bent reading: every angle ok within 3 u, one mark named bent."""
    for r in found:
        assert not r.lens_limited, r.notes
        assert abs(_z(r, angles)) <= 3, _z(r, angles)
    assert sum(any(n.endswith("the mark is bent") or ": the mark is bent" in n for n in r.notes)
               for r in found) == 1


@pytest.mark.parametrize("stability", ["0", "0.5"])
@pytest.mark.parametrize("seed", range(3))
def test_bent_mark_with_straight_marks_is_read_bent_at_a_declared_stability(seed, stability):
    """The camera declared unmoved (0) or stable to 0.5 px: a 32-35 px move that would also
    explain the bows (seeds 0, 1) is beyond it, so the bent reading stands (named so)."""
    img, angles = _frame(seed, True)
    rg = LensRanges.parse(f"pp_stability_px={stability}", beside="--camera")
    found = [r for r in measure_image(img, "f.png", camera=_camera(), ranges=rg) if r.found]
    assert len(found) == 3
    _bent_read(found, angles)
    assert not any(UNDECIDED in n for r in found for n in r.notes)


def test_bent_mark_with_straight_marks_at_the_default_stability():
    """The stability not declared (the default 0.5 px decides nothing): where the straight
    marks cannot separate the bend from a move that explains every mark, both readings are
    named, with what decides, and every angle is lens-limited (not ok) with a u that covers
    both (the truth, the bent reading, within 3 u; the move's change of each angle in u);
    where they can, the bent reading and ok. Over the seeds, both cases occur (the move's
    bow in the other marks 2.6 / 1.4 sigma apart in seeds 0, 1)."""
    seen = set()
    for seed in range(3):
        img, angles = _frame(seed, True)
        found = [r for r in measure_image(img, "f.png", camera=_camera()) if r.found]
        assert len(found) == 3
        notes = [n for r in found for n in r.notes]
        if any(UNDECIDED in n for n in notes):
            seen.add("undecided")
            assert any("are bent beside the kept calibration" in n and "declare the camera's "
                       "principal-point stability (`--lens pp_stability_px=`" in n
                       for n in notes), notes
            for r in found:
                assert r.lens_limited, (seed, r.notes)
                assert abs(_z(r, angles)) <= 3, (seed, _z(r, angles))
                # the move's reading of this angle (its change, the term x sqrt 3) within 3 u
                move = np.sqrt(3) * abs(r.u_terms["camera_moved_or_bent"])
                assert 0 < move <= 3 * r.angle_u_rad, (seed, move, r.angle_u_rad)
                assert any("camera_moved_or_bent" in n and "pp_stability_px" in n
                           for n in r.notes), r.notes
        else:
            seen.add("bent")
            _bent_read(found, angles)
    assert seen == {"undecided", "bent"}, seen


@pytest.mark.parametrize("seed", range(2))
def test_bent_mark_alone_names_both_readings_and_what_tells_them(seed):
    img, angles = _frame(seed, False)
    (r,) = [r for r in measure_image(img, "f.png", camera=_camera()) if r.found]
    assert r.lens_limited and abs(_z(r, angles)) <= 3
    said = [n for n in r.notes if "lens-limited" in n]
    assert said and "image straight marks elsewhere in the frame" in said[0], r.notes
    assert not any("give it with" in n for n in r.notes), r.notes
