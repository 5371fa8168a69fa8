"""A page of the tool in headless Chromium, measured: one browser run loads a copy of the page
with a probe script added (the pages themselves have none), takes a screenshot of the first
screen and dumps the DOM, into which the probe has written what it measured — where elements
are on the page, in-page links whose target does not exist, images that did not decode. The
browser's console must stay silent: an error there (a broken resource, the probe failing)
is a failure."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

WIDTH, HEIGHT = 1280, 900
"""The first screen: a laptop's window."""

PROBE = """<script>
window.addEventListener('load', () => {
  const box = (sel) => { const e = document.querySelector(sel); if (!e) return null;
    const r = e.getBoundingClientRect();
    return [r.top + window.scrollY, r.bottom + window.scrollY, e.textContent.trim()]; };
  const boxes = {};
  for (const sel of SELECTORS) boxes[sel] = box(sel);
  const links = [...document.querySelectorAll('a[href^="#"]')].map(a => a.getAttribute('href'));
  const out = {boxes: boxes, links: links,
    broken_links: links.filter(h => !document.getElementById(decodeURIComponent(h.slice(1)))),
    images: document.images.length,
    broken_images: [...document.images].filter(i => !(i.complete && i.naturalWidth > 0))
                                      .map(i => i.alt),
    height: document.documentElement.scrollHeight};
  const pre = document.createElement('pre');
  pre.id = 'probe-result';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


@dataclass
class Rendered:
    boxes: dict          # selector -> [top, bottom, text] [CSS px from the page's top] or None
    links: list          # every in-page link (href="#...")
    broken_links: list   # those whose target id does not exist
    images: int
    broken_images: list
    height: float        # the page's height [CSS px]
    console: list        # the browser's console lines (expected: none)
    screenshot: Path     # the first screen, WIDTH x HEIGHT


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if shutil.which(name):
            return name
    pytest.skip("headless Chromium is absent (Debian package 'chromium'; .ci/run installs it)")


def render(page: Path, selectors: list[str], out: Path) -> Rendered:
    """Load ``page`` (a copy with the probe, written beside it so relative links hold) and
    measure it; the screenshot goes to ``out``."""
    browser = chromium()
    probe = page.with_name(f".probe-{page.name}")
    text = page.read_text(encoding="utf-8")
    probe.write_text(text.replace("</body>", PROBE.replace("SELECTORS", json.dumps(selectors))
                                  + "</body>"), encoding="utf-8")
    try:
        run = subprocess.run(
            [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--enable-logging=stderr", "--v=0", "--virtual-time-budget=3000",
             f"--window-size={WIDTH},{HEIGHT}", f"--screenshot={out}", "--dump-dom",
             probe.as_uri()], capture_output=True, text=True, timeout=120)
    finally:
        probe.unlink()
    m = re.search(r'<pre id="probe-result">(.*?)</pre>', run.stdout, re.S)
    assert m is not None, run.stderr[-2000:]
    d = json.loads(html.unescape(m.group(1)))
    console = [x for x in run.stderr.splitlines() if ":CONSOLE" in x]
    return Rendered(d["boxes"], d["links"], d["broken_links"], d["images"],
                    d["broken_images"], d["height"], console, out)


def first_screen_is_not_blank(png: Path) -> None:
    """The screenshot shows text (dark pixels on a light page), not an empty window."""
    import numpy as np
    from PIL import Image

    img = np.asarray(Image.open(png).convert("L"), float)
    assert img.shape == (HEIGHT, WIDTH), img.shape
    assert img.std() > 20 and (img < 128).mean() > 0.005
