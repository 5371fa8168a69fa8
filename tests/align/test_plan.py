"""What to measure next: the ranking, and (slow) the predicted u after the advised measurement
against the u obtained on a synthetic session with that measurement added."""

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import special

from align.cli import main
from align.fusion import E_INDEX, E_NAMES, NOT_EXCLUDED_TAG
from align.fusion.budget import Budget, Group, Linearisation
from align.plan import (
    NOISE_K,
    image_noise,
    options,
    plan,
    plan_from_result,
    predict,
    predicted,
    prediction_noise,
)
from align.plan_carried import ranged_after
from align.session import load_session, run_session
from align.warnings import CARRIED_PREFIX, carried_notices, session_notes, session_warnings
from axisbase.units import ARCSEC
from synth.session import SessionSpec, write_session


def _run(folder, spec, roll_u=None, ref_u=None):
    write_session(folder, spec)
    toml = folder / "session.toml"
    if roll_u is not None:  # the declared rolls calibrated to ± roll_u [rad]
        toml.write_text(toml.read_text().replace(
            "roll_arcsec = ", f"roll_u_arcsec = {roll_u / ARCSEC!r}\nroll_arcsec = "))
    if ref_u is not None:  # the reference face's offset known to ± ref_u [rad]
        toml.write_text(toml.read_text().replace(
            'direction = "ccw"', f'direction = "ccw"\nreference_offset_u_arcsec = '
            f'{ref_u / ARCSEC!r}', 1))
    res = run_session(load_session(folder))
    assert res.ok
    return res


def _u(res):
    """E's u less the candidates the fusion carries as not excluded (align/fusion/plausible.py:
    a Type B term drawn from each run's own estimate, outside the plan's algebra)."""
    b = res.fusion.budget.angles
    return np.array([np.sqrt(b[n][0] ** 2 - sum(c.u2 for c in b[n][1]
                                                if NOT_EXCLUDED_TAG in c.source))
                     for n in E_NAMES])


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


def _images_lin(own_arcsec2, lens_arcsec=0.0) -> Linearisation:
    """E_xY seen only by images of housing x in view A (camera A), each with its own variance
    ``own_arcsec2`` [″²], all coupled by ``lens_arcsec`` [″] to one lens error (a unit prior);
    the other five angles known to 0.01″ (a static-like group)."""
    P = 7  # the six angles, the lens error
    rows = []
    for k, v in enumerate(own_arcsec2):
        A = np.zeros((1, P))
        A[0, 0], A[0, 6] = 1.0, lens_arcsec * ARCSEC
        rows.append(Group(f"image x_A_{k}.png", "image", A, np.array([[v * ARCSEC**2]]), (),
                          {"housing": "x", "view": "A", "camera": "A"}))
    rest = np.zeros((5, P))
    rest[:, 1:6] = np.eye(5)
    lens = np.zeros((1, P))
    lens[0, 6] = 1.0
    return Linearisation((*E_NAMES, "lens[0]"),
                         (*rows, Group("static poses", "static", rest,
                                       np.eye(5) * (0.01 * ARCSEC) ** 2),
                          Group("lens of camera A", "typeB", lens, np.eye(1))),
                         (("lens of camera A", (6,)),))


def _option(lin, kind):
    return next(o for o in options(lin) if o[1] == kind)


