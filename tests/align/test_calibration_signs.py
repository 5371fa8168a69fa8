"""Scale-factor signs from labelled faces (issue 22, class 4): a six-position calibration of
a triad whose outputs fall as its axes point up (k < 0) is no longer turned upside down by the
default signs; a --scale-sign that contradicts the labels, and a mounting that is a mirror,
are refused with the reason; the valid cases are unchanged."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from align.calibration import calibrate
from align.errors import InputError
from synth.tumble import Triad
from tests.align.test_calibration_known import NOISE_V, six_faces

NEGATIVE = Triad(noise_v=NOISE_V)  # synth's default: the paper's Table 1, k < 0 on all axes
SWAP_XY = {"+x": "+y", "+y": "+x", "-x": "-y", "-y": "-x"}


def roll_pitch_deg(cal, poses, face: str) -> tuple[float, float]:
    """Roll and pitch [deg] of a face's mean through the calibration (as align tilt)."""
    i = poses.labels.index(face)
    a = cal.model.specific_force(poses.u[i:i + 1], poses.t[i:i + 1])[0]
    return (float(np.degrees(np.arctan2(a[1], a[2]))),
            float(np.degrees(np.arctan2(-a[0], np.hypot(a[1], a[2])))))


@pytest.mark.parametrize("seed", range(10))
def test_negative_scale_factors_from_labels(seed):
    """Before: k = +2.41 V/g with a mirror mounting (det -1) and the level pose at roll
    ~180 deg. Now the labels give k < 0 within its u of the truth, det +1, level at 0."""
    tr, p = six_faces(seed, triad=NEGATIVE)
    cal = calibrate(p)
    assert cal.signs == (-1.0, -1.0, -1.0)
    k, u = cal.model.sensitivity(), cal.model.sensitivity_u()
    truth = np.asarray(tr.k) * np.linalg.norm(tr.sensing(), axis=1)
    assert np.all(np.abs(k - truth) < 5 * u), (k, truth, u)
    assert np.linalg.det(cal.known.mounting) == pytest.approx(1.0, abs=1e-9)
    roll, pitch = roll_pitch_deg(cal, p, "+z")
    # the synth fixture error (100 µrad) and the triad's beta (~600 µrad) bound the tilt
    assert abs(roll) < 0.1 and abs(pitch) < 0.1, (roll, pitch)


def test_explicit_signs_agreeing_with_labels_change_nothing():
    for triad, signs in ((NEGATIVE, (-1, -1, -1)), (None, (1, 1, 1))):
        _, p = six_faces(3, triad=triad)
        a, b = calibrate(p), calibrate(p, signs)
        assert a.signs == b.signs == tuple(float(s) for s in signs)
        assert np.array_equal(a.model.k, b.model.k) and np.array_equal(a.model.cov, b.model.cov)


def test_positive_six_faces_unchanged():
    """k > 0: the labels give +,+,+ (the old default), so the result is the old one."""
    tr, p = six_faces(4)
    cal = calibrate(p)
    assert cal.signs == (1.0, 1.0, 1.0) and np.all(cal.model.k > 0)
    assert np.linalg.det(cal.known.mounting) > 0


def test_contradicting_scale_sign_refused_naming_both():
    _, p = six_faces(5, triad=NEGATIVE)
    with pytest.raises(InputError, match=r"scale sign \+,\+,\+ .*contradicts the labelled "
                       r"faces, which give -,-,- \(ux of face \+x is -2\.4"):
        calibrate(p, (1, 1, 1))
    with pytest.raises(InputError, match=r"scale sign -,\+,- .*which give -,-,-"):
        calibrate(p, (-1, 1, -1))


def test_labels_that_do_not_name_the_axes():
    """x and y labels swapped: the labels cannot give signs (refused without --scale-sign);
    with signs that make the mounting a mirror, refused naming the determinant; with signs
    that make it a rotation (the triad turned 90° in the fixture), accepted."""
    _, p = six_faces(6, triad=NEGATIVE)
    q = replace(p, labels=tuple(SWAP_XY.get(lab, lab) for lab in p.labels))
    with pytest.raises(InputError, match="do not name the triad's axes"):
        calibrate(q)
    with pytest.raises(InputError, match="determinant -1.000"):
        calibrate(q, (-1, -1, -1))
    cal = calibrate(q, (1, -1, -1))
    assert np.linalg.det(cal.known.mounting) == pytest.approx(1.0, abs=1e-9)


def test_cli_default_signs_from_labels(tmp_path, capsys):
    from align.cli import main

    tr, p = six_faces(7, triad=NEGATIVE)
    path = tmp_path / "six.csv"
    path.write_text("pose,ux,uy,uz\n" + "".join(
        f"{lab},{a},{b},{c}\n" for lab, (a, b, c) in zip(p.labels, p.u, strict=True)))
    assert main(["calibrate", str(path)]) == 0
    assert "scale-factor signs (-1.0, -1.0, -1.0)" in capsys.readouterr().out
    assert main(["calibrate", str(path), "--scale-sign", "+"]) == 2
    assert "contradicts the labelled faces, which give -,-,-" in capsys.readouterr().err


def test_a_session_is_told_its_key_not_the_flag(tmp_path):
    """The same refusal from session.toml names ``[calibration] scale_sign`` (a session user
    has no --scale-sign)."""
    from align.session import load_session, run_session

    _, p = six_faces(7, triad=NEGATIVE)
    (tmp_path / "six.csv").write_text("pose,ux,uy,uz\n" + "".join(
        f"{lab},{a},{b},{c}\n" for lab, (a, b, c) in zip(p.labels, p.u, strict=True)))
    (tmp_path / "session.toml").write_text('[calibration]\nstatic = "six.csv"\n'
                                           'scale_sign = "+"\n')
    err = run_session(load_session(tmp_path)).errors[0]
    assert err.stage == "calibration"
    assert ("scale sign +,+,+ ([calibration] scale_sign) contradicts the labelled faces, "
            "which give -,-,-") in err.message
    assert "drop [calibration] scale_sign" in err.message and "--" not in err.message
