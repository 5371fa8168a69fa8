"""Image files that are valid but unusual, or hostile, built byte by byte (no imaging library
writes a decompression bomb or every orientation tag): shared by the bad-input tests."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (struct.pack(">I", len(data)) + kind + data
            + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))


def png_bomb(path: Path, width: int = 20000, height: int = 20000) -> Path:
    """A complete, valid 8-bit gray PNG of ``width`` x ``height`` black pixels in a few
    hundred kB (20000 x 20000: ~390 kB declaring 400 MP). Built from one deflate block of
    200 rows repeated (a full flush resets the compressor, so each repeat is the same bytes)
    instead of compressing 400 MB, which takes seconds."""
    rows = 200
    assert height % rows == 0
    block = bytes((width + 1) * rows)  # filter byte 0 + zero pixels, per row
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    part = c.compress(block) + c.flush(zlib.Z_FULL_FLUSH)
    adler = 1
    for _ in range(height // rows):
        adler = zlib.adler32(block, adler)
    body = (b"\x78\xda" + part * (height // rows) + b"\x03\x00"  # final empty fixed block
            + struct.pack(">I", adler))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", body)
                     + _chunk(b"IEND", b""))
    return path
