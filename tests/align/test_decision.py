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
    undecided,
)
from align.errors import InputError
from align.fusion import E_INDEX, E_NAMES
from align.fusion.undetermined import Undetermined
from align.problem_codes import ANGLE_UNDECIDED, DISAGREEMENT
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


def test_a_fail_names_a_failing_angle_and_its_guard_band():
    # user 16: E_xZ misses by more (-64.2″) but its wide u makes it INCONCLUSIVE; the unit
    # FAILs on E_yX and E_zY, and names the one furthest beyond its rejection limit
    d = decide(_result([0, -64.23, -65.08, 0, 0, -79.64], [1, 22.03, 2.01, 1, 1, 8.53]),
               _spec())
    by = {a.name: a for a in d.angles}
    assert by["E_xZ"].verdict == INCONCLUSIVE
    assert d.verdict == FAIL and by[d.worst].verdict == FAIL and d.worst == "E_zY"
    assert "E_zY = -79.64 ± 8.53″ is 19.6″ outside" in d.reason
    assert "beyond the guard band 17.1″" in d.reason


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


def _undecided_result(e_arcsec, u_arcsec, spec, more_problems=()):
    """A fused result whose reference-face offset the data cannot determine (σ 2″ declared,
    all of E_yX's u), its problems and their codes as ``align run`` lists them
    (``more_problems``: (code, text))."""
    d = _result(e_arcsec, u_arcsec, ok=False)
    c = Undetermined("reference_face_offset", 2 * A, float("inf"),
                     np.array([0, 0, 2 * A, 0, 0, 0]), True)
    d["undetermined"] = [c.to_dict()]
    e6, u6 = ([v * A for v in x] for x in (e_arcsec, u_arcsec))
    lines = [(ANGLE_UNDECIDED, why) for _, why in undecided(e6, u6, [c], spec)]
    lines += list(more_problems)
    d["problems"] = [t for _, t in lines]
    d["problem_codes"] = [code for code, _ in lines]
    return d


def test_an_angle_not_measured_never_hides_a_clear_fail():
    spec, u = _spec(), [1.0, 5.3, 2.0, 1.0, 1.0, 1.0]
    # user 16: E_yX -57 ± 2.0″ is INCONCLUSIVE, its u all the undetermined offset's
    d = decide(_undecided_result([10, 122.3, -57, 20, -15, 5], u, spec), spec)
    assert d.verdict == FAIL and d.worst == "E_xZ", d.reason
    assert "not measured: E_yX" in d.reason and "as declared" in d.reason
    assert {a.name: a.verdict for a in d.angles}["E_yX"] == INCONCLUSIVE
    # E_xZ inside its guard band: no verdict beyond NOT MEASURED (never INCONCLUSIVE/PASS)
    for e_xz in (20.0, 55.0, 65.0):
        d = decide(_undecided_result([10, e_xz, -57, 20, -15, 5], u, spec), spec)
        assert d.verdict == NOT_MEASURED and "E_yX's tolerance cannot be decided" in d.reason
    # another reason the result is not ok: NOT MEASURED whatever the numbers
    r = _undecided_result([10, 122.3, -57, 20, -15, 5], u, spec, [
        (DISAGREEMENT, "fusion: the instruments disagree beyond their uncertainties")])
    assert decide(r, spec).verdict == NOT_MEASURED
    # the codes are read, never the text: an edited line changes nothing ...
    r = _undecided_result([10, 122.3, -57, 20, -15, 5], u, spec)
    r["problems"] = [p.replace("as declared", "declared") for p in r["problems"]]
    assert decide(r, spec).verdict == FAIL
    # ... a result without codes (written before them) or with an unknown one is not ok
    for codes in (None, ["no_such_code"], [ANGLE_UNDECIDED, ANGLE_UNDECIDED]):
        r = _undecided_result([10, 122.3, -57, 20, -15, 5], u, spec)
        r["problem_codes"] = codes
        assert decide(r, spec).verdict == NOT_MEASURED, codes


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