def test_another_image_is_the_cameras_mean_image_not_a_copy():
    """The defect of the copied covariance: one more image of x in A adds the camera's mean
    information (own u² 1 and 9 ″²: 1/u² 1 and 1/9, their mean 5/9: a variance 1.8 ″², not the
    mean variance 5 ″² a single poor image sets), and its draw's scatter is the prediction's
    noise."""
    lin = _images_lin([1.0, 9.0])
    _, _, _, add, drop, _ = _option(lin, "image")
    assert add[0].C[0, 0] / ARCSEC**2 == pytest.approx(1.8)
    # pooled relative SD of the informations: |1/(5/9) - 1| = |(1/9)/(5/9) - 1| = 0.8, 1 dof
    images = [g for g in lin.groups if g.kind == "image"]
    s, dof = image_noise(images)
    assert (s, dof) == (pytest.approx(0.8 * np.sqrt(2)), 1)
    p = plan(lin)
    o = next(o for o in p.options if o.kind == "image")
    # u² = 1 / (1/1 + 1/9 + 5/9) ″²
    info = 1 + 1 / 9 + 5 / 9
    assert o.u_after / ARCSEC == pytest.approx(info ** -0.5, rel=1e-6)
    # The new information's 68 % interval: ± 1.13 × √(1 + 1/2) × t_1(84.1 %) = 1.837 of the
    # mean (> 1: its low end is no information, the image not added); u's interval its image.
    rel = 0.8 * np.sqrt(2) * np.sqrt(1 + 1 / 2) * 1.8373
    low, high = (1 + 1 / 9) ** -0.5, (1 + 1 / 9 + 5 / 9 * (1 + rel)) ** -0.5
    assert o.u_after_noise / ARCSEC == pytest.approx((low - high) / 2, rel=1e-3)


def test_a_lens_the_cameras_images_share_does_not_average_down():
    """A lens error of 3″ on every image of camera A (own u 0.5″): more images of that camera
    leave E_xY lens-limited; the new row is coupled to the same lens error."""
    lin = _images_lin([0.25, 0.25], lens_arcsec=3.0)
    u0 = lin.u_with()[0]
    _, _, _, add, drop, _ = _option(lin, "image")
    assert add[0].A[0, 6] == pytest.approx(3.0 * ARCSEC)
    u1 = lin.u_with(add=add, drop=drop)[0]
    assert 1 - u1 / u0 < 0.01  # a per-image term would have fallen by 18 % (sqrt(2/3))


def test_the_plan_says_when_no_gain_exceeds_the_noise_of_its_prediction():
    """Two images whose own u² scatter 1 to 9: one more image or a reversal would lower u of
    E_xY by less than twice its prediction's noise, and the plan says so; two alike images
    (4 and 5 ″²) make the same gains clear."""
    noisy = plan(_images_lin([1.0, 9.0]))
    assert noisy.target == "E_xY" and noisy.options
    assert all(noisy.u_before - o.u_after < NOISE_K * o.u_after_noise for o in noisy.options)
    assert noisy.within_noise and noisy.to_dict()["within_noise"]
    text = "\n".join(noisy.lines())
    assert "no measurement improves E_xY by more than the noise of its prediction" in text
    assert "->" not in text  # nothing advised
    clear = plan(_images_lin([4.0, 5.0]))
    assert not clear.within_noise
    assert "->" in "\n".join(clear.lines()) and "noise" not in "\n".join(clear.lines())


def _roll_lin(b_arcsec: float) -> Linearisation:
    """E_xY seen by three images of housing x in view A (u 1″ each), whose mark angle also
    carries camera A's roll, held: the fusion carries it as not excluded, estimate
    ``b_arcsec`` [″]; and by a static-like row of u 2″; the other five angles known to 0.01″.
    Freed, the roll is the images' mean less E_xY: u_b² = 4 + 1/3 ″², k = dE/db = -12/13."""
    P = 7
    rows = []
    for k in range(3):
        A = np.zeros((1, P))
        A[0, 0] = A[0, 6] = 1.0
        rows.append(Group(f"image x_A_{k}.png", "image", A, np.array([[ARCSEC**2]]), (),
                          {"housing": "x", "view": "A", "camera": "A"}))
    rest = np.zeros((6, P))
    rest[0, 0] = 1.0
    rest[1:, 1:6] = np.eye(5)
    C = np.diag([4.0, *[1e-4] * 5]) * ARCSEC**2
    return Linearisation((*E_NAMES, "camera_roll[A]"),
                         (*rows, Group("static poses", "static", rest, C)), (), 1.0,
                         (("camera_roll[A]", (6,), (b_arcsec * ARCSEC,),
                           float(special.chdtrc(1, b_arcsec**2 / (4 + 1 / 3)))),))


