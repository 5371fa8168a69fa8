"""The pieces every self-contained HTML page of the tool is built from (session report, lot
report): the Jinja2 templates (package data in ``align/templates``, autoescaped), escaping,
a table, a figure as an inline PNG (a data URI: the page is one file)."""

from __future__ import annotations

import base64
import functools
import html

from markupsafe import Markup


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


def png_img(png: bytes, alt: str = "figure", cls: str = "", mime: str = "image/png") -> Markup:
    """An ``<img>`` holding the image's bytes inline (PNG unless ``mime`` says otherwise;
    safe to put into a template as it is)."""
    c = f' class="{esc(cls)}"' if cls else ""
    return Markup(f'<img alt="{esc(alt)}"{c} '
                  f'src="data:{mime};base64,{base64.b64encode(png).decode()}">')


@functools.cache
def _environment():
    import jinja2

    # StrictUndefined: a name the page needs and the caller did not give is an error, not an
    # empty cell.
    return jinja2.Environment(loader=jinja2.PackageLoader("align", "templates"),
                              autoescape=True, trim_blocks=True, lstrip_blocks=True,
                              undefined=jinja2.StrictUndefined)


def render(template: str, **context: object) -> str:
    """The page ``align/templates/<template>`` rendered with ``context``."""
    return _environment().get_template(template).render(**context)
