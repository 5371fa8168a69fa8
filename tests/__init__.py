"""The test suite. Imported before ``tests/conftest.py``, so before numpy: the place to set
what its BLAS reads when it loads."""

import os

# One BLAS thread per test process (and the ``python -m align`` processes tests start, which
# inherit it). The matrices are small, and on a machine whose cores are busy OpenBLAS's
# waiting threads spin: two threads cost ~20 % more CPU over tests/imaging/test_measure.py
# and tests/align/test_session.py (35.7 s against 28.4 s user+sys), for no result that
# differs beyond rounding. ``setdefault``: a value set outside wins.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