# ----------------------------------------------------------------------------- end to end

@pytest.fixture(scope="module")
def session(tmp_path_factory):
    from synth.session import SessionSpec, write_session

    folder = tmp_path_factory.mktemp("dec") / "s"
    write_session(folder, SessionSpec(seed=8, views=("A", "B")))
    return folder


def test_run_writes_the_disposition_and_fail_on_reject_exits_3(session, tmp_path, capsys):
    import json

    from align.cli import main
    from align.contract import validate

    (session / "session.toml").write_text((session / "session.toml").read_text()
                                          + "\n[tolerance]\narcsec = 1000\nE_xZ = [-30, 90]\n"
                                          "nominal_arcsec = { E_xZ = 5.0 }\n")
    js = tmp_path / "r.json"
    code = main(["run", str(session), "--json", str(js), "--fail-on-reject"])
    d = json.loads(js.read_text())
    validate(d, "session")
    disp = d["disposition"]
    e_xz = d["misalignment_arcsec"][0][2]
    expected = FAIL if not -25 - 1 <= e_xz <= 95 + 1 else None  # synth E: 60-300″, signed
    assert disp["rule"] == "guarded" and disp["k"] == 2.0
    a = {x["name"]: x for x in disp["angles"]}["E_xZ"]
    assert (a["lower_arcsec"], a["upper_arcsec"]) == pytest.approx((-25, 95))
    if expected:
        assert disp["verdict"] == FAIL and code == 3
    assert "VERDICT: " + disp["verdict"] in capsys.readouterr().out


def test_flags_override_and_the_lot_judges_each_unit(session, tmp_path):
    import json

    from align.cli import main
    from align.contract import validate

    # The command line overrides session.toml: a wide tolerance passes, exit 0.
    js2 = tmp_path / "r2.json"
    assert main(["run", str(session), "--json", str(js2), "--tolerance-arcsec", "2000",
                 "--decision", "simple", "--fail-on-reject", "-q"]) == 0
    d2 = json.loads(js2.read_text())
    assert d2["disposition"]["verdict"] == PASS and d2["disposition"]["rule"] == "simple"
    assert set(d2["budget"]["angles"]) == set(E_NAMES)

    # A lot judges every unit by its flags: one unit shifted far out FAILs.
    from synth.lot import lot_results

    results, truth = lot_results(d2, 8, seed=1, mean_rad=0.0, sigma_rad=2 * A,
                                 shifts={3: (1, 40.0)})
    files = []
    for k, r in enumerate(results):
        f = tmp_path / f"u{k}.json"
        f.write_text(json.dumps(r))
        files.append(str(f))
    lot_js = tmp_path / "lot.json"
    assert main(["lot", *files, "--json", str(lot_js), "--tolerance-arcsec", "40",
                 "--fail-on-reject", "-q"]) == 3
    lot = json.loads(lot_js.read_text())
    validate(lot, "lot")
    verdicts = [u["verdict"] for u in lot["dispositions"]]
    assert verdicts[3] == FAIL and lot["dispositions"][3]["worst"] == "E_xZ"
    assert [u["unit"] for u in lot["dispositions"]] == [f"SN{k:05d}" for k in range(8)]


def test_a_failed_session_is_not_measured_even_with_a_tolerance(session, tmp_path):
    import json
    import shutil

    from align.cli import main

    broken = tmp_path / "b"
    shutil.copytree(session, broken)
    (broken / "x_A.png").write_bytes(b"not a png")
    js = tmp_path / "r.json"
    assert main(["run", str(broken), "--json", str(js), "--tolerance-arcsec", "2000",
                 "--fail-on-reject", "-q"]) == 2  # the documented status of a failed stage
    d = json.loads(js.read_text())
    assert d["disposition"]["verdict"] == NOT_MEASURED and d["disposition"]["angles"] == []
    assert "x_A.png" in d["disposition"]["reason"]