def test_the_plan_predicts_a_carried_term_and_names_what_resolves_it():
    """A camera roll carried as not excluded (5″ ± 2.08″, z 2.4) moves E_xY by -12/13 of it:
    u 0.555″ without it, 4.65″ with it. A reversed view separates the roll from E (k -> 0):
    the term drops and u falls to 0.4″ — the advice, named as what resolves it; one more
    image leaves it carried (k -16/17) and raises u; the roll calibrated is declared: no
    longer a candidate, u 0.555″ (in 30 min: last). The warning says so."""
    lin = _roll_lin(5.0)
    fixed, shift = 1 / np.sqrt(3.25), -12 / 13 * 5.0
    p = plan(lin)
    assert p.target == "E_xY"
    assert p.u_before / ARCSEC == pytest.approx(np.hypot(fixed, shift), rel=1e-6)
    (c,) = p.carried
    assert (c.name, c.p) == ("camera_roll[A]", 1.0)
    assert c.estimate / ARCSEC == pytest.approx(5.0)
    assert c.u / ARCSEC == pytest.approx(np.sqrt(4 + 1 / 3), rel=1e-6)
    assert c.shift[0] / ARCSEC == pytest.approx(shift, rel=1e-6)
    by_kind = {o.kind: o for o in p.options}
    rev = by_kind["reversed view"]
    assert rev.u_after / ARCSEC == pytest.approx(0.4, rel=1e-6)
    assert rev.carried[0].p == 0.0
    assert p.best is rev and p.resolves["camera_roll[A]"] == rev.action
    # One more image: k -16/17, u_b² 4.25 ″²; z 2.4 still, the shift 4.7″ >> u/2: carried,
    # and u rises (not an option: it lowers nothing).
    img = predict(lin, *_option(lin, "image")[3:5])
    assert img.carried[0].p > 0.95 and "image" not in by_kind
    assert img.u[0] / ARCSEC == pytest.approx(np.hypot(1 / np.sqrt(4.25), 16 / 17 * 5.0),
                                              rel=0.01)
    cam = by_kind["camera"]
    assert cam.carried == () and cam.u_after / ARCSEC == pytest.approx(fixed, rel=1e-6)
    assert [o.kind for o in p.options] == ["reversed view", "static", "camera"]
    text = "\n".join(p.lines())
    assert "its u carries camera_roll[A] not excluded (+5.0 ± 2.1″)" in text
    assert "likely no longer carries camera_roll[A] (p 0.00; named p 0.96)" in text
    # a term too small to lower u by MIN_GAIN of it gets no line (user 16: "0.000″ of it")
    tiny = replace(p.carried[0], shift=tuple(1e-3 * np.asarray(p.carried[0].shift)))
    assert "its u carries" not in "\n".join(replace(p, carried=(tiny,)).lines())
    # The session warning: the candidate, its value and u, and what resolves it.
    fusion = SimpleNamespace(budget=Budget({}, 1.0, lin))
    assert carried_notices(fusion) == [
        f"{CARRIED_PREFIX}camera_roll[A] not excluded (+5.0 ± 2.1″): {rev.action}"]
    # A roll near zero is no longer carried after more images of the same kind: dropped.
    assert not predict(_roll_lin(0.5), *_option(lin, "image")[3:5]).still("camera_roll[A]")


