"""One rule for a goniometer's face plan, whichever interface states it: ``align gonio``
(flags) and ``session.toml`` (keys) refuse the same plans with the same reason, each naming
what the user wrote (issue 21: the command line used to accept both with no word)."""

from __future__ import annotations

import numpy as np
import pytest

from align.commands.main import main
from align.face_plan import check_face_plan
from align.session import load_session
from axisbase.errors import InputError

REF_IS_HOUSING = ("the first face is the reference face (marked by the binding signal); 'x' is "
                  "a housing")
X_Y_PARALLEL = ("faces x and y would be 0.000° apart (mod 180°); the axes are perpendicular — "
                "contradictory nominal orientation")
CASES = [  # faces, nominal [deg] or None, the reason
    (["x", "y", "ref", "z"], None, REF_IS_HOUSING),
    (["ref", "x", "z", "y"], None, X_Y_PARALLEL),
    (["ref", "x", "z", "y"], [90.0, 90.0, 90.0, 90.0], X_Y_PARALLEL),
    (["ref", "y", "x", "z"], [90.0, 180.0, 45.0, 45.0], "faces x and y would be 0.000° apart"),
]


@pytest.mark.parametrize("faces,nominal,reason", CASES)
def test_the_command_line_and_session_toml_refuse_alike(tmp_path, capsys, faces, nominal,
                                                        reason):
    (tmp_path / "g.csv").write_text("count,counter,ref\n")
    flags = ["--faces", ",".join(faces)] + (
        ["--nominal", ",".join(f"{v:g}" for v in nominal)] if nominal else [])
    assert main(["gonio", str(tmp_path / "g.csv"), *flags, "-q"]) == 2
    cli = capsys.readouterr().err
    assert cli.count("\n") == 1 and "Traceback" not in cli, cli
    named = flags[-2] + " " + flags[-1] if reason != REF_IS_HOUSING else "--faces"
    # the log the plan was given for, then the flag (the independent user's rule: file, flag)
    assert cli.startswith(f"align gonio: {tmp_path / 'g.csv'}: {named}") and reason in cli, cli

    s = tmp_path / "s"
    s.mkdir()
    key = "" if nominal is None else f"nominal_deg = {nominal}\n"
    (s / "session.toml").write_text(f'[goniometer]\nlog = "../g.csv"\nfaces = {faces}\n{key}'
                                    .replace("'", '"'))
    with pytest.raises(InputError) as exc:
        load_session(s)
    where = "faces" if reason == REF_IS_HOUSING else "nominal_deg"
    assert f"session.toml: [goniometer] {where}" in str(exc.value)
    assert reason in str(exc.value)


def test_a_sound_plan_passes_and_the_direction_does_not_matter():
    check_face_plan(["ref", "y", "x", "z"], None, "--faces", "--nominal")
    check_face_plan(["ref", "y", "x", "z"], np.deg2rad([90.2, 89.5, 90.3, 90.0]), "f", "n")
    check_face_plan(["a", "b", "c"], None, "f", "n")  # no housings: nothing to contradict
    with pytest.raises(InputError, match="^n: faces x and y would be 91.500° apart"):
        check_face_plan(["ref", "y", "x", "z"], np.deg2rad([90.0, 91.5, 88.5, 90.0]), "f", "n")
