"""Decision rules (ISO 14253-1 / ILAC-G8) on constructed cases at the zone edges."""

import numpy as np
import pytest
from scipy import stats

from align.decision import (
    FAIL,
    INCONCLUSIVE,
    NO_TOLERANCE,
    NOT_MEASURED,
    PASS,
    Disposition,
    ToleranceSpec,
    decide,
    judge_angle,
    limits_arcsec,
    resolve,
)
from align.errors import InputError
from align.fusion import E_INDEX, E_NAMES
from axisbase.units import ARCSEC

A = ARCSEC


def _result(e_arcsec, u_arcsec, ok=True, fused=True, errors=()):
    E, U = np.zeros((3, 3)), np.zeros((3, 3))
    for (i, j), v, u in zip(E_INDEX, e_arcsec, u_arcsec, strict=True):
        E[i, j], U[i, j] = v * A, u * A
    d = {"ok": ok, "fused": fused, "errors": [{"stage": s, "message": m} for s, m in errors]}
    if fused:
        d.update(misalignment_rad=E.tolist(), misalignment_u_rad=U.tolist(),
                 covariance_rad2=np.diag([(u * A) ** 2 for u in u_arcsec]).tolist())
    return d


def _spec(lo=-60.0, hi=60.0, rule="guarded", k=2.0, nominal=None, only=None):
    lim = {n: (lo * A, hi * A) for n in (only or E_NAMES)}
    return ToleranceSpec(lim, {n: v * A for n, v in (nominal or {}).items()}, rule, k)


U5 = [5.0] * 6


@pytest.mark.parametrize(("value", "rule", "expected"), [
    (49.999, "guarded", PASS),       # margin 10.001 ≥ w = 10: inside the acceptance zone
    (50.001, "guarded", INCONCLUSIVE),
    (60.0, "guarded", INCONCLUSIVE),  # on the tolerance limit
    (69.999, "guarded", INCONCLUSIVE),
    (70.001, "guarded", FAIL),       # outside the tolerance by more than w
    (-70.001, "guarded", FAIL),
    (-49.999, "guarded", PASS),
    (59.999, "simple", PASS),
    (60.0, "simple", PASS),          # the limit belongs to the zone
    (60.001, "simple", FAIL),
    (-60.001, "simple", FAIL),
])
def test_one_angle_at_the_zone_edges(value, rule, expected):
    e = [0.0, value, 0.0, 0.0, 0.0, 0.0]
    d = decide(_result(e, U5), _spec(rule=rule))
    assert d.verdict == expected, d.reason
    assert d.worst == "E_xZ"
    a = {x.name: x for x in d.angles}["E_xZ"]
    assert a.margin / A == pytest.approx(60 - abs(value), abs=1e-9)
    assert a.guard / A == pytest.approx(10.0 if rule == "guarded" else 0.0)


def test_unit_verdict_fail_dominates_inconclusive_dominates_pass():
    d = decide(_result([0, 55, -75, 0, 0, 0], U5), _spec())
    assert d.verdict == FAIL and d.worst == "E_yX"
    assert {a.name: a.verdict for a in d.angles}["E_xZ"] == INCONCLUSIVE
    d = decide(_result([0, 55, -45, 0, 0, 0], U5), _spec())
    assert d.verdict == INCONCLUSIVE and d.worst == "E_xZ"


def test_asymmetric_tolerance_and_nonzero_nominal():
    # Zone for E_xZ: nominal 20 + [-30, 90] = [-10, 110]″; guard 2·5 = 10″.
    spec = ToleranceSpec({"E_xZ": (-30 * A, 90 * A)}, {"E_xZ": 20 * A}, "guarded", 2.0)
    cases = {0.5: PASS, -0.5: INCONCLUSIVE, 99.5: PASS, 100.5: INCONCLUSIVE,
             -20.5: FAIL, -19.5: INCONCLUSIVE, 120.5: FAIL}
    for v, verdict in cases.items():
        d = decide(_result([300, v, 300, 300, 300, 300], U5), spec)  # others not toleranced
        assert d.verdict == verdict, (v, d.reason)
        (a,) = d.angles
        assert (a.lower / A, a.upper / A) == pytest.approx((-10, 110))
        assert a.margin / A == pytest.approx(min(v + 10, 110 - v))