def test_the_plan_judges_a_carried_candidate_over_its_declared_range():
    """The range declared in session.toml (``Linearisation.ranges``) is the one the plan
    judges by, not the default: camera A's roll (5″ ± 2.08″, carried) after one more image has
    u freed 2.06″ — within the default range (σ 34.6″): still carried as not excluded; beyond
    a declared σ of 1″: undetermined, carried over that range (σ² u_f²/(σ² + u_f²) k²), as the
    fusion judges it (undetermined first)."""
    lin = _roll_lin(5.0)
    add, drop = _option(lin, "image")[3:5]
    default = predict(lin, add, drop)
    assert default.carried[0].p > 0.95 and default.ranged == ()
    declared = replace(lin, ranges=(("camera_roll[A]", 1.0 * ARCSEC),),
                       declared=("camera_roll[A]",))
    after = predict(declared, add, drop)
    assert after.carried[0].p == 0.0
    (r,) = after.ranged
    assert (r.name, r.sigma) == ("camera_roll[A]", 1.0 * ARCSEC)
    # named as declared, as the fusion's warning names it (the range read where it is kept)
    assert r.declared and "σ 1.0″, declared;" in r.label, r.label
    assert Linearisation.from_dict(declared.to_dict()).declared == ("camera_roll[A]",)
    (r,) = predict(replace(declared, declared=()), add, drop).ranged
    assert "default range" in r.label
    u_f2 = 4 + 1 / 4  # [″²]: four images of u 1″ and the static row of u 2″
    assert r.u_freed / ARCSEC == pytest.approx(np.sqrt(u_f2), rel=1e-3)
    assert abs(r.shift[0]) / ARCSEC == pytest.approx(16 / 17 * np.sqrt(u_f2 / (1 + u_f2)),
                                                     rel=1e-3)
    # the session's own data: the fusion decided (carried as not excluded), not re-judged
    assert predict(declared).carried[0].p == 1.0


def test_no_carried_note_when_nothing_is_carried(session21_run):
    """The clean session of seed 21 carries nothing: no such note, and its plan's u is
    the linearisation's."""
    res, _ = session21_run
    lin = res.fusion.budget.model
    assert lin.held == ()
    assert session_notes(res) == []
    assert not any(w.startswith(CARRIED_PREFIX) for w in session_warnings(res))
    assert np.allclose(predict(lin).u, lin.u_with())


def _realise(spec: SessionSpec, kind: str, detail) -> SessionSpec:
    """The synthetic session with option ``kind``/``detail`` added; the rest of the session is
    the same to the bit (synth draws added views and images from their own stream)."""
    if kind == "static":  # twice the samples per pose: each pose's mean with half the variance
        return replace(spec, samples_per_pose=2 * spec.samples_per_pose)
    if kind == "datum":  # the side poses added to the levelled ones
        return replace(spec, platform_poses=(*spec.platform_poses, "Xup", "Xdn", "Yup", "Ydn"))
    if kind == "gonio":
        return replace(spec, revolutions=2 * spec.revolutions)
    if kind == "tumble":
        return replace(spec, tumble_repeats=2)
    if kind == "reversed view":
        return replace(spec, added_views=(detail["view"] + "r",))
    if kind == "image":
        return replace(spec, repeat_images=((detail["housing"], detail["view"]),))
    assert kind == "camera", kind  # the roll calibrated: declared (exactly; see ROLL_U)
    name = f"camera_roll_{detail['camera']}"
    return replace(spec, undeclared=spec.undeclared - {name},
                   effects={name: 0.0, **spec.effects})


SCENARIOS = {
    # the full session less the reversed views: the static poses dominate u
    "full": lambda seed: SessionSpec(seed=100 + seed, views=("A", "B")),
    # no platform static readings: the images dominate the tilts of the axes
    "images": lambda seed: SessionSpec(seed=200 + seed, views=("A", "B"),
                                       platform_static=False),
    # no static readings, camera A reversed and rolled 40″ (undeclared): the loop estimates
    # the roll, and calibrating it is an option
    "roll": lambda seed: SessionSpec(seed=300 + seed, views=("A", "Ar", "B"),
                                     platform_static=False, effects={"camera_roll_A": 40.0},
                                     undeclared=frozenset({"camera_roll_A"})),
}
# Per option, the largest |predicted/obtained - 1| accepted: 3 SD of that ratio over the seeds
# (the obtained u scatters because the new data state their own u), measured with this test
# over 5 seeds × 3 scenarios: one more image SD 0.050 (its own u² a new draw about the
# camera's mean), a reversed view 0.035, a log twice as long 0.154 (its u re-evaluated from
# the new log's phase path and quantisation), the static poses 0.022, the tumble 0.002 and
# a calibrated roll 0.000 (both under the linearisation's 1 %: 3 %); the reversed view 3 SD = 0.105:
# the 10 % of before kept.
BOUND = {"image": 0.15, "reversed view": 0.10, "gonio": 0.45, "static": 0.07,
         "tumble": 0.03, "camera": 0.03}
