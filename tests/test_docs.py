"""The documentation says only what the tool does: README.md and docs/ against the code.

* every ``align COMMAND … --flag`` written in them is an option of that command's parser (read
  from ``python3 -m align COMMAND --help``, so the test does not depend on where the parser
  lives);
* every relative link resolves (to a file, and to a heading when it names an anchor);
* README.md stays a first page (≤ 200 lines);
* the Python blocks marked ``<!-- example -->`` run, and the shell blocks marked
  ``<!-- example-shell -->`` exit 0 (slow: each in a fresh copy of ``align demo``'s folder);
* the `session.toml` examples load and the generated schema tables are current.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted([ROOT / "README.md", *DOCS.rglob("*.md")])
COMMANDS = ("demo", "run", "marks", "camera", "calibrate", "tilt", "gonio", "apply", "lot",
            "synth", "init", "check")
# `align synth` has one subcommand; its flags are those of `align synth session`.
HELP_ARGS = {"synth": ("synth", "session")}
# Flags on a command's page that belong to another program.
NOT_OURS = {("run", "--nthreads")}  # `dask worker --nthreads 1`


def _rel(p: Path) -> str:
    return str(p.relative_to(ROOT))


def _code_spans_and_blocks(text: str) -> list[str]:
    """The text of every fenced block and every inline code span (where commands are written)."""
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.S | re.M)
    prose = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.S | re.M)
    return blocks + re.findall(r"`([^`\n]+)`", prose)


def mentioned_flags() -> dict[str, set[tuple[str, str]]]:
    """command -> {(flag, page)} for every ``align COMMAND ... --flag`` in the docs.

    A command line runs from ``align COMMAND`` to the end of its line (a continuation line of a
    fenced block, indented, belongs to the line above); a ``#`` comment ends it."""
    found: dict[str, set[tuple[str, str]]] = {c: set() for c in COMMANDS}
    for page in PAGES:
        for chunk in _code_spans_and_blocks(page.read_text(encoding="utf-8")):
            lines: list[str] = []
            for line in chunk.splitlines():
                if lines and line.startswith(" ") and not line.lstrip().startswith("align "):
                    lines[-1] += " " + line
                else:
                    lines.append(line)
            for line in lines:
                for m in re.finditer(r"\balign (\w+)\b(.*)", line):
                    cmd, rest = m.group(1), m.group(2).split(" # ")[0]
                    rest = re.split(r"\balign \w+", rest)[0]
                    if cmd not in found:
                        continue
                    for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", rest):
                        found[cmd].add((flag, _rel(page)))
    # On a command's own page a flag written alone (`--roi`) is that command's.
    for cmd in COMMANDS:
        page = DOCS / "commands" / f"{cmd}.md"
        for chunk in _code_spans_and_blocks(page.read_text(encoding="utf-8")):
            if re.search(r"\balign \w|\bdask ", chunk):
                continue
            for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", chunk):
                if (cmd, flag) not in NOT_OURS:
                    found[cmd].add((flag, _rel(page)))
    return found


# One interpreter prints every command's --help through the module entry point, as
# `python3 -m align COMMAND --help` would (one start-up instead of ten).
_HELPS = """
import runpy, sys
for args in ARGS:
    sys.argv = ["align", *args, "--help"]
    print("\\0" + args[0])
    try:
        runpy.run_module("align", run_name="__main__", alter_sys=True)
    except SystemExit:
        pass
"""


@cache
def _help_texts() -> dict[str, str]:
    args = [HELP_ARGS.get(c, (c,)) for c in COMMANDS]
    out = subprocess.run([sys.executable, "-c", _HELPS.replace("ARGS", repr(args))], cwd=ROOT,
                         capture_output=True, text=True, timeout=120, check=True).stdout
    texts = dict(part.split("\n", 1) for part in out.split("\0")[1:])
    assert sorted(texts) == sorted(COMMANDS), out[:500]
    return texts


