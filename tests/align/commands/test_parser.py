"""The ``align`` parser's help: examples that parse, defaults only where they exist."""

from __future__ import annotations

import argparse
import contextlib
import io
import shlex

import pytest

from align.commands.args import attach_signs
from align.commands.parser import build_parser


def _subparsers(p: argparse.ArgumentParser, path=()):
    """(command path, parser) of every command that runs something (synth session too)."""
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sp in action.choices.items():
                yield from _subparsers(sp, (*path, name))
            return
    yield path, p


COMMANDS = list(_subparsers(build_parser()))


def _help(p: argparse.ArgumentParser) -> str:
    with contextlib.redirect_stdout(io.StringIO()) as out:
        p.print_help()
    return out.getvalue()


def test_every_command_is_listed():
    names = {" ".join(path) for path, _ in COMMANDS}
    assert names == {"marks", "camera", "calibrate", "tilt", "gonio", "run", "apply", "lot",
                     "plan", "init", "check", "synth session", "demo"}


@pytest.mark.parametrize("path,p", COMMANDS, ids=[" ".join(c) for c, _ in COMMANDS])
def test_help_has_examples_that_parse(path, p):
    text = _help(p)
    assert "examples:" in text
    examples = [line.strip()[2:] for line in text.split("examples:")[1].splitlines()
                if line.strip().startswith("$ ")]
    assert 1 <= len(examples) <= 3
    for ex in examples:
        argv = shlex.split(ex)
        assert argv[0] == "align" and tuple(argv[1:1 + len(path)]) == path, ex
        args = build_parser().parse_args(attach_signs(argv[1:]))  # SystemExit fails the test
        assert args.func is not None


@pytest.mark.parametrize("path,p", COMMANDS, ids=[" ".join(c) for c, _ in COMMANDS])
def test_defaults_only_where_they_exist(path, p):
    text = " ".join(_help(p).split())
    for empty in ("(default: None)", "(default: False)", "(default: [])"):
        assert empty not in text
    # a real default is still shown
    shown = [a for a in p._actions if a.default not in (None, False, [], argparse.SUPPRESS)
             and a.option_strings and a.help and "default" not in a.help]
    for a in shown:
        assert f"(default: {a.default})" in text, a.option_strings


def test_top_level_description_is_whole_and_names_the_exit_status():
    text = _help(build_parser())
    desc = build_parser().description
    assert desc.endswith(".") and len(desc) > 60
    assert "exit status:" in text and "130 interrupted" in text


def test_run_platform_calibration_keeps_the_older_name():
    p = build_parser()
    new = p.parse_args(["run", "S", "--platform-calibration", "pc.json"])
    old = p.parse_args(["run", "S", "--calibration", "pc.json"])
    assert new.calibration == old.calibration == "pc.json"
    # messages name the spelling the user typed
    assert (new.calibration_flag, old.calibration_flag) == ("--platform-calibration",
                                                            "--calibration")