def test_guard_bands_covering_the_zone_never_pass():
    d = decide(_result([0.0] * 6, [40.0] * 6), _spec(-60, 60))  # 2·80 > 120
    assert d.verdict == INCONCLUSIVE and "cover the whole tolerance" in d.reason
    assert decide(_result([0.0] * 6, [40.0] * 6), _spec(rule="simple")).verdict == PASS


def test_p_conform_is_the_gaussian_probability_in_the_zone():
    a = judge_angle("E_xY", 50 * A, 5 * A, 0.0, -60 * A, 60 * A, "guarded", 2.0)
    assert a.p_conform == pytest.approx(stats.norm.cdf(2) - stats.norm.cdf(-22))
    # at the limit: one half
    a = judge_angle("E_xY", 60 * A, 5 * A, 0.0, -60 * A, 60 * A, "simple", 2.0)
    assert a.p_conform == pytest.approx(0.5, abs=1e-12)
    # joint: independent angles multiply
    d = decide(_result([50, 50, 0, 0, 0, 0], U5), _spec())
    ps = [x.p_conform for x in d.angles]
    assert d.p_conform_all == pytest.approx(np.prod(ps), rel=1e-3)


def test_failed_session_is_not_measured_whatever_its_numbers():
    r = _result([0.0] * 6, U5, ok=False, errors=[("marks", "x_A.png: no mark found")])
    d = decide(r, _spec())
    assert d.verdict == NOT_MEASURED and not d.angles and d.worst is None
    assert "x_A.png" in d.reason
    assert decide(_result([0] * 6, U5, ok=False, fused=False), _spec()).verdict == NOT_MEASURED
    assert decide(_result([0.0] * 6, U5), None).verdict == NO_TOLERANCE
    assert decide(_result([0.0] * 6, U5), resolve(None, rule="simple")).verdict == NO_TOLERANCE


def test_round_trip_and_overrides():
    d = decide(_result([0, 55, -75, 0, 0, 0], U5), _spec())
    assert Disposition.from_dict(d.to_dict()) == d
    spec = ToleranceSpec.from_table({"arcsec": 60, "E_xZ": [-30, 90],
                                     "nominal_arcsec": {"E_xY": 10.0}, "decision": "simple",
                                     "k": 3}, "session.toml: [tolerance]")
    assert spec.limits["E_xZ"] == pytest.approx((-30 * A, 90 * A))
    assert spec.limits["E_yX"] == pytest.approx((-60 * A, 60 * A))
    o = resolve(spec, tolerance=(-5.0, 5.0), k=1.0)
    assert o.rule == "simple" and o.k == 1.0 and o.nominal["E_xY"] == pytest.approx(10 * A)
    assert all(v == pytest.approx((-5 * A, 5 * A)) for v in o.limits.values())


@pytest.mark.parametrize(("table", "says"), [
    ({"arcsec": -5}, "arcsec = -5: a symmetric tolerance must be > 0"),
    ({"E_xZ": [90, -30]}, "E_xZ = [90, -30]: need lower < upper"),
    ({"E_xq": 5}, "unknown key(s) E_xq"),
    ({"decision": "strict"}, "decision = 'strict'"),
    ({"k": -1}, "k = -1"),
    ({"nominal_arcsec": {"E_xx": 1}}, "nominal_arcsec: unknown angle(s) E_xx"),
    ({"arcsec": "60"}, "arcsec = '60'"),
])
def test_bad_tolerance_keys_are_named(table, says):
    with pytest.raises(InputError, match=None) as e:
        ToleranceSpec.from_table(table, "session.toml: [tolerance]")
    assert says in str(e.value) and str(e.value).startswith("session.toml: [tolerance]")


def test_flag_text():
    assert limits_arcsec("60", "--t", text=True) == (-60, 60)
    assert limits_arcsec("-30,90", "--t", text=True) == (-30, 90)
    with pytest.raises(InputError, match="--t = 'a,b'"):
        limits_arcsec("a,b", "--t", text=True)