ROLL_U = 1e-3 * ARCSEC
"""The calibrated roll's u for the check [rad]: synth declares the true roll, exactly."""
SEEDS = 5


def _fixed(lin: Linearisation, add=(), drop=(), detail=None) -> np.ndarray:
    """The plan's u of the six angles [rad] less the not-excluded candidates' shares (as
    :func:`_u`): the linearisation's with the undetermined nuisances' ranges after the
    measurement (a calibrated camera's roll declared)."""
    gs = [g for g in lin.groups if g.source not in drop] + list(add)
    declared = ({f"camera_roll[{detail['camera']}]": ROLL_U} if detail and "camera" in detail
                else {})
    ranged = ranged_after(lin, lin.information(gs), declared)
    return np.sqrt(lin.u_with(add=add, drop=drop) ** 2
                   + sum((np.square(r.shift) for r in ranged), np.zeros(6)))


@pytest.mark.slow
@pytest.mark.parametrize("scenario", [
    "full",
    "images",
    "roll"])
def test_predicted_u_of_every_option_matches_simulation(tmp_path, scenario):
    """Over 5 seeds, every option of the plan realised in synth (another image of each
    housing in each view, a reversed view, a log twice as long, a second tumble, the static
    poses repeated, a calibrated camera roll): the u it predicts against the u obtained, on
    the angle it lowers most and on the critical angle."""
    rows = []
    for seed in range(SEEDS):
        spec = SCENARIOS[scenario](seed)
        res = _run(tmp_path / f"b{seed}", spec)
        lin = res.fusion.budget.model
        p = plan(lin, camera_roll_u=ROLL_U)
        k = E_NAMES.index(p.target)
        u0 = _fixed(lin)
        for action, kind, _, add, drop, detail in options(lin, camera_roll_u=ROLL_U):
            pred = _fixed(lin, add, drop, detail)
            gain = 1 - pred / u0
            if gain.max() < 1e-3:
                continue  # lowers no angle: nothing to compare
            noise = prediction_noise(lin, add, drop)
            data = lin.u_with(add=add, drop=drop)  # the part the linearisation computes
            got = _u(_run(tmp_path / f"{seed}{kind}{detail}".replace(" ", "_"),
                          _realise(spec, kind, detail), ROLL_U if kind == "camera" else None))
            best = p.best is not None and p.best.action == action
            for j in sorted({int(np.argmax(gain)), k}):
                if gain[j] >= 1e-3:
                    rows.append((seed, kind, action, best, E_NAMES[j], u0[j], pred[j],
                                 noise[j], got[j], data[j]))
    z = []
    for seed, _, action, best, angle, before, pred, noise, got, data in rows:
        # the linearisation's own error: 1 % (test_budget: leave-one-out within 2 %) of what
        # it computes, the data's part of u (2 % of its u², over 2 u); the undetermined
        # nuisances' terms are the fusion's rule over their σ, the same on both sides (the
        # calibrated rolls, exact: 0.000″ off on 3.1″ where 1 % of u would be 0.35″)
        z.append((got - pred) / np.hypot(noise, 0.01 * data**2 / pred))
        print(f"{scenario} seed {seed}: {action}{' (advised)' if best else ''}: {angle} u "
              f"{before / ARCSEC:.4f}″ -> predicted {pred / ARCSEC:.4f} ± {noise / ARCSEC:.4f}″,"
              f" obtained {got / ARCSEC:.4f}″ ({100 * (pred / got - 1):+.1f} %, z {z[-1]:+.2f})")
    z = np.array(z)
    ratio = np.array([r[6] / r[8] for r in rows])
    for kind in dict.fromkeys(r[1] for r in rows):
        sel = np.array([r[1] == kind for r in rows])
        print(f"{scenario} {kind}: predicted/obtained over {sel.sum()}: mean "
              f"{ratio[sel].mean():.3f}, SD {ratio[sel].std():.3f}, min {ratio[sel].min():.3f}, "
              f"max {ratio[sel].max():.3f}; RMS z {np.sqrt(np.mean(z[sel] ** 2)):.2f}")
    stated = np.array([r[7] > 0 for r in rows])
    print(f"{scenario}: RMS z {np.sqrt(np.mean(z ** 2)):.2f} (over the rows with a stated noise "
          f"{np.sqrt(np.mean(z[stated] ** 2)):.2f}), max |z| {np.abs(z).max():.2f}")
    assert sum(r[3] for r in rows) >= SEEDS  # the advice of every seed was simulated
    # Each row within its own stated noise (⊕ 1 %), and that noise honest over the scenario's
    # rows that state one: neither understated (RMS z > 1.4) nor inflated to pass (RMS z <
    # 0.4) — a row without (a calibrated roll: exact) tests the linearisation, not a noise.
    assert np.abs(z).max() <= 3.5, z
    assert 0.4 <= np.sqrt(np.mean(z[stated]**2)) <= 1.4, z[stated]
    bound = np.array([BOUND[r[1]] for r in rows])
    off = [(r[1], r[4], q) for r, q, b in zip(rows, ratio, bound, strict=True) if abs(q - 1) > b]
    assert not off, off


