"""Small modules with one job: no module of the project is over 600 lines (a module that grows
past it is split along its jobs, its public names re-exported where they were)."""

from __future__ import annotations

from pathlib import Path

from tests.source import tree

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("align", "axisbase", "goniometry", "imaging", "synth")
LIMIT = 600


def test_no_module_over_600_lines():
    sizes = {str(f.relative_to(ROOT)): len(f.read_text(encoding="utf-8").splitlines())
             for pkg in PACKAGES for f in (ROOT / pkg).rglob("*.py")}
    assert len(sizes) > 50  # the packages were found
    over = {f: n for f, n in sizes.items() if n > LIMIT}
    assert not over, over


def test_every_command_is_a_thin_call_into_the_library():
    """Each ``cmd_*`` of align/commands is at most 20 lines (parse, call, print): logic a
    library user would need lives in the library."""
    import ast

    long_ = {}
    for f in (ROOT / "align" / "commands").glob("*.py"):
        for node in tree(f).body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("cmd_"):
                n = node.end_lineno - node.lineno + 1
                if n > 20:
                    long_[f"{f.name}:{node.name}"] = n
    assert not long_, long_
