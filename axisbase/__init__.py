"""The foundation every other package stands on: one exception hierarchy, one constant per
unit, and one reader for every table (CSV) the tool takes in.

``imaging``, ``goniometry``, ``align`` and ``synth`` may import this package; it imports
none of them.
"""

from axisbase.errors import AxisAlignError, InputError, InternalError
from axisbase.table import Column, Table, TableSpec, iter_table, parse_column_map, read_table
from axisbase.units import ARCMIN, ARCSEC, DEG, G0, MICRO_G

__all__ = [
    "ARCMIN", "ARCSEC", "DEG", "G0", "MICRO_G",
    "AxisAlignError", "Column", "InputError", "InternalError", "Table", "TableSpec",
    "iter_table", "parse_column_map", "read_table",
]