def _carrying(seed: int) -> SessionSpec:
    """Camera B rolled 20″, undeclared, and no reversal views: the fusion cannot tell the roll
    from E (nor from the platform's levelling) and carries them as not excluded."""
    return SessionSpec(seed=seed, views=("A", "B"),
                       platform_poses=("L000", "L090", "L180", "L270"), noise_v=1e-3,
                       effects={"camera_roll_B": 20.0},
                       undeclared=frozenset({"camera_roll_B"}))


CARRY_REF_U = 1.0 * ARCSEC
"""The reference face's offset in the carrying scenario known to ± this [rad] (declared): it
has no azimuth datum, and over the default range (σ 34.6″) the offset would be its largest u,
E_xY's, which only the X/Y-up poses lower (test_predicted_u_of_every_option_matches_simulation
checks that); the scenario is about the carried roll and levelling."""
CARRY_SEEDS = (10, 11, 12, 15, 16, 17, 18)
"""The seeds of 10–18 whose fusion carries the roll (13 carries nothing, 14 names it)."""


@pytest.mark.slow
def test_predicted_u_with_carried_terms_matches_simulation(tmp_path):
    """In sessions that carry not-excluded terms, every option of the plan (ranked or not)
    realised in synth: the u it predicts for the critical angle — each carried term's
    expected share after the measurement included (named, undetermined beside a named one,
    carried freed or in place of a named one, or dropped, over the draws of the new
    estimates) — against the u the fusion then states (a calibrated roll declared to
    ``ROLL_U`` in both). The plan starts from the stated u;
    each row within 3.5 of its stated noise (⊕ 1 %), and that noise honest over the rows
    (RMS z 0.4–1.4); where the plan says a term is likely no longer carried, the fusion
    mostly does not carry it."""
    from align.errors import InputError
    from align.plan import plan_from_result

    rows, agree, refused = [], [], []
    for seed in CARRY_SEEDS:
        spec = _carrying(seed)
        res = _run(tmp_path / f"b{seed}", spec, ref_u=CARRY_REF_U)
        lin = res.fusion.budget.model
        assert lin.held, seed  # the scenario carries (else the seed list is stale)
        p = plan(lin, camera_roll_u=ROLL_U)
        k = E_NAMES.index(p.target)
        ij = E_INDEX[k]
        if p.u_before != pytest.approx(res.fusion.E_u[ij], rel=0.01):
            # The plan's model does not give the stated u (seeds 11, 15 since the centres
            # reach the grooves' ends: camera_roll[B] added, platform_level held beside it at
            # -0.049 rad, u(E_yZ) 10199″ for 24.96″): `align plan` must refuse, not plan.
            with pytest.raises(InputError, match="not planned"):
                plan_from_result(json.loads(json.dumps(res.to_dict())))
            refused.append(seed)
            continue
        for o in predicted(lin, p.target, camera_roll_u=ROLL_U):  # ranked or not
            got_res = _run(tmp_path / f"{seed}{o.kind}{o.detail}".replace(" ", "_"),
                           _realise(spec, o.kind, o.detail),
                           ROLL_U if o.kind == "camera" else None, ref_u=CARRY_REF_U)
            got = got_res.fusion.E_u[ij]
            z = (got - o.u_after) / np.hypot(o.u_after_noise, 0.01 * o.u_after)
            after = {c.name: c.p for c in o.carried}
            held = {h[0] for h in got_res.fusion.budget.model.held}
            for c in p.carried:
                if after.get(c.name, 0.0) < 0.5:
                    agree.append(c.name not in held)
            rows.append(z)
            best = p.best is not None and o.action == p.best.action
            print(f"seed {seed}: {o.action}{' (advised)' if best else ''}: {p.target} "
                  f"u {p.u_before / ARCSEC:.3f}″ -> predicted {o.u_after / ARCSEC:.3f} ± "
                  f"{o.u_after_noise / ARCSEC:.3f}″ (carried {after}), obtained "
                  f"{got / ARCSEC:.3f}″ (carried {sorted(held)}), z {z:+.2f}")
    z = np.array(rows)
    print(f"{len(z)} rows: RMS z {np.sqrt(np.mean(z**2)):.2f}, max |z| {np.abs(z).max():.2f}; "
          f"'likely no longer carried' right in {sum(agree)} of {len(agree)}")
    assert len(refused) <= 2, refused  # most seeds planned: the rows below are the test
    assert np.abs(z).max() <= 3.5, z
    assert 0.4 <= np.sqrt(np.mean(z**2)) <= 1.4, z
    assert sum(agree) >= 0.8 * len(agree), agree


