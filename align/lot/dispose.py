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
    judge_result,
    resolve,
)
from align.errors import InputError
from align.fusion.undetermined import Undetermined
from align.lot.read import UnitResult


def own_spec(unit: UnitResult) -> ToleranceSpec | None:
    """The tolerance a unit's session judged it against (its session.toml's ``[tolerance]``,
    as its stored disposition records it — ``limits``, kept whatever the verdict; a result
    written before them: its judged angles' — relative to each nominal, nominals, rule, k),
    or None when the result carries no disposition."""
    d = unit.disposition
    if not isinstance(d, Mapping) or "rule" not in d:
        return None
    own = Disposition.from_dict(d)
    limits = {n: (lo - nom, hi - nom) for n, nom, lo, hi in own.limits}
    nominal = {n: nom for n, nom, _, _ in own.limits}
    return ToleranceSpec(limits, nominal, own.rule, own.k,
                         f"{unit.file} (its session's [tolerance])")


def unit_disposition(unit: UnitResult, spec: ToleranceSpec | None,
                     flags: Mapping | None = None) -> Disposition:
    """One unit's disposition: the one its result carries when the lot was given no decision
    flags; else judged anew, with the lot's ``flags`` (:func:`align.decision.resolve`'s
    keywords) applied over the unit's own tolerance as ``align run`` applies them over
    session.toml's (a tolerance flag replaces the limits, the nominals stay; a rule or k
    alone keeps the limits) — ``spec`` (the flags alone) when the unit carries none — and
    the unit judged as 'align run' would have judged it with that tolerance
    (:func:`align.decision.judge_result`)."""
    if not flags and unit.disposition is not None:
        try:
            return Disposition.from_dict(unit.disposition)
        except (KeyError, TypeError, ValueError, InputError) as exc:  # an edited or odd file
            return Disposition(NO_TOLERANCE, DEFAULT_RULE, DEFAULT_K,
                               f"{unit.file}: its disposition cannot be read ({exc!r}); "
                               "give the lot a tolerance to judge it")
    try:
        carried = [Undetermined.from_dict(c) for c in unit.undetermined]
        own = own_spec(unit) if flags else None
    except (KeyError, TypeError, ValueError, InputError) as exc:  # an edited or odd file
        raise InputError(f"{unit.file}: its disposition or undetermined terms cannot be read "
                         f"({exc!r})") from None
    if own is not None:
        spec = resolve(own, **flags)
    # As 'align run' judges with that spec: an angle the unit's own tolerance left undecided
    # is found anew for this one, from the nuisances its result carries.
    return judge_result(unit.e_rad if unit.fused else None, unit.u_rad, unit.covariance, spec,
                        unit.failed_stages, unit.problems, carried, unit.ok)


def dispositions(units: Sequence[UnitResult], spec: ToleranceSpec | None,
                 flags: Mapping | None = None) -> list[dict]:
    """The lot JSON's ``dispositions``: per unit (in the lot's order) its label, session and
    file with :meth:`Disposition.to_dict` (see :func:`unit_disposition`)."""
    return [{"unit": u.label, "session": u.session, "file": u.file,
             **unit_disposition(u, spec, flags).to_dict()} for u in units]
