"""The one reader of a session result JSON (``align.session_json.LoadedSession``): every
former reader — the lot, ``align apply``/``tilt``, a resumed batch's rows, ``align plan`` —
reads through it and still says what it said, of every readable format version."""

from __future__ import annotations

import copy
import json
from dataclasses import replace

import numpy as np
import pytest

from align.cli import main
from align.contract import FORMATS
from align.errors import InputError
from align.session_json import ANGLE_NAMES, LoadedSession
from axisbase.units import ARCSEC
from tests.conftest import imageless_session

PROV = ("tool", "tool_version", "created_utc", "command", "settings", "inputs")


@pytest.fixture(scope="module")
def result(tmp_path_factory) -> dict:
    """A seeded session run by ``align run`` (no images): its result JSON."""
    from synth.session import SessionSpec

    root = tmp_path_factory.mktemp("loaded")
    # short poses and log: the readers are under test, not the estimates (~1 s CPU)
    s = imageless_session(root, SessionSpec(seed=21, samples_per_pose=30, revolutions=40))
    out = root / "r.json"
    assert main(["run", str(s), "--json", str(out), "--tolerance-arcsec", "600", "-q"]) == 0
    return json.loads(out.read_text())


def _v1(d: dict) -> dict:
    """As format version 1 wrote it: no envelope at all."""
    return {k: v for k, v in d.items() if k not in ("format", "format_version", *PROV)}


def _v2(d: dict) -> dict:
    """As format version 2 wrote it: the provenance nested in a block of its own."""
    out = {k: v for k, v in d.items() if k not in PROV}
    out["format_version"] = 2
    out["provenance"] = {"tool": d["tool"], "version": d["tool_version"],
                         "written_utc": d["created_utc"], "command_line": d["command"],
                         "settings": d["settings"], "inputs": d["inputs"]}
    return out


def _v3(d: dict) -> dict:
    """As format version 3 wrote it: the same keys (only the meaning of a multi-component
    fusion effect's top-level estimate changed in version 4)."""
    return dict(d, format_version=3)


def _v4(d: dict) -> dict:
    """As format version 4 wrote it: no ``problem_codes`` (version 5 added them)."""
    return {k: v for k, v in d.items() if k != "problem_codes"} | {"format_version": 4}


@pytest.mark.parametrize("version", [1, 2, 3, 4, 5])
def test_every_readable_version_reads_the_same(result, version):
    d = {1: _v1, 2: _v2, 3: _v3, 4: _v4, 5: dict}[version](result)
    r = LoadedSession.from_dict(d, "r.json")
    assert r.format_version == version
    assert (r.session, r.ok, r.fused, r.folder) == (result["session"], True, True,
                                                    result["folder"])
    E = np.array(result["misalignment_rad"])
    assert r.e_rad == tuple(E[i, j] for i, j in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)))
    assert np.array_equal(np.array(r.covariance), np.array(result["covariance_rad2"]))
    assert r.platform_calibration == result["platform_calibration"]
    assert r.verdict == result["disposition"]["verdict"] == "PASS"
    sha = [i["sha256"] for i in result["inputs"]]
    assert [i.sha256 for i in r.provenance.inputs] == ([] if version == 1 else sha)
    assert r.provenance.settings == ({} if version == 1 else result["settings"])


def test_problem_codes_read_and_an_older_results_problems_unknown(result):
    """Version 5 gives each problem its code; a result written before codes reads each of
    its problems as ``unknown`` (not ok whatever the tolerance, as before); codes that do not
    match the lines (edited) are unknown too — never fewer problems than the file says."""
    lines = ["fusion: E_xY's tolerance cannot be decided: ...", "a.png: lens-limited"]
    d = dict(result, ok=False, problems=lines, problem_codes=["angle_undecided", "lens_limited"])
    assert LoadedSession.from_dict(d, "r.json").problem_codes == ("angle_undecided",
                                                                  "lens_limited")
    assert LoadedSession.from_dict(_v4(d), "r.json").problem_codes == ("unknown", "unknown")
    for codes in (["angle_undecided"], ["angle_undecided", "no_such_code"]):
        r = LoadedSession.from_dict(dict(d, problem_codes=codes), "r.json")
        assert r.problem_codes == ("unknown", "unknown"), codes
    assert result["problem_codes"] == [] == result["problems"]


def test_a_newer_or_another_format_is_refused_naming_the_file(result):
    with pytest.raises(InputError, match=r"r\.json: .*version 99 is newer"):
        LoadedSession.from_dict(dict(result, format_version=99), "r.json")
    with pytest.raises(InputError, match=r"r\.json: a 'axis-align/gonio' file"):
        LoadedSession.from_dict(dict(result, format="axis-align/gonio"), "r.json")


