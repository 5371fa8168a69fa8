"""Figure plumbing shared by every plotting module: matplotlib's pyplot on the Agg backend
(imported on first use: matplotlib is heavy), PNG bytes for a report, a new PNG file that
overwrites nothing."""

from __future__ import annotations

import io
from pathlib import Path

from axisbase.output import write_atomic


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def tight(fig):
    """``fig`` laid out tightly when it is drawn, not now: the layout then measures its texts
    with the renderer and dpi the PNG is drawn at, where they are drawn from the same caches
    (``fig.tight_layout()`` measures them at the figure's own dpi, and the PNG at its dpi
    lays out every label again, the log axes' mathtext above all)."""
    fig.set_layout_engine("tight")
    return fig


# zlib level 3 instead of PIL's default 6: these figures come out smaller and the encoding
# takes a third less time (measured on the session report's figures).
PNG = {"compress_level": 3}


def png_bytes(fig, dpi: int = 90) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, pil_kwargs=PNG)
    pyplot().close(fig)
    return buf.getvalue()


def jpeg_bytes(fig, dpi: int = 90, quality: int = 75) -> bytes:
    """A photograph-like figure (an image's thumbnail) as JPEG: its sensor noise does not
    compress in a PNG (30 kB a thumbnail against 6 kB)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="jpeg", dpi=dpi, pil_kwargs={"quality": quality})
    pyplot().close(fig)
    return buf.getvalue()


def write_png(fig, folder: Path, stem: str) -> Path:
    """A new PNG (temporary name, then an exclusive rename: nothing is overwritten)."""
    out = new_png(Path(folder), stem)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, pil_kwargs=PNG)
    pyplot().close(fig)
    return write_atomic(out, buf.getvalue())


def new_png(folder: Path, stem: str) -> Path:
    """A PNG path in ``folder`` that does not exist yet (nothing is overwritten)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{stem}.png"
    k = 1
    while out.exists():
        out = folder / f"{stem}_{k}.png"
        k += 1
    return out
