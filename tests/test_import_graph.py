"""The project's import graph: no cycle among its modules, and no project module imported
inside a function (which hides a cycle) outside the command line's deliberate lazy loading.

Both kinds of import count: at module level and inside functions. An import names the module
it loads (``from a.b import c`` is an edge to ``a.b.c`` when that is a module, else to
``a.b``); a package's ``__init__`` is its own node.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

from tests.source import tree

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("align", "axisbase", "goniometry", "imaging", "synth")

# Lazy by design: the command line loads the library per command (align --help stays fast).
LAZY_OK = ("align.commands",)
# Deliberate: align.gonio starts the loop's import (scipy, 1 s) on a thread during the log's
# pass, and align.gonio_loop imports it inside the functions that use it, so the import
# overlaps the parsing.
LAZY_EDGES_OK = {("align.gonio_loop", "align.loop")}
KNOWN_CYCLE: set[str] = set()
KNOWN_LAZY: set[tuple[str, str]] = set()


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = f
    return mods


@functools.cache
def _all_imports() -> tuple[tuple[str, str, bool, int, bool], ...]:
    return tuple(_imports(_modules()))


def _project_imports(with_types: bool = False) -> tuple[tuple[str, str, bool, int], ...]:
    """The imports that run (and with ``with_types`` those under ``if TYPE_CHECKING:`` too):
    both read from one parse of the project (each parse is ~0.8 s of CPU)."""
    return tuple((a, b, inside, n) for a, b, inside, n, typing in _all_imports()
                 if with_types or not typing)


def _imports(mods: dict[str, Path]) -> list[tuple[str, str, bool, int, bool]]:
    """(importer, imported, inside a function, line, for type checkers only) for every import
    of a project module."""
    def resolve(name: str) -> str | None:
        parts = name.split(".")
        while parts:
            if ".".join(parts) in mods:
                return ".".join(parts)
            parts.pop()
        return None

    found = []
    for mod, path in mods.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]

        def visit(node: ast.AST, in_function: bool, typing: bool = False, mod=mod,
                  package=package) -> None:
            for ch in ast.iter_child_nodes(node):
                if isinstance(ch, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
                    visit(ch, True, typing)
                    continue
                if (isinstance(ch, ast.If) and isinstance(ch.test, ast.Name)
                        and ch.test.id == "TYPE_CHECKING"):
                    # for type checkers only: never run, but still a circle
                    visit(ch, in_function, True)
                    continue
                names: list[str] = []
                if isinstance(ch, ast.Import):
                    names = [a.name for a in ch.names]
                elif isinstance(ch, ast.ImportFrom):
                    base = ch.module or ""
                    if ch.level:
                        up = package.split(".")[:len(package.split(".")) - ch.level + 1]
                        base = ".".join(up + ([base] if base else []))
                    # the submodule when one is named, else the module itself
                    names = [f"{base}.{a.name}" if resolve(f"{base}.{a.name}") ==
                             f"{base}.{a.name}" else base for a in ch.names]
                for target in {resolve(n) for n in names} - {None, mod}:
                    found.append((mod, target, in_function, ch.lineno, typing))
                visit(ch, in_function, typing)

        visit(tree(path), False)
    return found


def _cycles(edges: dict[str, set[str]]) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[set[str]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    x = stack.pop()
                    on.discard(x)
                    comp.add(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    out.append(comp)
    return out


def test_no_import_cycle_among_project_modules():
    edges: dict[str, set[str]] = {}
    for a, b, _, _ in _project_imports():
        edges.setdefault(a, set()).add(b)
    cycles = [c for c in _cycles(edges) if c != KNOWN_CYCLE]
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(sorted(c)) for c in cycles)


def test_no_circle_through_type_only_imports():
    """Names imported only for annotations (``if TYPE_CHECKING:``) never run, but a circle
    through them is still two modules that cannot be read apart: the types live in a module
    of their own (``axisbase.tablespec``, ``align.gonio_run``)."""
    edges: dict[str, set[str]] = {}
    for a, b, _, _ in _project_imports(with_types=True):
        edges.setdefault(a, set()).add(b)
    cycles = _cycles(edges)
    assert not cycles, "circles: " + "; ".join(" <-> ".join(sorted(c)) for c in cycles)


def test_no_function_level_import_of_a_project_module():
    lazy = [f"{a} (line {n}) imports {b}" for a, b, inside, n in _project_imports()
            if inside and not a.startswith(LAZY_OK) and (a, b) not in LAZY_EDGES_OK
            and (a, b) not in KNOWN_LAZY]
    assert not lazy, "function-level imports hide cycles: " + "; ".join(lazy)


def test_the_checks_see_a_cycle_and_a_hidden_import(tmp_path):
    """The graph finds what it is for: a two-module cycle and a function-level import."""
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [{"a", "b"}]
    assert _cycles({"a": {"b"}, "b": {"c"}}) == []
    found = _project_imports()
    assert ("align.commands.main", "align.commands.parser", False) in {
        (a, b, f) for a, b, f, _ in found}
    assert any(a.startswith("align.commands") and inside for a, _, inside, _ in found)


def test_the_commands_do_not_import_scipy_stats():
    """scipy.stats costs ~0.8 s of CPU per process (most of a short command's run): the
    pipeline takes its normal and chi-square tails from scipy.special; only the joint
    conformance probability imports scipy.stats, inside the function that needs it."""
    import subprocess
    import sys

    code = ("import sys, align.session, align.calibration, align.marks, align.lot, "
            "align.commands.main, align.plan; print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1]).stdout
    assert out.strip() == "False"
