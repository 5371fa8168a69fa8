"""The foundation every other package stands on: one exception hierarchy, one constant per
unit, one reader for every table (CSV) the tool takes in, one writer for every output, and the
provenance every result carries.

``imaging``, ``goniometry``, ``align`` and ``synth`` may import this package; it imports
none of them. Names are loaded on first use (PEP 562), so ``import axisbase`` does not pull in
numpy or pyarrow (``align --help`` must start fast).
"""

from importlib import import_module

from axisbase.errors import AxisAlignError, InputError, InternalError, NotApplicable
from axisbase.units import ARCMIN, ARCSEC, DEG, G0, MICRO_G
from axisbase.version import __version__

_LAZY = {
    "Column": "axisbase.table", "Table": "axisbase.table", "TableSpec": "axisbase.table",
    "iter_table": "axisbase.table", "read_table": "axisbase.table",
    "rate_warning": "axisbase.table",
    "OUTPUT_UNITS": "axisbase.header", "header_units": "axisbase.header",
    "parse_column_map": "axisbase.header", "resolve_units": "axisbase.header",
    "check_repeats": "axisbase.repeats", "find_copy": "axisbase.repeats",
    "row_keys": "axisbase.repeats", "Copy": "axisbase.repeats",
    "OutputError": "axisbase.output", "OutputPlan": "axisbase.output",
    "OutputSet": "axisbase.output", "Stopped": "axisbase.stop",
    "dumps": "axisbase.output", "write_atomic": "axisbase.output",
    "write_json": "axisbase.output",
    "envelope": "axisbase.provenance", "provenance": "axisbase.provenance",
    "check_format": "axisbase.provenance", "Provenance": "axisbase.provenance",
    "one_blas_thread": "axisbase.threads", "one_thread_environment": "axisbase.threads",
}

__all__ = [
    "ARCMIN", "ARCSEC", "DEG", "G0", "MICRO_G", "__version__",
    "AxisAlignError", "InputError", "InternalError", "NotApplicable", *_LAZY,
]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'axisbase' has no attribute {name!r}")
