"""Record batches of a table's text: pyarrow's streaming reader, or blocks on a thread pool.

A log of 10^8 rows is read in batches of bounded size; :func:`parallel_batches` parses blocks
of text cut at line ends on ``PARALLEL_WORKERS`` threads (pyarrow releases the GIL), handed on
in file order.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pacsv

from axisbase.header import Header


def read_batches(source, ro, po, co) -> Iterator[dict[str, pa.Array]]:
    reader = pacsv.open_csv(source, read_options=ro, parse_options=po, convert_options=co)
    try:
        for batch in reader:
            yield dict(zip(batch.schema.names, batch.columns, strict=True))
    finally:
        if not isinstance(source, str | Path):
            source.close()


# Text per parse task, and tasks in flight: 2 workers and one block ready ahead keep both
# cores busy; memory is ~4 x (2 MiB of text + its columns), whatever the file's length (4 MiB
# blocks: 19 MB more at the peak of a 10⁷-row log, no faster).
PARALLEL_BLOCK = 2 << 20
PARALLEL_WORKERS = 2
PARALLEL_AHEAD = 3


def _text_blocks(path: Path, skip: int, size: int) -> Iterator[bytes]:
    """The file after its first ``skip`` lines, in blocks of ~``size`` bytes cut after a line
    end (rows never span blocks: pyarrow's own parallel reader cuts the same way, values with
    line breaks not being allowed)."""
    with open(path, "rb") as f:
        for _ in range(skip):
            f.readline()
        while block := f.read(size):
            if not block.endswith(b"\n"):
                block += f.readline()
            yield block


def parallel_batches(path: Path, h: Header, ro, po, co) -> Iterator[dict[str, pa.Array]]:
    """Like :func:`read_batches`, parsed on ``PARALLEL_WORKERS`` threads: blocks of text cut at
    line ends, each parsed whole by ``pyarrow.csv.read_csv`` (which releases the GIL), handed
    on in file order as record batches of about ``ro.block_size`` bytes of text. pyarrow's
    streaming reader parses one block at a time; its whole-file ``read_csv`` holds the whole
    table (0.9 GB for a 10⁷-row log). A file with lone carriage returns as line ends is read
    serially (it is not cut at lines here)."""
    from concurrent.futures import ThreadPoolExecutor

    ro1 = pacsv.ReadOptions(column_names=ro.column_names, skip_rows=0, use_threads=False,
                            encoding=ro.encoding, block_size=min(PARALLEL_BLOCK * 2, 1 << 30))
    with open(path, "rb") as f:
        head = f.read(PARALLEL_BLOCK)
    if head.count(b"\r") != head.count(b"\r\n"):
        yield from read_batches(path, ro, po, co)
        return

    def parse(text: bytes) -> tuple[pa.Table, int]:
        return pacsv.read_csv(pa.py_buffer(text), read_options=ro1, parse_options=po,
                              convert_options=co), len(text)

    pool = ThreadPoolExecutor(PARALLEL_WORKERS, thread_name_prefix="csv")
    pending: list = []
    try:
        for text in _text_blocks(path, h.skip, PARALLEL_BLOCK):
            pending.append(pool.submit(parse, text))
            if len(pending) < PARALLEL_AHEAD:
                continue
            yield from _pieces(*pending.pop(0).result(), ro.block_size)
        for fut in pending:
            yield from _pieces(*fut.result(), ro.block_size)
        pending = []
    finally:
        for fut in pending:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)


def _pieces(table: pa.Table, text_bytes: int, block_bytes: int
            ) -> Iterator[dict[str, pa.Array]]:
    """A parsed block (of ``text_bytes`` of text) as batches of about ``block_bytes`` of text
    (zero-copy slices): the consumer's temporaries stay cache-sized."""
    table = table.combine_chunks()
    rows = table.num_rows
    if not rows:
        return
    step = max(1, rows * block_bytes // text_bytes)
    for s in range(0, rows, step):
        part = table.slice(s, step)
        yield {name: part.column(name).chunk(0) for name in part.column_names}
