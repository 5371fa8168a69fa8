"""What the lot decides about each unit, and its warnings ranked for the reader.

A unit's verdict is the one ``align lot`` reached itself when it judged the units (the lot
JSON's ``dispositions``), else its own result's ``disposition`` when the result has one (the
session's tolerance and decision rule); otherwise, with the lot's tolerance ±T, the lot's rule: FAIL
when an angle is outside ±T, INCONCLUSIVE when one is inside by less than GUARD·u (its
conformance cannot be stated), PASS otherwise; NOT MEASURED when the result is not ok or not
fused (never a verdict on its numbers); NO TOLERANCE without any tolerance.

The warnings are split into what someone must *act* on (files not read, units not ok or out
of tolerance, a process not capable) and what to *note* (control-limit flags a lot of this
size expects by chance, metadata differences, provisional limits, duplicates); a message
repeated with other numbers or angles is one line with a count.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from align.lot.read import ANGLE_NAMES
from align.lot.stats import Lot
from axisbase.units import ARCSEC

SEVERITY = {"FAIL": 0, "INCONCLUSIVE": 1, "NOT MEASURED": 2, "PASS": 3, "NO TOLERANCE": 4}
"""Order of the verdicts in the lot's table: what needs a decision first."""


@dataclass(frozen=True)
class UnitDisposition:
    """One unit's verdict. ``worst``: the angle with the smallest margin (None when not
    measured or without a tolerance); ``margin_arcsec``: its margin to the tolerance [″]
    (negative: outside); ``source``: "result" (the unit's own disposition) or "lot" (the
    lot's ±T); ``index``: the unit's index in ``Lot.units``."""

    index: int
    verdict: str
    worst: str | None
    margin_arcsec: float | None
    source: str


def _from_disposition(k: int, d: Mapping[str, Any], source: str) -> UnitDisposition:
    """A unit's verdict from a disposition document (the session result's ``disposition``,
    or an entry of the lot JSON's ``dispositions``)."""
    worst = d.get("worst")
    margin = next((a.get("margin_arcsec") for a in d.get("angles") or []
                   if a.get("name") == worst), None)
    return UnitDisposition(k, str(d["verdict"]), worst, margin, source)


def unit_dispositions(lot: Lot, decided: Sequence[Mapping[str, Any]] | None = None
                      ) -> list[UnitDisposition]:
    """Every unit's verdict, most severe first (then in the lot's order). ``decided``: the
    lot JSON's ``dispositions`` (one per unit, in the lot's order) when ``align lot``
    judged the units itself — taken as they are."""
    if decided is not None and len(decided) == len(lot.units):
        out = [_from_disposition(k, d, "lot") for k, d in enumerate(decided)]
        return sorted(out, key=lambda x: (SEVERITY.get(x.verdict, 5), x.index))
    marginal = {k for a in lot.angles for k in a.marginal}
    outside = {k for a in lot.angles for k in a.outside_tolerance}
    out = []
    for k, u in enumerate(lot.units):
        d = u.disposition
        if (d is not None and isinstance(d.get("verdict"), str)
                and (d["verdict"] != "NO TOLERANCE" or lot.tolerance is None)):
            out.append(_from_disposition(k, d, "result"))
        elif not (u.ok and u.fused) or u.e_rad is None:
            out.append(UnitDisposition(k, "NOT MEASURED", None, None, "lot"))
        elif lot.tolerance is None:
            out.append(UnitDisposition(k, "NO TOLERANCE", None, None, "lot"))
        else:
            margins = [lot.tolerance - abs(v) for v in u.e_rad]
            i = min(range(6), key=lambda j: margins[j])
            verdict = ("FAIL" if k in outside else "INCONCLUSIVE" if k in marginal
                       else "PASS")
            out.append(UnitDisposition(k, verdict, ANGLE_NAMES[i], margins[i] / ARCSEC,
                                       "lot"))
    return sorted(out, key=lambda x: (SEVERITY.get(x.verdict, 5), x.index))


def session_report_of(result_file: str | Path) -> Path | None:
    """The HTML report beside a session result, when it is there: the same name with
    ``.html`` (``align run S1 S2 --json DIR --report DIR``), or ``report.html`` beside a
    ``result.json`` (``align demo``)."""
    p = Path(result_file)
    for cand in (p.with_suffix(".html"),
                 p.parent / "report.html" if p.name == "result.json" else None):
        if cand is not None and cand.is_file():
            return cand
    return None


def relative_link(target: Path, page: Path) -> str:
    """``target`` as a link relative to the folder of ``page`` (the page may be moved with
    the results)."""
    return Path(os.path.relpath(target.resolve(), page.resolve().parent)).as_posix()


WARNING_CODES = {"not_read": True, "not_ok": True, "no_statistics": True,
                 "outside_tolerance": True, "not_capable": True, "spelling": False,
                 "duplicate": False, "provisional": False, "control_limits": False,
                 "differs_with_metadata": False}
"""The code of each of the lot's warnings (``warning_codes`` in the lot JSON, one per line of
``warnings``) and whether it is for someone to *act* on (else a note): the report ranks them
by code, never by their text."""


_SHAPE = re.compile(r"E_[xyz][XYZ]|[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?|unit \S+|\([^)]*\)")


_WHO = re.compile(r"unit ([^\s:(),;]+)|E_[xyz][XYZ]")
"""What tells apart messages of one shape: the unit and the angle they name."""


def shape(line: str) -> str:
    """The message with its numbers, angle names, units and parenthesised details taken out:
    messages of one shape say the same thing of different angles or units."""
    return _SHAPE.sub("#", line)


@dataclass(frozen=True)
class RankedLine:
    """One line of the ranked warnings: the first message of its shape and how many there
    are (``count`` 1: a single message), with what differs between them (``variants``)."""

    text: str
    count: int
    variants: tuple[str, ...] = ()


def rank_warnings(items: Sequence[tuple[str, str]]
                  ) -> tuple[list[RankedLine], list[RankedLine]]:
    """``(act, note)``: the lot's warnings, (code, text) each, split by their code
    (:data:`WARNING_CODES`: an unknown code is for someone to act on),
    one line per shape with a count, in the order first met."""
    groups: dict[tuple[bool, str], list[str]] = {}
    for code, line in items:
        act = WARNING_CODES.get(code, True)
        groups.setdefault((act, shape(line)), []).append(line)
    act, note = [], []
    for (is_act, _), same in groups.items():
        names = tuple(dict.fromkeys(" ".join(m.group(1) or m.group(0) for m in _WHO.finditer(x))
                                    for x in same)) if len(same) > 1 else ()
        (act if is_act else note).append(RankedLine(same[0], len(same), names))
    return act, note


def lot_name(lot: Lot, files: list[str] | None = None) -> str:
    """The lot's name: the ``lot`` metadata key when every unit gives the same one, else the
    folder the results share, else "unnamed"."""
    values = {str(u.metadata["lot"]) for u in lot.units if "lot" in u.metadata}
    if len(values) == 1 and all("lot" in u.metadata for u in lot.units):
        return values.pop()
    paths = [Path(u.file).resolve().parent for u in lot.units] if files is None else [
        Path(f).resolve().parent for f in files]
    if paths:
        common = Path(os.path.commonpath([str(p) for p in paths]))
        if common.name:
            return common.name
    return "unnamed"
