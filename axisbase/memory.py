"""Process memory behaviour for streaming passes.

A streaming pass allocates and frees the same few MB-sized numpy temporaries block after
block. glibc's malloc serves blocks that large with fresh ``mmap`` pages and gives them back
on ``free`` (its threshold adapts only partly), so every block faults its pages in again: on a
10⁷-row counter log that was 165 000 page faults and a third of the pass's time, in the
kernel. Raising the thresholds keeps freed memory in the process for the next block (5 000
faults); peak memory is unchanged, since the same sizes are reused.
"""

from __future__ import annotations

import ctypes
import sys

# mallopt parameters (glibc's malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
# Blocks up to 16 MB come from the heap; up to 32 MB of freed memory is kept for reuse
# instead of being returned to the OS (larger settings saved no more faults on a counter log;
# 4 / 8 MB let them back: 210 000).
MMAP_THRESHOLD = 16 << 20
TRIM_THRESHOLD = 32 << 20

_done = False


def reuse_freed_memory() -> bool:
    """Keep freed memory for reuse (glibc only; elsewhere nothing is changed).

    Returns True when the setting took effect. Process-wide and idempotent.
    """
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt  # the symbols the interpreter is linked with
    except (OSError, AttributeError, TypeError):  # not glibc (e.g. musl has no mallopt)
        return False
    _done = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return _done