def parser_flags(cmd: str) -> frozenset[str]:
    return frozenset(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", _help_texts()[cmd]))


def test_the_docs_mention_every_command():
    text = "\n".join(p.read_text(encoding="utf-8") for p in PAGES)
    assert not [c for c in COMMANDS if f"align {c}" not in text]


@pytest.mark.parametrize("cmd", COMMANDS)
def test_every_flag_the_docs_mention_exists(cmd):
    mentioned = mentioned_flags()[cmd]
    unknown = sorted(f"{page}: align {cmd} {flag}" for flag, page in mentioned
                     if flag not in parser_flags(cmd))
    assert not unknown, "flags the docs mention that the parser does not have:\n" + "\n".join(
        unknown)


def test_the_flag_scan_finds_flags():
    # The check above must not pass because the scan finds nothing.
    found = mentioned_flags()
    assert ("--json", "README.md") in found["run"]
    assert ("--roi", "docs/commands/marks.md") in found["marks"]
    assert ("--fix-k3", "docs/commands/camera.md") in found["camera"]


def _anchors(page: Path) -> set[str]:
    """Heading anchors as MkDocs' toc extension makes them (lower case, punctuation dropped,
    spaces to hyphens); README headings as GitHub makes them (the same for these headings)."""
    out = set()
    text = re.sub(r"^```[^\n]*\n.*?^```", "", page.read_text(encoding="utf-8"),
                  flags=re.S | re.M)
    for line in text.splitlines():
        m = re.match(r"#{1,6} (.+)", line)
        if m:
            slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower())
            out.add(re.sub(r"[ ]+", "-", slug.strip()))
    return out


def relative_links(page: Path) -> list[tuple[str, str]]:
    """(target, anchor) of every Markdown link or image that is not absolute or mail, outside
    code."""
    text = page.read_text(encoding="utf-8")
    text = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.S | re.M)
    text = re.sub(r"`[^`\n]+`", "", text)
    out = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        out.append((path, anchor))
    return out


@pytest.mark.parametrize("page", PAGES, ids=_rel)
def test_every_relative_link_resolves(page):
    broken = []
    for path, anchor in relative_links(page):
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{path}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(f"{path}#{anchor}: no such heading")
    assert not broken, f"{_rel(page)}: " + "; ".join(broken)


def test_the_link_check_sees_links():
    assert ("docs/formats.md", "sessiontoml") in relative_links(ROOT / "README.md")


def test_readme_is_a_first_page():
    n = len((ROOT / "README.md").read_text(encoding="utf-8").splitlines())
    assert n <= 200, f"README.md has {n} lines (at most 200: the rest belongs in docs/)"


def examples() -> list[tuple[str, int, str]]:
    """(page, line, code) of every ```python block directly after a ``<!-- example -->`` line."""
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"<!-- example -->\n```python\n(.*?)^```", text, flags=re.S | re.M):
            out.append((_rel(page), text[:m.start()].count("\n") + 2, m.group(1)))
    return out


def test_there_are_examples():
    assert len(examples()) >= 3


@pytest.mark.parametrize("page,line,code", examples(), ids=lambda v: str(v)[:40])
def test_example_runs(page, line, code, monkeypatch):
    # As a reader pastes it at the project's root: a fresh ``__main__`` namespace, run from
    # the root (in this process: a fresh interpreter per example cost ~1.4 s CPU of imports
    # each; the example's own imports are what it shows).
    monkeypatch.chdir(ROOT)
    failure = None
    try:
        exec(compile(code, f"{page}:{line}", "exec"), {"__name__": "__main__"})
    except Exception as exc:  # any failure of the example is the finding, with its place
        failure = f"{type(exc).__name__}: {exc}"
    assert failure is None, f"{page}:{line}: the example fails: {failure}"


