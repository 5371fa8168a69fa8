"""Write ``docs/generated/schemas.md``: the keys of every output's JSON Schema as tables.

The file formats page includes it (pymdownx.snippets), so the key lists come from
``align/schemas/`` and cannot drift from them; ``tests/test_docs.py`` fails when the committed
fragment differs from what this script writes now. Run from the repository's root:
``python3 docs/gen_schema_tables.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCHEMAS = ROOT / "align" / "schemas"
OUT = ROOT / "docs" / "generated" / "schemas.md"
INPUTS = ("session-toml",)
"""Schemas of files the tool reads (session.toml: docs/getting-started-own-data.md), not outputs."""
ORDER = ("marks", "camera", "calibration", "tilt", "gonio", "session", "platform-calibration",
         "lot")


def _type(spec: dict) -> str:
    if "const" in spec:
        return f"`{json.dumps(spec['const'])}`"
    if "$ref" in spec:
        return spec["$ref"].rsplit("/", 1)[-1]
    t = spec.get("type", "any")
    t = " or ".join(t) if isinstance(t, list) else t
    if t == "array" and isinstance(spec.get("items"), dict) and "type" in spec["items"]:
        it = spec["items"]["type"]
        t += " of " + (" or ".join(it) if isinstance(it, list) else it)
    return t


def table(kind: str) -> str:
    d = json.loads((SCHEMAS / f"{kind}.schema.json").read_text(encoding="utf-8"))
    required = set(d.get("required", ()))
    cond = set(d.get("then", {}).get("required", ()))
    rows = [f"### {kind}", "", f"{d.get('title', kind)}; `align/schemas/{kind}.schema.json`.",
            "", "| key | type | required |", "|---|---|---|"]
    for key, spec in d.get("properties", {}).items():
        req = "yes" if key in required else ("when fused" if key in cond else "")
        rows.append(f"| `{key}` | {_type(spec)} | {req} |")
    return "\n".join(rows) + "\n"


def kinds() -> list[str]:
    """The known outputs in reading order, then any schema added since, by name."""
    on_disk = sorted(p.name.removesuffix(".schema.json") for p in SCHEMAS.glob("*.schema.json"))
    return [k for k in ORDER if k in on_disk] + [
        k for k in on_disk if k not in ORDER and k not in ("envelope", *INPUTS)]


def render() -> str:
    env = table("envelope").replace("### envelope", "### Every output (the envelope)")
    return ("<!-- written by python3 docs/gen_schema_tables.py; do not edit -->\n\n" + env + "\n"
            + "\n".join(table(k) for k in kinds()))


if __name__ == "__main__":
    OUT.write_text(render(), encoding="utf-8")
    print(f"wrote {OUT.relative_to(ROOT)}")