def user16_generator():
    """Independent user 16's generator (``tests/imaging/user16_inputs.py``)."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "imaging" / "user16_inputs.py"
    if "user16_inputs" not in sys.modules:
        spec = importlib.util.spec_from_file_location("user16_inputs", path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules["user16_inputs"] = mod
        spec.loader.exec_module(mod)
    return sys.modules["user16_inputs"]


def loop_model(res) -> tuple[frozenset, frozenset]:
    """The loop's effects and the candidates carried as not excluded, by name."""
    d = res.fusion.to_dict()
    carried = {c["source"].split(NOT_EXCLUDED_TAG)[0].strip()
               for a in d["budget"]["angles"].values() for c in a["contributions"]
               if NOT_EXCLUDED_TAG in c["source"]}
    return frozenset(e["name"] for e in d["effects"]), frozenset(carried)


def one_more_image(g, folder, truth, E, housing, view, seed):
    """One more image of ``housing`` in ``view`` rendered as the user's generator renders a
    session's (same roll, same E), entered in session.toml."""
    c, r, up = g.VIEWS[view]
    rng = np.random.default_rng(seed)
    ang = g.image_angle_deg(g.axes(E)[housing], np.array(r, float), np.array(up, float),
                            truth["roll_arcsec"][c] * ARCSEC)
    m = g.random_mark(g.MICRO, rng, where="centre")
    # straight, as write_session draws them (its sagitta 0: random_mark bends a third)
    m = replace(m, angle_deg=ang, sagitta=0.0,
                length=min(m.length, 0.45 * min(g.MICRO.width, g.MICRO.height)))
    p = g.save(g.MICRO, g.render_marks(g.MICRO, [m], rng), folder / f"{housing}_{view}_more")
    nominal = "horizontal" if housing in ("x", "y") else "vertical"
    t = (folder / "session.toml").read_text()
    i = t.index("[tolerance]")
    (folder / "session.toml").write_text(
        t[:i] + f'[[images]]\nfile = "{p.name}"\nhousing = "{housing}"\nview = "{view}"\n'
        f'nominal = "{nominal}"\n\n' + t[i:])


USER16_E = {"E_xY": 10.0, "E_xZ": 28.0, "E_yX": -5.0, "E_yZ": 20.0, "E_zX": -15.0,
            "E_zY": 5.0}
