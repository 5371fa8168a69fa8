"""Production lots: many session results read together, each of the six angles E_ij charted
over the units in run order (individuals control chart), units outside the limits or the
tolerance flagged, process capability, and the angles against the sessions' metadata.

Public API::

    result_files(paths) -> [Path]            (files as given, folders as their *.json)
    read_results(files) -> [ReadFile]        (a unit or why the file was rejected; never raises)
    analyse(units, rejected, tolerance) -> Lot   (a unit in several results counted once)
    lot_outputs(lot, read, outs, force, settings) -> (written, JSON)
    lot_document(lot, read, settings), lot_csv(lot), lot_warnings(lot), write_lot_report(...)
"""

from align.lot.document import lot_csv, lot_document, lot_outputs, lot_warnings
from align.lot.duplicates import Duplicate, find_duplicates
from align.lot.read import ANGLE_NAMES, ReadFile, Rejected, UnitResult, read_results, result_files
from align.lot.report import write_lot_report as _write
from align.lot.stats import (
    Capability,
    ControlChart,
    Lot,
    analyse,
    capability,
    control_chart,
)


def write_lot_report(lot, path, doc, force=False):
    """The HTML report (:func:`align.lot.report.write_lot_report`; matplotlib is imported
    only when a report is written)."""

    return _write(lot, path, doc, force)


__all__ = ["ANGLE_NAMES", "Capability", "ControlChart", "Duplicate", "Lot", "ReadFile",
           "Rejected", "UnitResult", "analyse", "capability", "control_chart",
           "find_duplicates", "lot_csv", "lot_document", "lot_outputs", "lot_warnings",
           "read_results", "result_files", "write_lot_report"]