def shell_examples() -> list[tuple[str, int, str]]:
    """(page, line, block) of every ```bash block directly after ``<!-- example-shell -->``."""
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"<!-- example-shell -->\n```bash\n(.*?)^```", text,
                             flags=re.S | re.M):
            out.append((_rel(page), text[:m.start()].count("\n") + 3, m.group(1)))
    return out


def test_there_are_shell_examples():
    assert len(shell_examples()) >= 8


@pytest.fixture(scope="module")
def demo_folder(tmp_path_factory) -> Path:
    """What ``align demo --out /tmp/demo`` writes, once: the pages' examples name its files."""
    out = tmp_path_factory.mktemp("docs-demo") / "demo"
    done = subprocess.run([sys.executable, "-m", "align", "demo", "--out", str(out), "-q"],
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    return out


@pytest.mark.slow
@pytest.mark.parametrize("page,line,block", shell_examples(), ids=lambda v: str(v)[:40])
def test_shell_example_runs(page, line, block, demo_folder, tmp_path):
    # As a reader types it, line by line: in a fresh copy of the demo's folder standing where
    # the pages say (/tmp/demo), starting in an empty folder; `cd` moves, every other line is
    # an `align` command that must exit 0.
    demo = tmp_path / "demo"
    shutil.copytree(demo_folder, demo)
    cwd = tmp_path / "work"
    cwd.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for k, raw in enumerate(block.splitlines()):
        words = shlex.split(raw.replace("/tmp/demo", str(demo)), comments=True)
        if not words:
            continue
        where = f"{page}:{line + k}: {raw.strip()}"
        if words[0] == "cd":
            cwd = (cwd / words[1]).resolve()
            assert cwd.is_dir(), f"{where}: no such folder"
            continue
        assert words[0] == "align", f"{where}: a shell example runs align commands only"
        done = subprocess.run([sys.executable, "-m", "align", *words[1:]], cwd=cwd, env=env,
                              capture_output=True, text=True)
        assert done.returncode == 0, f"{where}: exit {done.returncode}\n{done.stderr[-1500:]}"


def test_the_schema_tables_are_current():
    # docs/generated/schemas.md is included by docs/formats.md; it must list today's schemas.
    spec = importlib.util.spec_from_file_location("gen", DOCS / "gen_schema_tables.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    current = (DOCS / "generated" / "schemas.md").read_text(encoding="utf-8")
    assert current == gen.render(), "run: python3 docs/gen_schema_tables.py"


@pytest.mark.parametrize("page", ["README.md", "docs/formats.md"])
def test_the_session_toml_examples_load(page, tmp_path):
    # The README's sketch and the complete example (its commented keys switched on) are
    # accepted by the session loader, with an empty file wherever they name one.
    from align.session import load_session

    text = (ROOT / page).read_text(encoding="utf-8")
    toml = re.search(r"```toml\n(.*?)^```", text, flags=re.S | re.M).group(1)
    toml = re.sub(r"^# (\w+ = )", r"\1", toml, flags=re.M)
    (tmp_path / "session.toml").write_text(toml, encoding="utf-8")
    named = re.findall(r'^(?:static|log|file|model|check) = "([^"]+)"', toml, flags=re.M)
    assert len(named) >= 4
    for name in named:
        (tmp_path / name).write_text("x\n", encoding="utf-8")
    load_session(tmp_path)


def test_the_lens_ranges_defaults_are_the_codes():
    """The `--lens` defaults are written three times for the reader (the table in
    docs/commands/marks.md, `align marks --help`, session.toml's commented keys in
    docs/formats.md): each says what :class:`align.lens_design.LensRanges` holds (independent
    user 16 found pp_px written as 20 in the table, 40 in the code)."""
    from align.lens_design import DEFAULT_RANGES

    table = (ROOT / "docs/commands/marks.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `(\w+)` \| ([0-9.e-]+) \|", table, flags=re.M))
    formats = (ROOT / "docs/formats.md").read_text(encoding="utf-8")
    commented = dict(re.findall(r"^# lens_(\w+) = ([0-9.e-]+)", formats, flags=re.M))
    helptext = "".join(_help_texts()["marks"].split())
    said = {k: float(v) for k, v in re.findall(r"\b(\w+)=([0-9.]+)", helptext.split("defaults")[1])}
    for key in ("k1", "k2", "p", "aspect", "pp_px", "max_u_arcsec"):
        want = float(getattr(DEFAULT_RANGES, key))
        assert float(rows[key]) == want, ("docs/commands/marks.md", key, rows[key], want)
        assert float(commented[key]) == want, ("docs/formats.md", key, commented[key], want)
        assert said[key] == want, ("align marks --help", key, said[key], want)


# docs/contributing.md names files and Python objects for the next developer: each must exist.
CONTRIBUTING = DOCS / "contributing.md"
_PATH_SPAN = re.compile(r"^[\w.-]+(?:/[\w.*-]+)*/(?:[\w.*-]+\.(?:py|json|md|toml|yml))?$")
_NAME_SPAN = re.compile(r"^(?:align|axisbase|goniometry|imaging|synth|tests)(?:\.\w+)+$")


def _named(text: str) -> tuple[list[str], list[str]]:
    """(paths, dotted names) written alone as inline code in ``text`` (a path has a ``/``:
    a folder, or a file with its suffix, relative to the repository's root; a dotted name
    starts with one of the project's packages)."""
    prose = re.sub(r"^```[^\n]*\n.*?^```", "", text, flags=re.S | re.M)
    spans = re.findall(r"`([^`\n]+)`", prose)
    # (``../shared/data/real/``: the real data beside the checkout, not part of it)
    paths = [s for s in spans if _PATH_SPAN.match(s) and not s.startswith("../")]
    return paths, [s for s in spans if _NAME_SPAN.match(s)]


def _top_names(path: Path) -> set[str]:
    """The names a module binds at its top level (defs, classes, assignments, imports), and
    ``Class.member`` for each class's own defs and fields: read, not imported (cheap)."""
    import ast

    out: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            out.add(node.name)
            if isinstance(node, ast.ClassDef):
                for m in node.body:
                    if isinstance(m, ast.FunctionDef | ast.AsyncFunctionDef):
                        out.add(f"{node.name}.{m.name}")
                    elif isinstance(m, ast.AnnAssign) and isinstance(m.target, ast.Name):
                        out.add(f"{node.name}.{m.target.id}")
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            out |= {t.id for t in targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.Import | ast.ImportFrom):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return out


def resolves(name: str) -> bool:
    """Whether ``pkg.module[.Object[.member]]`` names a module of the project, or an object
    its source binds at top level (a class's member one level down)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:k])
        module = base.with_suffix(".py") if base.with_suffix(".py").is_file() else (
            base / "__init__.py" if (base / "__init__.py").is_file() else None)
        if module is None:
            continue
        rest = parts[k:]
        if not rest:
            return True
        if len(rest) > 2:
            return False
        return ".".join(rest) in _top_names(module)
    return False


def test_the_developer_page_names_what_exists():
    paths, names = _named(CONTRIBUTING.read_text(encoding="utf-8"))
    missing = [p for p in paths if not any(ROOT.glob(p.rstrip("/")))]
    unknown = [n for n in names if not resolves(n)]
    assert not missing and not unknown, f"docs/contributing.md: no such file {missing}, " \
                                        f"no such name {unknown}"


def test_the_developer_page_check_sees_names():
    # The check above must not pass because it finds nothing, and must fail on a stale name.
    paths, names = _named(CONTRIBUTING.read_text(encoding="utf-8"))
    assert "align/problem_codes.py" in paths and "tests/test_import_graph.py" in paths
    assert "align.contract.read_json" in names and "align.loop.Candidate" in names
    assert resolves("align.gonio_loop.RevolutionStage.fit")
    assert not resolves("align.contract.no_such_function")
    assert not resolves("axisbase.no_such_module")
    assert not any(ROOT.glob("align/no_such_module.py"))
