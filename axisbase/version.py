"""The tool's name and version (kept equal to pyproject.toml's; a test checks it)."""

TOOL = "axis-align"
__version__ = "0.1.0"