@pytest.mark.parametrize("version", [1, 2, 3, 4, 5])
def test_the_former_readers_read_what_the_one_reader_reads(result, tmp_path, version):
    from align.apply import PlatformCalibration
    from align.lot.read import UnitResult, read_result
    from align.plan import plan_from_result
    from align.session.batch import batch_row

    d = {1: _v1, 2: _v2, 3: _v3, 4: _v4, 5: dict}[version](result)
    r = LoadedSession.from_dict(d, "r.json")
    # the lot
    f = tmp_path / "r.json"
    f.write_text(json.dumps(d))
    u = read_result(f).unit
    assert u is not None
    assert u == replace(UnitResult.of(LoadedSession.from_dict(d, str(f))), sha256=u.sha256)
    assert (u.e_rad, u.u_rad, u.covariance, u.ok, u.format_version) == (
        r.e_rad, r.u_rad, r.covariance, r.ok, version)
    assert u.label == result["session"] and u.disposition == result["disposition"]
    assert u.created_utc == (None if version == 1 else result["created_utc"])
    # align apply / tilt
    pc = PlatformCalibration.from_dict(d, "r.json")
    assert np.array_equal(pc.e6, np.array(r.e_rad))
    assert np.array_equal(pc.cov, np.array(r.covariance))
    # a batch's row
    row = batch_row({"session": "s", "ok": True, "json": d})
    assert row.e_max_arcsec == pytest.approx(max(map(abs, r.e_rad)) / ARCSEC, rel=1e-12)
    assert (row.chi2, row.dof, row.verdict, row.consistent) == (
        result["chi2"], result["dof"], "PASS", not result["unexplained_structure"])
    # align plan
    assert plan_from_result(d).lines() == plan_from_result(r).lines()


def test_a_corrupt_result_is_refused_alike_by_every_reader(result, tmp_path):
    """'ok' with a failed stage: the lot rejects the file, apply and plan refuse it, each
    with the one reader's line."""
    from align.apply import PlatformCalibration
    from align.lot.read import read_result
    from align.plan import plan_from_result

    bad = copy.deepcopy(result)
    bad["errors"] = [{"stage": "goniometer", "message": "gonio.csv: empty"}]
    f = tmp_path / "bad.json"
    f.write_text(json.dumps(bad))
    why = "'ok' is true but stage goniometer failed"
    assert why in read_result(f).rejected.reason
    for read in (lambda: PlatformCalibration.from_dict(bad, str(f)),
                 lambda: plan_from_result(bad, str(f)), lambda: LoadedSession.load(f)):
        with pytest.raises(InputError, match=why):
            read()
    assert main(["plan", str(f)]) == 2


def test_a_lot_alone_refuses_an_angle_beyond_5_degrees(result):
    """A lot's own rule on top of the reader's: |E| > 5° is no mounting error."""
    from align.lot.read import UnitResult

    d = copy.deepcopy(result)
    d["misalignment_rad"][0][1] = 0.1
    d.pop("misalignment_arcsec")
    r = LoadedSession.from_dict(d, "r.json")
    assert r.e_rad[0] == 0.1
    with pytest.raises(InputError, match=r"misalignment_rad\[0\]\[1\] .* beyond 5°"):
        UnitResult.of(r)


def test_resume_reads_the_one_readers_provenance(result, tmp_path):
    """--resume: a version-2 result of this folder is redone (its provenance read from the
    nested block), another folder's is refused, a stub is not a result."""
    from align.session.batch import SessionJob, reuse_verdict

    out = tmp_path / "r.json"
    job = SessionJob(result["folder"], str(out))
    out.write_text(json.dumps(_v2(result)))
    writes = FORMATS["session"]
    assert reuse_verdict(job) == ("redo", f"{out} has format version 2, this tool writes {writes}")
    out.write_text(json.dumps(dict(result, folder=str(tmp_path))))
    assert reuse_verdict(job)[0] == "refuse"
    out.write_text(json.dumps(dict(result, ok="yes")))
    assert reuse_verdict(job) == ("redo", f"{out}: 'ok' and 'fused' must be true or false")


def test_cov_of_is_one_answer_from_every_result_type(result):
    """The covariance of named angles: the loaded result, its platform calibration and the
    fusion read back give the same numbers, from the matrix the JSON holds."""
    from align.apply import PlatformCalibration
    from align.fusion.solve import FusionResult

    r = LoadedSession.from_dict(result, "r.json")
    want = ("E_zX", "E_xY")
    full = np.array(result["covariance_rad2"])
    expect = full[np.ix_([4, 0], [4, 0])]  # E_zX is the 5th of E_NAMES, E_xY the 1st
    for got in (r.cov_of(*want), PlatformCalibration.from_dict(result, "r").cov_of(*want),
                FusionResult.from_dict(result).cov_of(*want)):
        assert np.array_equal(got, expect)
    with pytest.raises(KeyError, match="E_xX"):
        r.cov_of("E_xX")


def test_angle_names_are_the_fusions():
    from align.fusion import E_INDEX, E_NAMES
    from align.session_json import ANGLE_INDEX

    assert ANGLE_NAMES == E_NAMES and ANGLE_INDEX == E_INDEX
