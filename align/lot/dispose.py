"""Each unit of a lot judged against a tolerance (:mod:`align.decision`): the lot's own flags
when given, else the disposition the unit's session result carries (its session.toml's
``[tolerance]``), else NO TOLERANCE."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from align.decision import (
    DEFAULT_K,
    DEFAULT_RULE,
    NO_TOLERANCE,
    Disposition,
    ToleranceSpec,
    decide_values,
    resolve,
)
from align.errors import InputError
from align.lot.read import UnitResult
from axisbase.units import ARCSEC


def own_spec(unit: UnitResult) -> ToleranceSpec | None:
    """The tolerance a unit's session judged it against (its session.toml's ``[tolerance]``,
    as its stored disposition records it: limits relative to each nominal, nominals, rule,
    k), or None when the result carries no disposition."""
    d = unit.disposition
    if not isinstance(d, Mapping) or "rule" not in d:
        return None
    limits, nominal = {}, {}
    for a in d.get("angles") or []:
        n = a["name"]
        nominal[n] = float(a["nominal_arcsec"]) * ARCSEC
        limits[n] = ((float(a["lower_arcsec"]) - float(a["nominal_arcsec"])) * ARCSEC,
                     (float(a["upper_arcsec"]) - float(a["nominal_arcsec"])) * ARCSEC)
    return ToleranceSpec(limits, nominal, str(d["rule"]), float(d.get("k", DEFAULT_K)),
                         f"{unit.file} (its session's [tolerance])")


def unit_disposition(unit: UnitResult, spec: ToleranceSpec | None,
                     flags: Mapping | None = None) -> Disposition:
    """One unit's disposition: the one its result carries when the lot was given no decision
    flags; else judged anew, with the lot's ``flags`` (:func:`align.decision.resolve`'s
    keywords) applied over the unit's own tolerance as ``align run`` applies them over
    session.toml's (a tolerance flag replaces the limits, the nominals stay; a rule or k
    alone keeps the limits) — ``spec`` (the flags alone) when the unit carries none."""
    if not flags and unit.disposition is not None:
        try:
            return Disposition.from_dict(unit.disposition)
        except (KeyError, TypeError, ValueError, InputError) as exc:  # an edited or odd file
            return Disposition(NO_TOLERANCE, DEFAULT_RULE, DEFAULT_K,
                               f"{unit.file}: its disposition cannot be read ({exc!r}); "
                               "give the lot a tolerance to judge it")
    if flags:
        try:
            own = own_spec(unit)
        except (KeyError, TypeError, ValueError) as exc:  # an edited or odd file
            raise InputError(f"{unit.file}: its disposition cannot be read ({exc!r})") from None
        if own is not None:
            spec = resolve(own, **flags)
    return decide_values(unit.ok and unit.fused, unit.e_rad, unit.u_rad, unit.covariance,
                         spec, unit.failed_stages)


def dispositions(units: Sequence[UnitResult], spec: ToleranceSpec | None,
                 flags: Mapping | None = None) -> list[dict]:
    """The lot JSON's ``dispositions``: per unit (in the lot's order) its label, session and
    file with :meth:`Disposition.to_dict` (see :func:`unit_disposition`)."""
    return [{"unit": u.label, "session": u.session, "file": u.file,
             **unit_disposition(u, spec, flags).to_dict()} for u in units]
