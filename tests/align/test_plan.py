"""What to measure next: the ranking, and (slow) the predicted u after the advised measurement
against the u obtained on a synthetic session with that measurement added."""

import json
from dataclasses import replace

import numpy as np
import pytest

from align.cli import main
from align.fusion import E_INDEX, E_NAMES
from align.fusion.budget import Linearisation
from align.plan import options, plan, plan_from_result
from align.session import load_session, run_session
from axisbase.units import ARCSEC
from synth.session import SessionSpec, write_session


def _run(folder, spec):
    write_session(folder, spec)
    res = run_session(load_session(folder))
    assert res.ok
    return res


def _u(res):
    return np.array([res.fusion.E_u[i, j] for i, j in E_INDEX])


def test_plan_ranks_by_gain_per_minute_and_targets_the_critical_angle(tmp_path, capsys):
    write_session(tmp_path / "s", SessionSpec(seed=3, views=("A", "B")))
    js = tmp_path / "r.json"
    assert main(["run", str(tmp_path / "s"), "--json", str(js), "--tolerance-arcsec",
                 "30,400", "--decision", "simple", "--plan"]) == 0
    assert main(["plan", str(js)]) == 0
    out = capsys.readouterr().out
    assert "VERDICT:" in out and "what to measure next" in out
    assert main(["plan", str(tmp_path / "s" / "gonio.csv")]) == 2
    d = json.loads(js.read_text())
    lin = Linearisation.from_dict(d["budget"]["model"])
    p = plan(lin)
    u = np.array([d["misalignment_u_rad"][i][j] for i, j in E_INDEX])
    assert p.target == E_NAMES[int(np.argmax(u))]
    rates = [(p.u_before - o.u_after) / o.minutes for o in p.options]
    assert rates == sorted(rates, reverse=True) and all(r > 0 for r in rates)
    kinds = [o[1] for o in options(lin)]  # every candidate, before ranking
    assert kinds.count("reversed view") == 2  # A and B have no reversal yet
    assert all(o.kind != "image" for o in p.options)  # < 0.1 % on the target: not listed
    # A disposition makes the angle nearest its acceptance limit the target.
    disp = {"verdict": "INCONCLUSIVE", "angles": [
        {"name": "E_xY", "margin_arcsec": 0.1, "guard_arcsec": 0.2, "verdict": "INCONCLUSIVE"},
        {"name": "E_zX", "margin_arcsec": 50.0, "guard_arcsec": 0.4, "verdict": "PASS"}]}
    assert plan(lin, disp).target == "E_xY"
    assert plan_from_result(d).target == d["disposition"]["worst"]


def _realise(spec: SessionSpec, o) -> SessionSpec | None:
    """The synthetic session with option ``o`` added, or None when synth cannot make it."""
    if o.kind == "static":  # twice the samples per pose: each pose's mean with half the variance
        return replace(spec, samples_per_pose=2 * spec.samples_per_pose)
    if o.kind == "gonio":
        return replace(spec, revolutions=2 * spec.revolutions)
    if o.kind == "reversed view":
        return replace(spec, views=(*spec.views, o.detail["view"] + "r"))
    if o.kind == "image":
        return replace(spec, repeat_images=((o.detail["housing"], o.detail["view"]),))
    return None


SCENARIOS = {
    # the full session less the reversed views: the static poses dominate u
    "full": lambda seed: SessionSpec(seed=100 + seed, views=("A", "B")),
    # no platform static readings: the images dominate the tilts of the axes
    "images": lambda seed: SessionSpec(seed=200 + seed, views=("A", "B"),
                                       platform_static=False),
}


@pytest.mark.slow
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_predicted_u_after_the_advised_measurement_matches_simulation(tmp_path, scenario):
    """Over 6 seeds: the advised option (and the reversal of the target's views) predicted
    vs obtained u of the critical angle, within 15 % (see below)."""
    rows = []
    for seed in range(6):
        spec = SCENARIOS[scenario](seed)
        res = _run(tmp_path / f"b{seed}", spec)
        p = plan(res.fusion.budget.model)
        k = E_NAMES.index(p.target)
        assert _realise(spec, p.best) is not None, p.best.action  # synth can make the advice
        for o in p.options:
            if o is not p.best and o.kind != "reversed view":
                continue
            got = _u(_run(tmp_path / f"{seed}{o.kind}{o.detail}".replace(" ", "_"),
                          _realise(spec, o)))
            rows.append((seed, o.action, o is p.best, p.target, p.u_before, o.u_after, got[k]))
    for seed, action, best, target, before, pred, got in rows:
        print(f"{scenario} seed {seed}: {action}{' (advised)' if best else ''}: {target} u "
              f"{before / ARCSEC:.3f}″ -> predicted {pred / ARCSEC:.3f}″, obtained "
              f"{got / ARCSEC:.3f}″ ({100 * (pred / got - 1):+.1f} %)")
    ratio = np.array([r[5] / r[6] for r in rows])
    print(f"{scenario}: predicted/obtained over {len(rows)}: mean {ratio.mean():.3f}, "
          f"min {ratio.min():.3f}, max {ratio.max():.3f}")
    assert sum(r[2] for r in rows) == 6  # the advice of every seed was simulated
    # 15 %: the plan copies an existing image's covariance for "another image", and each
    # image's u now carries its own groove_profile term (read from that image's residual,
    # stop 28), whose image-to-image scatter the copy cannot predict (worst seen 0.879; 10 %
    # before the term, over the same 12 rows)
    assert np.all(np.abs(ratio - 1) <= 0.15), ratio
