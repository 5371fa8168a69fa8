"""The project's source as the static tests read it (nothing imported): each module's syntax
tree, parsed once for the whole test run.

Parsing every module is ~1 s of CPU; the import graph (tests/test_import_graph.py), the
numpydoc census (tests/test_numpydoc.py), the result types' fields
(tests/test_result_fields.py) and the commands' length (tests/test_module_size.py) each read
them, so they share this cache. The trees are read, never changed.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.cache
def tree(path: Path) -> ast.Module:
    """The syntax tree of the source file ``path`` (parsed on first use, then shared)."""
    return ast.parse(Path(path).read_text(encoding="utf-8"))
