"""Small modules with one job: no module of the project is over 600 lines (a module that grows
past it is split along its jobs, its public names re-exported where they were)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("align", "axisbase", "goniometry", "imaging", "synth")
LIMIT = 600


def test_no_module_over_600_lines():
    sizes = {str(f.relative_to(ROOT)): len(f.read_text(encoding="utf-8").splitlines())
             for pkg in PACKAGES for f in (ROOT / pkg).rglob("*.py")}
    assert len(sizes) > 50  # the packages were found
    over = {f: n for f, n in sizes.items() if n > LIMIT}
    assert not over, over