"""User 16's sessions' true misalignment [″]."""


def user16_one_more_image_z(folder, seeds) -> tuple[np.ndarray, int, int]:
    """Every "another image" option the plan ranks in user 16's sessions of ``seeds`` (two
    microscope cameras, their reversal views, marks near the centre, no lens declared),
    realised with the user's generator: z = (obtained - predicted) / stated noise of u of the
    critical angle, one row each (printed); the rows whose run changed the loop's model, and
    the sessions not ok (no plan), counted. ``folder``: a scratch directory."""
    import shutil

    g = user16_generator()
    E = {k: v * ARCSEC for k, v in USER16_E.items()}
    keys = {"lens_k1": 0, "lens_k2": 0, "lens_p": 0, "lens_aspect": 0, "lens_pp_px": 0}
    z, changed, not_ok = [], 0, 0
    for seed in seeds:
        base = folder / f"s{seed}"
        truth = g.write_session(base, seed, {"A": g.MICRO, "B": g.MICRO}, E=E,
                                where="centre", lens_keys={"A": keys, "B": keys},
                                tolerance_arcsec=30)
        res = run_session(load_session(base))
        if not res.ok:
            not_ok += 1
            continue
        p = plan(res.fusion.budget.model, res.disposition().to_dict())
        i, j = E_INDEX[E_NAMES.index(p.target)]
        model = loop_model(res)
        for n, o in enumerate(p.options):
            if o.kind != "image":
                continue
            more = folder / f"s{seed}_{n}"
            shutil.copytree(base, more)
            one_more_image(g, more, truth, E, o.detail["housing"], o.detail["view"],
                           1000 + 17 * seed + n)
            r2 = run_session(load_session(more))
            if loop_model(r2) != model:
                changed += 1
                continue
            got = r2.fusion.E_u[i, j]
            z.append((got - o.u_after) / o.u_after_noise)
            print(f"user16 seed {seed}: {o.action}: {p.target} u {p.u_before / ARCSEC:.3f}″ -> "
                  f"predicted {o.u_after / ARCSEC:.3f} ± {o.u_after_noise / ARCSEC:.3f}″, "
                  f"obtained {got / ARCSEC:.3f}″ (z {z[-1]:+.2f})")
    z = np.array(z)
    print(f"user16: {len(z)} rows ({changed} changed the model, {not_ok} sessions not ok): "
          f"mean z {z.mean():+.2f}, RMS z {np.sqrt(np.mean(z**2)):.2f}, max |z| "
          f"{np.abs(z).max():.2f}")
    return z, changed, not_ok


@pytest.mark.slow
def test_one_more_image_of_user16s_cameras_is_predicted_without_bias(tmp_path):
    """User 16 (two microscope cameras, each image's u 2.5-7.6″: its mark 256-461 px long):
    'align plan' predicted one more image's u too high (31.7 ± 5.8″ where 19.6″ came). Every
    "another image" option of seeds 4, 7, 11 (the ok ones of 4-13) realised with the user's
    generator, straight as the session's (its sagitta 0; random_mark bends a third, whose
    run gained nothing: mean z +0.78): z = (obtained - predicted) / stated noise on the
    critical angle. With the mean own u² (before) the 9 rows' mean z was -1.62, RMS 2.21;
    with the mean information -0.62, 1.11; with the new image straight and the noise its
    predictive interval (Student's t, the secant) +0.06, 0.69. Bound: 9 N(0, 1) draws have a
    mean within ±1.0 (3 SD) and an RMS within 0.4-1.6. A row whose run changed the loop's
    model (an effect estimated before, carried or dropped after) is not a prediction of the
    linearisation: left out, and counted."""
    z, changed, not_ok = user16_one_more_image_z(tmp_path, (4, 7, 11))
    assert not_ok == 0
    assert len(z) >= 8 and changed <= 2, (z, changed)
    assert abs(z.mean()) < 1.0 and 0.4 < np.sqrt(np.mean(z**2)) < 1.6, z
