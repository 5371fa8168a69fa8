"""``align.cli.main`` called in-process (by a test, a notebook) leaves the process as it found
it: the logger, the command line in the provenance, where ``-`` outputs go, the pixel budget."""

from __future__ import annotations

import json
import logging
import os
import sys

from axisbase.output import _real_stdout
from axisbase.provenance import command_line
from tests.cli import run_cli, run_cli_proc


def test_an_in_process_run_leaves_no_global_state_behind(tmp_path):
    log = logging.getLogger("align")
    before = (log.handlers[:], log.level, log.propagate)
    budget = os.environ.get("ALIGN_MAX_PIXELS")
    rc, out, err = run_cli("marks", tmp_path / "absent.png", "--json", "-", "-v",
                           "--max-pixels", "1000")
    assert rc == 2 and "absent.png" in err and json.loads(out)["marks"][0]["found"] is False
    assert (log.handlers, log.level, log.propagate) == before
    assert command_line() == sys.argv
    assert _real_stdout() is sys.stdout
    assert os.environ.get("ALIGN_MAX_PIXELS") == budget


def test_in_process_and_fresh_process_say_the_same(tmp_path):
    """The in-process runner the tests use gives what the shell sees (one case: a refusal)."""
    args = ("gonio", tmp_path / "absent.csv", "--faces", "ref,y,x,z")
    assert run_cli(*args) == run_cli_proc(*args)
