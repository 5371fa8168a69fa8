"""The same unit in several results of a lot: which one is counted.

A unit is what the lot calls it (README): metadata ``unit`` or ``serial``, else the session
name — :attr:`UnitResult.label`. Two results with the same label are the same unit: an
identical copy (same SHA-256), the same session data processed again (the same SHA-256 for
every input file), or the unit measured again. Counting it twice would weigh it twice in the
mean, the standard deviation, the moving ranges (a zero range between copies shrinks σ_w and
tightens the limits) and the capability, so each unit is counted once:

1. a result that is ok and fused (it can enter the statistics) before one that is not;
2. then the latest measurement (metadata date/time, when every candidate has a different one);
3. then the newest result (``created_utc`` of its envelope: the latest processing);
4. then the last given (for identical copies: the first, they are the same).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from align.lot.read import UnitResult


@dataclass(frozen=True)
class Duplicate:
    """One unit found in several results.

    Attributes
    ----------
    label : str
        The unit; unit —.
    used : int
        Index into the lot's units of the result counted — dimensionless.
    left_out : tuple of int
        Indices of the results not counted — dimensionless.
    relations : tuple of str
        ``relations[i]``: how ``left_out[i]`` relates to the used result; unit —.
    why : str
        Which rule chose the one counted; unit —.
    """

    label: str
    used: int
    left_out: tuple[int, ...]
    relations: tuple[str, ...]
    why: str

    def to_dict(self, units: Sequence[UnitResult]) -> dict:
        return {"unit": self.label, "used": units[self.used].file, "why": self.why,
                "left_out": [{"file": units[k].file, "relation": r}
                             for k, r in zip(self.left_out, self.relations, strict=True)]}


IDENTICAL = "an identical copy, same SHA-256"
SAME_DATA = "the same session data processed again, same input files"
OTHER_DATA = "another measurement of the unit, other input files"


def _relation(a: UnitResult, b: UnitResult) -> str:
    if a.sha256 is not None and a.sha256 == b.sha256:
        return IDENTICAL
    if a.inputs_sha256 and a.inputs_sha256 == b.inputs_sha256:
        return SAME_DATA
    return OTHER_DATA


def _usable(u: UnitResult) -> bool:
    return u.ok and u.fused and u.e_rad is not None and u.u_rad is not None


def _choose(units: Sequence[UnitResult], group: list[int]) -> tuple[int, str]:
    """The result counted for one unit (see the module's rules) and why."""
    usable = [k for k in group if _usable(units[k])]
    if len(usable) == 1:
        return usable[0], "the only one ok and fused"
    cand = usable or group
    prefix = "of those ok and fused, " if len(cand) < len(group) else ""

    def tell(rule: str) -> str:
        return prefix + rule

    if all(_relation(units[cand[0]], units[k]) == IDENTICAL for k in cand[1:]):
        return cand[0], tell("the first given, the copies being identical")
    whens = [units[k].when for k in cand]
    if all(w is not None for w in whens) and len(set(whens)) == len(whens):
        return cand[max(range(len(cand)), key=lambda i: whens[i])], tell(
            "the latest measured by its metadata date/time")
    made = [units[k].created_utc for k in cand]
    if all(m is not None for m in made) and len(set(made)) == len(made):
        # ISO 8601 UTC texts of one format ('...Z') sort as times.
        return cand[max(range(len(cand)), key=lambda i: made[i])], tell(
            "the newest result by its created_utc")
    return cand[-1], tell("the last given")


def unit_key(label: str) -> str:
    """The label as units are compared: trimmed, inner white space as one space, case-folded
    ('SN-4 ', 'sn-4' and 'SN-4' are one unit)."""
    return " ".join(label.split()).casefold()


def spelling_warnings(units: Sequence[UnitResult]) -> list[str]:
    """One line per unit whose serial is written in more than one way across the lot (taken
    as one unit; the spellings named so a typo can be found)."""
    spellings: dict[str, list[str]] = {}
    for u in units:
        raw = next((str(u.metadata[k]) for k in ("unit", "serial")
                    if u.metadata.get(k) not in (None, "")), u.label)
        seen = spellings.setdefault(unit_key(u.label), [])
        if raw not in seen:
            seen.append(raw)
    return [f"unit {s[0].strip()!r} is written {len(s)} ways ({', '.join(map(repr, s))}): "
            "taken as one unit (serials are compared trimmed and case-folded)"
            for s in spellings.values() if len(s) > 1]


def find_duplicates(units: Sequence[UnitResult]) -> tuple[Duplicate, ...]:
    """Every unit that appears in more than one result, in the order of first appearance."""
    groups: dict[str, list[int]] = {}
    for k, u in enumerate(units):
        groups.setdefault(unit_key(u.label), []).append(k)
    out = []
    for group in groups.values():
        if len(group) < 2:
            continue
        label = units[group[0]].label  # as first written (the key is case-folded)
        used, why = _choose(units, group)
        left = tuple(k for k in group if k != used)
        out.append(Duplicate(label, used, left,
                             tuple(_relation(units[used], units[k]) for k in left), why))
    return tuple(out)
