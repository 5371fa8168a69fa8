"""Conformity decision of a measured misalignment against its tolerance (ISO 14253-1, ILAC-G8).

Each angle E_ij has a tolerance zone [n + lo, n + hi] (n its nominal, lo < hi relative to it)
and a measured value v with standard uncertainty u. Two decision rules:

* **simple** (ILAC-G8 "simple acceptance", w = 0): an angle PASSes when v lies in the
  tolerance zone, else it FAILs;
* **guarded** (ISO 14253-1, guard band w = k·u): the acceptance zone is the tolerance zone
  narrowed by w at both ends, the rejection zone the tolerance zone widened by w. An angle
  PASSes inside the acceptance zone, FAILs beyond the rejection limit (outside the tolerance by
  more than w), and is INCONCLUSIVE in between.

A unit PASSes when every toleranced angle passes, FAILs when any angle fails, and is
INCONCLUSIVE otherwise. A session whose stages failed, or whose fusion did not run or was
refused (a gross disagreement between instruments), is NOT MEASURED: its numbers are not a
measurement and get no verdict. Without any tolerance the verdict is NO TOLERANCE.

The probability of conformance of an angle (JCGM 106:2012, eq. 9, Gaussian knowledge of the
measurand) is p = Φ((n + hi − v)/u) − Φ((n + lo − v)/u), Φ the standard normal CDF; the
unit's joint probability uses the 6×6 covariance of E (multivariate normal over the box).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align import problem_codes as pc
from align.errors import InputError
from align.fusion.observations import E_INDEX, E_NAMES
from align.fusion.undetermined import Undetermined
from axisbase.covariance import cov_of
from axisbase.units import ARCSEC

FORMAT_VERSION = 1
RULES = ("simple", "guarded")
DEFAULT_RULE = "guarded"
DEFAULT_K = 2.0
"""Guard-band factor of the guarded rule: w = k·u (k = 2: ~95 % one-sided confidence that an
accepted angle conforms, ILAC-G8 §4.2.2)."""
MAX_K = 10.0
PASS, FAIL, INCONCLUSIVE = "PASS", "FAIL", "INCONCLUSIVE"
NOT_MEASURED, NO_TOLERANCE = "NOT MEASURED", "NO TOLERANCE"
VERDICTS = (PASS, FAIL, INCONCLUSIVE, NOT_MEASURED, NO_TOLERANCE)
MAX_TOLERANCE_ARCSEC = 36000.0
"""The widest tolerance limit accepted [″] (10°): beyond it the small-angle model of E does
not hold, and a larger number is a typing error."""


def _finite(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where} = {value!r}: expected a number")
    v = float(value)
    if not math.isfinite(v) or abs(v) > MAX_TOLERANCE_ARCSEC:
        raise InputError(f"{where} = {value!r}: not a number within ±{MAX_TOLERANCE_ARCSEC:g}″")
    return v


def limits_arcsec(value: object, where: str, text: bool = False) -> tuple[float, float]:
    """A tolerance as given [″]: a positive number T (the zone ±T) or [lower, upper] with
    lower < upper, both relative to the nominal, or (the command line's form) the text "T"
    or "LO,HI" when ``text``. ``where`` names the key or flag in errors."""
    if isinstance(value, str) and text:
        parts = [p.strip() for p in value.split(",")]
        try:
            value = [float(p) for p in parts] if len(parts) > 1 else float(parts[0])
        except ValueError:
            raise InputError(f"{where} = {value!r}: expected T or LO,HI in arc-seconds"
                             ) from None
    if isinstance(value, list | tuple):
        if len(value) != 2:
            raise InputError(f"{where} = {list(value)!r}: expected [lower, upper] in ″")
        lo, hi = (_finite(v, where) for v in value)
        if not lo < hi:
            raise InputError(f"{where} = {list(value)!r}: need lower < upper")
        return lo, hi
    t = _finite(value, where)
    if t <= 0:
        raise InputError(f"{where} = {value!r}: a symmetric tolerance must be > 0")
    return -t, t


@dataclass(frozen=True)
class ToleranceSpec:
    """The specification of E: per angle name, the limits (lower, upper) [rad] relative to
    its nominal [rad] (angles without an entry are not toleranced); the decision rule and the
    guard-band factor k [-]. ``source`` says where it came from (for the reason line)."""

    limits: Mapping[str, tuple[float, float]]
    nominal: Mapping[str, float] = field(default_factory=dict)
    rule: str = DEFAULT_RULE
    k: float = DEFAULT_K
    source: str = "session.toml [tolerance]"

    @classmethod
    def from_table(cls, t: Mapping, where: str) -> ToleranceSpec:
        """From ``[tolerance]`` of session.toml (keys ``arcsec``, ``E_xY``…, ``nominal_arcsec``,
        ``decision``, ``k``); errors name ``where`` and the key."""
        known = {"arcsec", "nominal_arcsec", "decision", "k", *E_NAMES}
        unknown = set(t) - known
        if unknown:
            raise InputError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; known: "
                             f"{', '.join(sorted(known))}")
        limits: dict[str, tuple[float, float]] = {}
        if "arcsec" in t:
            lo, hi = limits_arcsec(t["arcsec"], f"{where} arcsec")
            limits = dict.fromkeys(E_NAMES, (lo * ARCSEC, hi * ARCSEC))
        for n in E_NAMES:
            if n in t:
                lo, hi = limits_arcsec(t[n], f"{where} {n}")
                limits[n] = (lo * ARCSEC, hi * ARCSEC)
        nom = t.get("nominal_arcsec", {})
        if not isinstance(nom, dict):
            raise InputError(f"{where} nominal_arcsec: expected a table {{ E_xY = 10.0, ... }}")
        bad = set(nom) - set(E_NAMES)
        if bad:
            raise InputError(f"{where} nominal_arcsec: unknown angle(s) "
                             f"{', '.join(sorted(bad))}; known: {', '.join(E_NAMES)}")
        nominal = {n: _finite(v, f"{where} nominal_arcsec.{n}") * ARCSEC
                   for n, v in nom.items()}
        rule = t.get("decision", DEFAULT_RULE)
        if rule not in RULES:
            raise InputError(f"{where} decision = {rule!r}: one of {', '.join(RULES)}")
        k = check_k(t.get("k", DEFAULT_K), f"{where} k")
        return cls(limits, nominal, rule, k, where)

    def override(self, limits_arcsec_: tuple[float, float] | None = None,
                 rule: str | None = None, k: float | None = None) -> ToleranceSpec:
        """This spec with the command line's flags applied (a tolerance flag replaces every
        angle's limits; the nominals stay)."""
        lim = (dict.fromkeys(E_NAMES, (limits_arcsec_[0] * ARCSEC, limits_arcsec_[1] * ARCSEC))
               if limits_arcsec_ is not None else self.limits)
        src = "--tolerance-arcsec" if limits_arcsec_ is not None else self.source
        return ToleranceSpec(lim, self.nominal, rule or self.rule,
                             self.k if k is None else k, src)


def check_k(value: object, where: str) -> float:
    """The guard-band factor k: a number in [0, MAX_K]."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
            math.isfinite(value) and 0 <= value <= MAX_K):
        raise InputError(f"{where} = {value!r}: expected a number in [0, {MAX_K:g}]")
    return float(value)


def resolve(spec: ToleranceSpec | None, tolerance: tuple[float, float] | None = None,
            rule: str | None = None, k: float | None = None) -> ToleranceSpec | None:
    """The spec in force: session.toml's ``spec`` (or none) with the command line's flags
    (``tolerance`` [″] (lower, upper), ``rule``, ``k``) applied. Without limits from either,
    a spec that only carries the rule (NO TOLERANCE)."""
    if spec is None:
        if tolerance is None and rule is None and k is None:
            return None
        spec = ToleranceSpec({}, source="the command line")
    return spec.override(tolerance, rule, k)


@dataclass(frozen=True)
class AngleDisposition:
    """One toleranced angle.

    Attributes
    ----------
    name : str
        The angle (``E_xY``, ...); unit —.
    value : float
        Its value v [rad].
    u : float
        Its standard uncertainty [rad].
    nominal : float
        The nominal n [rad].
    lower, upper : float
        The absolute tolerance limits n + lo, n + hi [rad].
    guard : float
        The guard band w [rad] (k·u; 0 for the simple rule).
    margin : float
        Distance to the nearest tolerance limit [rad], positive inside.
    p_conform : float
        Probability that the angle lies within its limits — dimensionless.
    verdict : str
        PASS / FAIL / INCONCLUSIVE; unit —.
    """

    name: str
    value: float
    u: float
    nominal: float
    lower: float
    upper: float
    guard: float
    margin: float
    p_conform: float
    verdict: str

    def to_dict(self) -> dict:
        a = ARCSEC
        return {"name": self.name, "value_arcsec": self.value / a, "u_arcsec": self.u / a,
                "nominal_arcsec": self.nominal / a, "lower_arcsec": self.lower / a,
                "upper_arcsec": self.upper / a, "guard_arcsec": self.guard / a,
                "margin_arcsec": self.margin / a, "p_conform": self.p_conform,
                "verdict": self.verdict}

    @classmethod
    def from_dict(cls, d: Mapping) -> AngleDisposition:
        a = ARCSEC
        return cls(str(d["name"]), *(float(d[k]) * a for k in (
            "value_arcsec", "u_arcsec", "nominal_arcsec", "lower_arcsec", "upper_arcsec",
            "guard_arcsec", "margin_arcsec")), float(d["p_conform"]), str(d["verdict"]))


@dataclass(frozen=True)
class Disposition:
    """The unit's verdict and why.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`; unit —.
    rule : str
        ``simple`` or ``guarded``; unit —.
    k : float
        The guard band's coverage factor — dimensionless.
    reason : str
        One line saying why; unit —.
    worst : str or None
        On a FAIL the most clearly failing angle (furthest beyond its rejection limit:
        smallest margin + guard band), else the angle nearest to (or furthest beyond) its
        acceptance limit (smallest margin − guard band); None without a verdict on numbers;
        unit —.
    angles : tuple of AngleDisposition
        Each toleranced angle; unit — (their fields carry units).
    p_conform_all : float or None
        The probability that every toleranced angle conforms at once (from the 6×6
        covariance; None without a verdict on numbers) — dimensionless.
    limits : tuple of (str, float, float, float)
        The tolerance judged against, whatever the verdict: per toleranced angle (name,
        nominal, lower, upper) [rad], the limits absolute (what ``align lot`` re-judges a
        NOT MEASURED unit with; empty without a tolerance).
    """

    verdict: str
    rule: str
    k: float
    reason: str
    worst: str | None = None
    angles: tuple[AngleDisposition, ...] = ()
    p_conform_all: float | None = None
    limits: tuple[tuple[str, float, float, float], ...] = ()

    def to_dict(self) -> dict:
        a = ARCSEC
        return {"format_version": FORMAT_VERSION, "verdict": self.verdict, "rule": self.rule,
                "k": self.k, "reason": self.reason, "worst": self.worst,
                "p_conform_all": self.p_conform_all,
                "angles": [x.to_dict() for x in self.angles],
                "limits": [{"name": n, "nominal_arcsec": nom / a, "lower_arcsec": lo / a,
                            "upper_arcsec": hi / a} for n, nom, lo, hi in self.limits]}

    @classmethod
    def from_dict(cls, d: Mapping) -> Disposition:
        v = int(d.get("format_version", FORMAT_VERSION))
        if v > FORMAT_VERSION:
            raise InputError(f"disposition format_version {v}: newer than this tool reads "
                             f"({FORMAT_VERSION})")
        if d["verdict"] not in VERDICTS:
            raise InputError(f"disposition verdict {d['verdict']!r}: not one of {VERDICTS}")
        pa = d.get("p_conform_all")
        a = ARCSEC
        # (written before 'limits': the judged angles' own, all a verdict on numbers has)
        lim = d.get("limits", d["angles"])
        return cls(str(d["verdict"]), str(d["rule"]), float(d["k"]), str(d["reason"]),
                   d.get("worst"), tuple(AngleDisposition.from_dict(x) for x in d["angles"]),
                   None if pa is None else float(pa),
                   tuple((str(x["name"]), *(float(x[k]) * a for k in (
                       "nominal_arcsec", "lower_arcsec", "upper_arcsec"))) for x in lim))

    def line(self) -> str:
        """The terminal's verdict line."""
        return f"VERDICT: {self.verdict} ({self.rule} rule{self._k()}): {self.reason}"

    def _k(self) -> str:
        return f", k = {self.k:g}" if self.rule == "guarded" else ""


def p_conform(value: float, u: float, lower: float, upper: float) -> float:
    """Probability that the angle lies in [lower, upper] given value and u (Gaussian); with
    u = 0, 1 inside and 0 outside."""
    if u <= 0:
        return float(lower <= value <= upper)
    return float(special.ndtr((upper - value) / u) - special.ndtr((lower - value) / u))


def judge_angle(name: str, value: float, u: float, nominal: float, lo: float, hi: float,
                rule: str, k: float) -> AngleDisposition:
    """One angle's verdict under ``rule`` (all angles [rad]; lo, hi relative to nominal)."""
    lower, upper = nominal + lo, nominal + hi
    w = k * u if rule == "guarded" else 0.0
    margin = min(value - lower, upper - value)
    if margin >= w and (rule == "simple" or upper - lower > 2 * w):
        verdict = PASS
    elif margin < -w:
        verdict = FAIL
    else:
        verdict = INCONCLUSIVE
    return AngleDisposition(name, value, u, nominal, lower, upper, w, margin,
                            p_conform(value, u, lower, upper), verdict)


UNDECIDED_SHARE = 0.5
"""An angle is not measured when a nuisance the data cannot determine sets more than this
share of its u² and the angle is INCONCLUSIVE (:func:`undecided`)."""


def undecided(e6: Sequence[float], u6: Sequence[float], carried: Sequence[Undetermined],
              spec: ToleranceSpec) -> list[tuple[str, str]]:
    """The toleranced angles a result cannot decide (issue 18): INCONCLUSIVE, with more than
    :data:`UNDECIDED_SHARE` of their u² set by a nuisance the data cannot determine
    (``carried``: the fusion's :class:`~align.fusion.undetermined.Undetermined`, carried over
    its plausible range) — the result is then not a measurement of them. Each as (angle,
    the result's problem line, saying what to measure); ``e6``, ``u6`` [rad] in ``E_NAMES``
    order."""
    out = []
    for m, n in enumerate(E_NAMES):
        if n not in spec.limits:
            continue
        lo, hi = spec.limits[n]
        a = judge_angle(n, float(e6[m]), float(u6[m]), spec.nominal.get(n, 0.0), lo, hi,
                        spec.rule, spec.k)
        if a.verdict != INCONCLUSIVE:
            continue
        for c in carried:
            if c.shift[m] ** 2 > UNDECIDED_SHARE * a.u**2:
                src = "as declared" if c.declared else "the default range"
                out.append((n, f"fusion: {n}'s tolerance cannot be decided: its u "
                               f"{a.u / ARCSEC:.1f}″ is set by {c.name}, which these data "
                               f"cannot determine (carried over its plausible range, σ "
                               f"{c.sigma / ARCSEC:.1f}″, {src}): measure {c.measure}"))
    return out


def _joint_p(angles: Sequence[AngleDisposition], cov: np.ndarray | None) -> float | None:
    """P(every angle within its limits) under N(E, cov) (the marginals' product when the
    covariance is not at hand)."""
    if cov is None:
        return float(np.prod([a.p_conform for a in angles]))
    C = cov_of(np.asarray(cov, float), E_NAMES, [a.name for a in angles])
    if np.any(np.diag(C) <= 0):
        return float(np.prod([a.p_conform for a in angles]))
    mean = np.array([a.value for a in angles])
    s = np.sqrt(np.diag(C))
    # Standardised (the CDF's absolute tolerance is then relative to the uncertainties).
    corr = C / np.outer(s, s)
    lo = np.array([(a.lower - a.value) / si for a, si in zip(angles, s, strict=True)])
    hi = np.array([(a.upper - a.value) / si for a, si in zip(angles, s, strict=True)])
    if len(angles) == 1:
        return angles[0].p_conform
    # Genz's quasi-Monte Carlo integration: seeded, so the same result gives the same JSON.
    # (scipy.stats imported here, the one place it is needed: ~0.8 s of CPU per process.)
    from scipy import stats

    mvn = stats.multivariate_normal(mean=np.zeros(len(mean)), cov=corr, allow_singular=True,
                                    seed=0)
    return float(np.clip(mvn.cdf(hi, lower_limit=lo), 0.0, 1.0))


def decide(result: Mapping, spec: ToleranceSpec | None) -> Disposition:
    """The disposition of a session result (the JSON of 'align run', or its
    :meth:`SessionResult.to_dict`) against ``spec`` (None: no tolerance given).

    NOT MEASURED when the result is not ok (a stage failed, the fusion did not run or was
    refused, a problem) — before any look at the numbers; a problem is read by its code
    (``problem_codes``; a result without them: every problem :data:`~align.problem_codes.UNKNOWN`),
    never by its text (:func:`judge_result`)."""
    fused = bool(result.get("fused")) and "misalignment_rad" in result
    e6 = u6 = None
    if fused:
        E = np.asarray(result["misalignment_rad"], float)
        U = np.asarray(result["misalignment_u_rad"], float)
        e6 = [float(E[i, j]) for i, j in E_INDEX]
        u6 = [float(U[i, j]) for i, j in E_INDEX]
    errs = [(str(e.get("stage", "?")), str(e.get("message", "")))
            for e in result.get("errors") or []]
    problems = [str(p) for p in result.get("problems") or []]
    codes = pc.codes_of(problems, result.get("problem_codes"))
    carried = [Undetermined.from_dict(c) for c in result.get("undetermined") or ()]
    return judge_result(e6, u6, result.get("covariance_rad2"), spec, errs,
                        tuple(zip(codes, problems, strict=True)), carried,
                        bool(result.get("ok")))


def judge_result(e6: Sequence[float] | None, u6: Sequence[float] | None,
                 cov: Sequence | np.ndarray | None, spec: ToleranceSpec | None,
                 errors: Sequence[tuple[str, str]] = (),
                 problems: Sequence[tuple[str, str]] = (),
                 carried: Sequence[Undetermined] = (), said_ok: bool = True) -> Disposition:
    """A session result judged against ``spec`` as 'align run' judges it with that spec:
    the six angles, their u [rad] (None when not fused) and covariance [rad²]; the failed
    stages (stage, message); the result's problems (code, text); the nuisances it carries
    undetermined (:class:`~align.fusion.undetermined.Undetermined`).

    A problem whose code depends on the tolerance
    (:data:`~align.problem_codes.TOLERANCE_DEPENDENT`: an angle left undecided) is set aside
    and the undecided angles found anew for ``spec`` (:func:`undecided`); any other problem,
    or a failed stage, makes the result NOT MEASURED. So ``align lot`` with its own tolerance
    judges a unit as 'align run' would have with that tolerance. ``said_ok``: the result's
    own ``ok``; false with neither a failed stage nor a problem (an edited file) is a problem
    of unknown code."""
    if not said_ok and not errors and not problems:
        problems = ((pc.UNKNOWN, "the result says ok: false"),)
    ok = (e6 is not None and u6 is not None and not errors
          and all(code in pc.TOLERANCE_DEPENDENT for code, _ in problems))
    unmeasured = (undecided(e6, u6, carried, spec)
                  if ok and spec is not None and carried else [])
    errs = [*errors, *(("not ok", text) for _, text in problems)]
    return decide_values(ok, e6, u6, cov, spec, errs, unmeasured)


def decide_values(ok: bool, e6: Sequence[float] | None, u6: Sequence[float] | None,
                  cov: Sequence | np.ndarray | None, spec: ToleranceSpec | None,
                  errors: Sequence[tuple[str, str]] = (),
                  unmeasured: Sequence[tuple[str, str]] = ()) -> Disposition:
    """:func:`decide` from the parts: ``ok`` (every stage succeeded and fused), the six angles
    and their u [rad] in ``E_NAMES`` order (None when not fused), their covariance [rad²]
    (or None), the spec, and the failed stages (stage, message) for the reason.
    ``unmeasured``: the angles the result cannot decide (:func:`undecided`: (angle, the
    result's problem line)), ``ok`` then saying the result is ok but for them: the unit FAILs
    when another angle fails beyond its guard band (its own u, every carried term in it), and
    is NOT MEASURED otherwise — never PASS nor INCONCLUSIVE on a result that is not ok."""
    rule = spec.rule if spec is not None else DEFAULT_RULE
    k = spec.k if spec is not None else DEFAULT_K
    limits = spec_limits(spec)
    if not ok or e6 is None or u6 is None:
        why = ("; ".join(f"{st}: {msg}" for st, msg in errors[:2])
               if errors else "the fusion did not run")
        return Disposition(NOT_MEASURED, rule, k, f"no verdict on a result that is not ok ({why})",
                           limits=limits)
    if spec is None or not spec.limits:
        return Disposition(NO_TOLERANCE, rule, k,
                           "no tolerance given ([tolerance] in session.toml or "
                           "--tolerance-arcsec)")
    angles = []
    for m, n in enumerate(E_NAMES):
        if n in spec.limits:
            lo, hi = spec.limits[n]
            angles.append(judge_angle(n, float(e6[m]), float(u6[m]), spec.nominal.get(n, 0.0),
                                      lo, hi, rule, k))
    verdicts = {a.verdict for a in angles}
    verdict = FAIL if FAIL in verdicts else PASS if verdicts == {PASS} else INCONCLUSIVE
    if unmeasured and verdict != FAIL:  # an angle not measured: only a FAIL is a verdict
        why = "; ".join(f"not ok: {msg}" for _, msg in unmeasured[:2])
        return Disposition(NOT_MEASURED, rule, k, f"no verdict on a result that is not ok ({why})",
                           limits=limits)
    worst = worst_angle(angles)
    reason = _reason(verdict, worst, len(angles), spec)
    if unmeasured:
        names = ", ".join(dict.fromkeys(n for n, _ in unmeasured))
        reason += (f"; not measured: {names} (the result is not ok: "
                   f"{unmeasured[0][1].removeprefix('fusion: ')})")
    return Disposition(verdict, rule, k, reason, worst.name, tuple(angles),
                       _joint_p(angles, None if cov is None else np.asarray(cov, float)), limits)


def spec_limits(spec: ToleranceSpec | None) -> tuple[tuple[str, float, float, float], ...]:
    """``spec``'s limits as :attr:`Disposition.limits` (name, nominal, lower, upper) [rad],
    the limits absolute, in ``E_NAMES`` order."""
    if spec is None:
        return ()
    return tuple((n, spec.nominal.get(n, 0.0), spec.nominal.get(n, 0.0) + spec.limits[n][0],
                  spec.nominal.get(n, 0.0) + spec.limits[n][1])
                 for n in E_NAMES if n in spec.limits)


def worst_angle(angles: Sequence[AngleDisposition]) -> AngleDisposition:
    """The angle the unit's verdict names: of the failing angles the most clearly failing
    (furthest beyond its rejection limit: smallest m + w), else the one nearest to (or
    furthest beyond) its acceptance limit (smallest m − w). (An angle failing by a little
    with a small u is the FAIL; a larger miss whose guard band is wider is INCONCLUSIVE,
    and names no FAIL.)"""
    fails = [a for a in angles if a.verdict == FAIL]
    if fails:
        return min(fails, key=lambda a: a.margin + a.guard)
    return min(angles, key=lambda a: a.margin - a.guard)


def _reason(verdict: str, worst: AngleDisposition, n: int, spec: ToleranceSpec) -> str:
    a = ARCSEC
    zone = f"[{worst.lower / a:+.1f}, {worst.upper / a:+.1f}]″"
    val = f"{worst.name} = {worst.value / a:+.2f} ± {worst.u / a:.2f}″"
    if verdict == PASS:
        tail = (f"closest: {val}, {worst.margin / a:.1f}″ inside {zone}"
                + (f" (guard band {worst.guard / a:.1f}″)" if spec.rule == "guarded" else ""))
        return f"all {n} toleranced angles inside the acceptance zone; {tail}"
    if verdict == FAIL:
        return (f"{val} is {-worst.margin / a:.1f}″ outside its tolerance {zone}"
                + (f", beyond the guard band {worst.guard / a:.1f}″"
                   if spec.rule == "guarded" else ""))
    if worst.upper - worst.lower <= 2 * worst.guard:
        return (f"{val}: the guard bands 2 × {worst.guard / a:.1f}″ cover the whole tolerance "
                f"{zone}: u too large to accept (see 'align plan')")
    return (f"{val} lies within the guard band {worst.guard / a:.1f}″ of its limit {zone} "
            f"(margin {worst.margin / a:+.1f}″): lower u to decide (see 'align plan')")
