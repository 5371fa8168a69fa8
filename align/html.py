"""The pieces every self-contained HTML page of the tool is built from (session report, lot
report): escaping, a table, a figure as an inline PNG (a data URI: the page is one file)."""

from __future__ import annotations

import base64
import html


def esc(text: object) -> str:
    """``text`` escaped for HTML."""
    return html.escape(str(text))


def table(head: list[str], rows: list[list[object]], left: int = 1) -> str:
    """A table; the first ``left`` columns left-aligned (CSS class ``l``), the rest right."""
    h = "".join(f'<th class="{"l" if i < left else ""}">{esc(c)}</th>'
                for i, c in enumerate(head))
    body = "".join("<tr>" + "".join(f'<td class="{"l" if i < left else ""}">{esc(c)}</td>'
                                    for i, c in enumerate(r)) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{body}</table>"


def png_img(png: bytes, alt: str = "figure") -> str:
    """An ``<img>`` holding PNG bytes inline."""
    return f'<img alt="{esc(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'
