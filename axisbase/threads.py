"""One BLAS thread for a run of ``align`` unless the user chose a thread count.

Why: the tool's linear algebra is many thousands of small solves (3 x 3 normal equations,
least squares over a few hundred rows), where a threaded BLAS spends more on waking its
threads, and on their spinning between calls, than on the arithmetic:
``align marks left03.jpg`` took 11.5-13.6 s CPU with OpenBLAS's default threads on a busy
2-core host and 0.7-0.9 s with one (the same answer). Work in parallel runs in processes
(``align lot``; Dask's workers are limited to one thread by Dask itself).

The thread count of OpenBLAS, MKL and OpenMP is read from the environment when the library
loads; the commands import numpy and scipy inside the run, so setting it here, before them,
is enough, and processes the run starts inherit it. A count the user set (any of the
variables) is left as it is.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""The environment variables the BLAS libraries numpy and scipy ship with read at load."""


def one_thread_environment() -> dict[str, str]:
    """The variables to set for one BLAS thread: {} when the user set any of
    :data:`THREAD_VARIABLES` (their choice stands)."""
    if any(os.environ.get(v) for v in THREAD_VARIABLES):
        return {}
    return {v: "1" for v in THREAD_VARIABLES}


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Within the block, BLAS libraries loaded from now on use one thread, unless the user set
    any of :data:`THREAD_VARIABLES`; the environment is restored on leaving (``align``'s
    ``main()`` may run in-process, more than once)."""
    setting = one_thread_environment()
    before = {v: os.environ.get(v) for v in setting}
    os.environ.update(setting)
    try:
        yield
    finally:
        for v, value in before.items():
            if value is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = value
