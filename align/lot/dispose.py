"""Each unit of a lot judged against a tolerance (:mod:`align.decision`): the lot's own flags
when given, else the disposition the unit's session result carries (its session.toml's
``[tolerance]``), else NO TOLERANCE."""

from __future__ import annotations

from collections.abc import Sequence

from align.decision import (
    DEFAULT_K,
    DEFAULT_RULE,
    NO_TOLERANCE,
    Disposition,
    ToleranceSpec,
    decide_values,
)
from align.errors import InputError
from align.lot.read import UnitResult


def unit_disposition(unit: UnitResult, spec: ToleranceSpec | None) -> Disposition:
    """One unit's disposition: judged anew against ``spec`` (the lot's flags), or the one
    its result carries when ``spec`` is None."""
    if spec is None and unit.disposition is not None:
        try:
            return Disposition.from_dict(unit.disposition)
        except (KeyError, TypeError, ValueError, InputError) as exc:  # an edited or odd file
            return Disposition(NO_TOLERANCE, DEFAULT_RULE, DEFAULT_K,
                               f"{unit.file}: its disposition cannot be read ({exc!r}); "
                               "give the lot a tolerance to judge it")
    return decide_values(unit.ok and unit.fused, unit.e_rad, unit.u_rad, unit.covariance,
                         spec, unit.failed_stages)


def dispositions(units: Sequence[UnitResult], spec: ToleranceSpec | None) -> list[dict]:
    """The lot JSON's ``dispositions``: per unit (in the lot's order) its label, session and
    file with :meth:`Disposition.to_dict`."""
    return [{"unit": u.label, "session": u.session, "file": u.file,
             **unit_disposition(u, spec).to_dict()} for u in units]
