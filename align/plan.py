"""What to measure next: the added measurement that lowers u of the critical angle most per
minute of work, predicted from the fused solve's linearisation (:mod:`align.fusion.budget`).

The critical angle is the one nearest to (or furthest beyond) its acceptance limit (smallest
margin − guard band of the disposition), or, without a tolerance, the one with the largest u.
Each option is a hypothetical change of the observations, with the noise of the existing ones
of that kind; its information is added to the session's and the new information inverted:

* another image of a housing in a view: the expected image of that camera (:func:`expected_image`):
  the Jacobian of that housing in that view, coupled to the camera's lens errors as its images
  are (a lens they share does not average down), and the mean own u² of the camera's images
  (what each image reads from itself — noise, groove profile, background — is a new draw);
* a reversed view (the platform turned 180° on the table, the same camera): the view's rows with
  the sign of their dependence on E flipped and that on the camera's roll kept — what separates
  a roll from E — each an expected image of the camera;
* a goniometer log twice as long: the log's covariance without its Type B terms halved (more
  revolutions average the scatter, not a bound);
* a second tumble (as many poses again): the calibration's covariance halved;
* the platform static poses repeated: their covariance halved;
* a calibrated camera (only when the loop estimated its roll): the roll known to
  ±``CAMERA_ROLL_U_ARCSEC``.

Each prediction carries its noise (:func:`prediction_noise`): the new data's own u is not
known before they are taken. When no option's gain exceeds ``NOISE_K`` times it, the plan says
that no measurement improves the angle by more than the noise of its prediction.

Minutes per option are the documented defaults ``MINUTES`` (a site changes them in code or by
keyword). The prediction is first order in the data (the linearisation does not move) and keeps
the nuisances the loop chose; a new view may let the loop choose differently.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import)

from align.errors import InputError
from align.fusion.budget import Group, Linearisation, inverse
from align.fusion.observations import E_NAMES, LEVEL, REF, ROLL, TILT
from align.fusion.plausible import is_carried
from align.loop import sidak
from align.session_json import LoadedSession
from axisbase.units import ARCSEC

FORMAT_VERSION = 1
MINUTES = {
    "image": 2.0,           # re-seat the camera on a housing, focus, shoot
    "reversed view": 10.0,  # turn the platform 180° and re-level (plus its images)
    "gonio": 15.0,          # a log as long again
    "tumble": 15.0,         # 14 more poses at ~1 min each
    "static": 10.0,         # the 8 platform poses again
    "camera": 30.0,         # a roll calibration of one camera (plumb line or level target)
}
"""Work per option [min], defaults."""
MIN_GAIN = 1e-3
"""An option lowering u by less than this fraction is not listed (it does not matter)."""
RESTATED_U_NOISE = {"gonio": 0.15, "static": 0.03, "tumble": 0.01}
"""Relative standard deviation of the u a repeated measurement of that kind will *state*
about the u predicted for it — dimensionless. Its u is estimated from its own data again:
the goniometer's from the new log's phase path and quantisation (which averages faster than
1/√n on some logs: the prediction is then high), the static poses' from their samples'
scatter, the tumble's from its fit's residuals. Measured by simulation (predicted/obtained
over seeds, ``tests/align/test_plan.py``, docs/decision.md): log twice as long SD 0.08–0.16,
static poses repeated 0.02, second tumble 0.002."""
NOISE_K = 2.0
"""A gain below ``NOISE_K`` standard deviations of its prediction is not promised: the plan
says no measurement improves the angle by more than the prediction's noise."""
CAMERA_ROLL_U_ARCSEC = 2.0
"""Standard uncertainty [″] of a camera roll after its calibration (a plumb-line image: the
roll to ~1–3″)."""
RESOLVES = {
    ROLL: "a reversed view of that camera (the platform turned 180° on the table), or its "
          "roll calibrated",
    LEVEL: "levelled static poses with the platform inverted (Z down) as well as Z up, or "
           "camera views of E_xZ, E_yZ: they separate the levelling from E",
    TILT: "levelled static poses at more table angles (the table's tilt turns with it, the "
          "platform's axes do not)",
    REF: "a goniometer log with the reference face's offset known (declared in session.toml)",
}
"""What separates each kind of candidate from E when no measurement of the plan's kinds
does (by the observation equations, align/fusion/observations.py); unit —."""


@dataclass(frozen=True)
class Carried:
    """A candidate E's u carries as not excluded (:mod:`align.fusion.plausible`), as the
    linearisation predicts it for some data.

    Attributes
    ----------
    name : str
        The candidate (``platform_level``, ``camera_roll[A]``); unit —.
    estimate, u : float
        Its size when freed and that size's u [rad].
    shift : tuple of float
        The shift of the six angles (``E_NAMES``) when it is freed: its Type B share of u² is
        its square [rad].
    p : float
        The probability that the fusion carries it (its estimate on the new data a new draw
        about the one now, :func:`predict`); 1 for the session's own data — dimensionless.
    named : float
        The probability that the new data make it significant at the loop's level: named, E
        corrected for it, its share of u² that of freeing it — dimensionless.
    share : tuple of float
        Its expected share of u² of the six angles (``shift²`` × carried, over the draws)
        [rad²].
    """

    name: str
    estimate: float
    u: float
    shift: tuple[float, ...]
    p: float = 1.0
    share: tuple[float, ...] = (0.0,) * 6
    named: float = 0.0

    def to_dict(self) -> dict:
        return {"name": self.name, "estimate_arcsec": self.estimate / ARCSEC,
                "u_arcsec": self.u / ARCSEC, "p_carried": self.p,
                "shift_arcsec": dict(zip(E_NAMES, (v / ARCSEC for v in self.shift),
                                         strict=True))}

    @property
    def label(self) -> str:
        return f"{self.name} not excluded ({self.estimate / ARCSEC:+.1f} ± {self.u / ARCSEC:.1f}″)"


NAMED_ALPHA = 1e-3
"""The fusion loop's level (``align.fusion.fuse``'s ``alpha``): a candidate whose χ² drop
passes it (Šidák over ``NAMED_TESTED`` candidates) and lowers BIC by ``NAMED_MIN_BIC`` is
named, not carried — dimensionless."""
NAMED_TESTED = 5
"""Candidates a fusion round tests (two cameras' rolls, the reference face's offset, the
table's tilt, the platform's levelling) — dimensionless."""
NAMED_MIN_BIC = 6.0
"""The loop's least BIC drop (``run_loop``'s ``min_delta_bic``) — dimensionless."""
REDRAWS = 256
"""Draws of a carried candidate's estimate on the new data (:func:`predict`): the share's
mean to ~3 % of itself at p = 0.5, fixed (seed 0) so that a plan is reproducible."""


@dataclass(frozen=True)
class Prediction:
    """u of the six angles as the fusion would state them after a measurement.

    Attributes
    ----------
    u : numpy.ndarray
        The expected u (√ of the expected u²) of the six angles, ``E_NAMES`` order [rad].
    u_sd : numpy.ndarray
        The standard deviation of that u over the draws of the carried candidates' new
        estimates [rad] (0 without carried candidates).
    carried : tuple of Carried
        The session's carried candidates with the probability each stays carried; unit —.
    """

    u: np.ndarray
    u_sd: np.ndarray
    carried: tuple[Carried, ...]

    def still(self, name: str) -> bool:
        """Whether ``name`` is more likely carried than not after the measurement."""
        return any(c.name == name and c.p >= 0.5 for c in self.carried)


def _named(drop: float, tested: float, width: int, n_rows: int) -> bool:
    """Whether the fusion loop would name a candidate whose freeing lowers χ² by ``drop``
    (``width`` components, ``n_rows`` observations; ``tested``: the drop its test sees, on
    the χ²(``width``) scale): its test at the loop's level after Šidák over the round's
    candidates, and its BIC drop."""
    return bool(sidak(float(special.chdtrc(width, tested)), NAMED_TESTED) < NAMED_ALPHA
                and drop - width * np.log(n_rows) > NAMED_MIN_BIC)


def _with_declared(info: np.ndarray, free: Sequence[int], idx: Sequence[int], b: np.ndarray,
                   declared: Sequence[tuple[Sequence[int], Sequence[float]]]) -> np.ndarray:
    """Candidate ``b`` [rad] (parameters ``idx``) estimated with each ``declared`` candidate
    (its indices, its value [rad]) fixed at its value instead of 0: with the ``free``
    parameters marginalised (the Schur complement M of ``info``), b(r) = b(0) − M_bb⁻¹ M_br r."""
    for didx, value in declared:
        j = [*free, *idx, *didx]
        n, w = len(free), len(idx)
        Ij = info[np.ix_(j, j)]
        M = Ij[n:, n:] - Ij[n:, :n] @ np.linalg.solve(Ij[:n, :n], Ij[:n, n:])
        b = b - np.linalg.solve(M[:w, :w], M[:w, w:] @ np.asarray(value))
    return b


def predict(lin: Linearisation, add: Sequence[Group] = (), drop: Sequence[str] = (),
            redraw: bool = True, declared: Sequence[str] = ()) -> Prediction:
    """u of the six angles as the fusion would state them with the groups named in ``drop``
    left out and ``add`` added, and the candidates it would carry.

    Each candidate the session's fusion carries (``lin.held``) is freed in the linearisation:
    with (E, b) of covariance Σ, freeing b moves E by k b̂ (k = Σ_Eb Σ_bb⁻¹) and lowers χ² by
    b̂ᵀ Σ_bb⁻¹ b̂. The new estimate b̂' is not known before the data are taken: it is drawn
    about b̂ with the covariance of b̂ − b̂' — the added data's draw, the dropped (replaced)
    data's, and the change of the kept data's weights (for data only added: Σ_bb − Σ'_bb;
    ``redraw`` False: b̂' = b̂). In each draw the candidate is named when the loop's test
    would take it (:func:`_named`; its share of u² then what freeing it adds), else carried
    when the fusion's own rule says so (:func:`align.fusion.plausible.is_carried`; its share
    (k b̂')²), else dropped; u² is the fixed model's plus the mean share. New data that
    separate b from E shrink k: the shift falls below u/2 and the term drops. A candidate
    more likely named than not is in the model against which the less significant ones are
    judged (the loop adds the best first), as is one ``declared`` (a camera's roll
    calibrated: no longer a candidate, E corrected for it at its estimate) — what it absorbed
    is no longer left for the others, whose estimates move with it (:func:`_with_declared`)."""
    kept = [g for g in lin.groups if g.source not in drop]
    infos = (lin.information([*kept, *add]), lin.information(), lin.information(kept),
             lin.information(add))
    free = list(lin.free)
    n_rows = sum(len(g.A) for g in [*kept, *add])
    u2 = np.diag(inverse(infos[0][np.ix_(free, free)]))[:6] * lin.inflation**2
    fixed = [(i, e) for n, i, e, _ in lin.held if n in declared]
    share = np.zeros((REDRAWS, 6))
    out = []
    own = not add and not drop  # the session's own data: the fusion decided (not re-judged)
    for name, idx, est, p_loop in sorted((h for h in lin.held if h[0] not in declared),
                                         key=lambda h: h[3]):
        # what the session's data left for it once the others are in the model
        c, mine = _one(infos, free, idx, _with_declared(infos[1], free, idx, np.array(est),
                                                        fixed),
                       p_loop, np.sqrt(u2), n_rows, redraw, own, lin.inflation)
        out.append(replace(c, name=name))
        share += mine
        if c.named >= 0.5:
            fixed.append((idx, est))
    u = np.sqrt(u2 + share)
    order = [h[0] for h in lin.held]
    return Prediction(np.sqrt(u2 + share.mean(0)), u.std(0),
                      tuple(sorted(out, key=lambda c: order.index(c.name))))


def _one(infos: tuple[np.ndarray, ...], free: list[int], idx: Sequence[int], b: np.ndarray,
         p_loop: float, u_e: np.ndarray, n_rows: int, redraw: bool, own: bool,
         inflation: float) -> tuple[Carried, np.ndarray]:
    """One held candidate (parameters ``idx``, estimate ``b`` [rad], the loop's p-value now
    ``p_loop``) after the measurement (``infos``: the information after, now, of the kept
    groups, of the added ones): its :class:`Carried` (unnamed) and its share of u² of the
    six angles in each draw [rad²]."""
    info, info_now, info_kept, info_add = infos
    j, n = [*free, *idx], len(free)
    C = inverse(info[np.ix_(j, j)])
    Cbb = C[n:, n:]
    K = C[:6, n:] @ np.linalg.inv(Cbb)
    # b̂ = Σ_b Σ_g A_gᵀ C_g⁻¹ y_g: the kept data's gain changes, the rest are new draws
    ix = np.ix_(j, j)
    S0, S1 = inverse(info_now[ix])[n:], C[n:]
    d = ((S0 - S1) @ info_kept[ix] @ (S0 - S1).T
         + S0 @ (info_now - info_kept)[ix] @ S0.T + S1 @ info_add[ix] @ S1.T)
    w, v = np.linalg.eigh((d + d.T) / 2 if redraw else 0 * d)
    z = np.random.default_rng(0).standard_normal((REDRAWS, len(b)))
    draws = b + z @ (v * np.sqrt(np.clip(w, 0.0, None))).T
    chi = np.einsum("ij,ij->i", draws, np.linalg.solve(Cbb, draws.T).T)
    # the loop's test is not χ²(w) on the drop (it divides by the fit's χ²/dof, its
    # weights are estimated): its p-value now fixes the scale of the drop it sees
    now_drop = float(b @ np.linalg.solve(S0[:, n:], b))
    scale = max(1.0, now_drop / float(special.chdtri(len(idx), max(p_loop, 1e-300))))
    named = np.array([_named(c, c / scale, len(idx), n_rows) for c in chi])
    hit = ~named & np.array([is_carried(c, len(idx), float(np.linalg.norm(x)), K @ x, u_e)
                             for c, x in zip(chi, draws, strict=True)])
    if own:
        hit[:], named[:] = True, False
    freed = np.diag(K @ Cbb @ K.T) * inflation**2  # what naming it adds to u²
    mine = (np.where(hit[:, None], np.square(draws @ K.T), 0.0)
            + np.where(named[:, None], freed, 0.0))
    size = float(np.linalg.norm(b))
    g = b / size if size > 0 else np.full(len(b), np.sqrt(1.0 / len(b)))
    if len(b) == 1:  # one component: its signed value (a vector's one number: its length)
        size, g = float(b[0]), np.ones(1)
    return Carried("", size, float(np.sqrt(g @ Cbb @ g)), tuple(K @ b), float(hit.mean()),
                   tuple(mine.mean(0)), float(named.mean())), mine


@dataclass(frozen=True)
class Option:
    """One measurement to add.

    Attributes
    ----------
    action : str
        What to do; unit —.
    kind : str
        The kind of measurement; unit —.
    minutes : float
        The work it takes [min].
    u_after : float
        u of the critical angle after it [rad].
    u_after_all : tuple of float
        u of all six angles after it, ``E_NAMES`` order [rad].
    detail : Mapping
        What exactly: an image's ``housing`` and ``view``, a reversal's ``view``, a camera's
        ``camera``, a replaced input's ``source``; unit —.
    u_after_noise : float
        Standard deviation of ``u_after`` as a prediction [rad]: the u the new data will state
        is not known before they are taken (a new image's own u is a new draw; a repeated
        log's, poses' or tumble's u is estimated from them again).
    carried : tuple of Carried
        The session's carried candidates as they would be after it, each with the
        probability that it is still carried and its expected share (:func:`predict`);
        unit —.
    """

    action: str
    kind: str
    minutes: float
    u_after: float
    u_after_all: tuple[float, ...]
    detail: Mapping[str, str] = field(default_factory=dict)
    """What exactly: an image's ``housing`` and ``view``, a reversal's ``view``, a
    camera's ``camera``, a replaced input's ``source``."""
    u_after_noise: float = 0.0
    carried: tuple[Carried, ...] = ()

    def to_dict(self, u_before: float) -> dict:
        return {"action": self.action, "kind": self.kind, "minutes": self.minutes,
                "detail": dict(self.detail), "carried_after": {c.name: c.p for c in self.carried},
                "u_after_arcsec": self.u_after / ARCSEC,
                "u_after_noise_arcsec": self.u_after_noise / ARCSEC,
                "u_after_all_arcsec": dict(zip(E_NAMES, (v / ARCSEC for v in self.u_after_all),
                                               strict=True)),
                "gain_arcsec_per_minute": (u_before - self.u_after) / ARCSEC / self.minutes}


@dataclass(frozen=True)
class Plan:
    """What to measure next.

    Attributes
    ----------
    target : str
        The critical angle; unit —.
    why : str
        Why it was chosen; unit —.
    u_before : float
        Its u now [rad].
    options : tuple of Option
        Ranked by the lowering of its u per minute, best first; unit —.
    carried : tuple of Carried
        The candidates E's u carries now as not excluded (included in ``u_before``); unit —.
    resolves : Mapping
        Per carried candidate, the measurement after which it would no longer be carried
        (the best option that does, else what separates that kind from E, ``RESOLVES``);
        unit —.
    """

    target: str
    why: str
    u_before: float
    options: tuple[Option, ...]
    carried: tuple[Carried, ...] = ()
    resolves: Mapping[str, str] = field(default_factory=dict)

    @property
    def best(self) -> Option | None:
        return self.options[0] if self.options else None

    def to_dict(self) -> dict:
        return {"format_version": FORMAT_VERSION, "target": self.target, "why": self.why,
                "u_before_arcsec": self.u_before / ARCSEC, "within_noise": self.within_noise,
                "carried": [dict(c.to_dict(), resolved_by=self.resolves.get(c.name))
                            for c in self.carried],
                "options": [o.to_dict(self.u_before) for o in self.options]}

    @property
    def within_noise(self) -> bool:
        """No option's gain exceeds ``NOISE_K`` standard deviations of its prediction (or
        there is no option at all)."""
        return not any(self.u_before - o.u_after > NOISE_K * o.u_after_noise
                       for o in self.options)

    def lines(self) -> list[str]:
        out = [f"what to measure next for {self.target} ({self.why}; u now "
               f"{self.u_before / ARCSEC:.3f}″):"]
        t = E_NAMES.index(self.target)
        for c in self.carried:
            out.append(f"  its u carries {c.label}: {abs(c.shift[t]) / ARCSEC:.3f}″ of it; "
                       f"resolved by {self.resolves.get(c.name, '?')}")
        if not self.options:
            out.append(f"  no measurement improves {self.target} by more than "
                       f"{100 * MIN_GAIN:g} % of its u (of the kinds known here)")
            return out
        if self.within_noise:
            o = max(self.options, key=lambda o: self.u_before - o.u_after)
            out.append(f"  no measurement improves {self.target} by more than the noise of "
                       f"its prediction: the largest gain, {o.action}, is "
                       f"{(self.u_before - o.u_after) / ARCSEC:.3f}″ ± "
                       f"{o.u_after_noise / ARCSEC:.3f}″ (< {NOISE_K:g} standard deviations)")
        for k, o in enumerate(self.options):
            after = {c.name: c for c in o.carried}
            left = [f"{c.name} (p {after[c.name].p:.2f}; named p {after[c.name].named:.2f})"
                    if c.name in after else f"{c.name} (declared)" for c in self.carried
                    if c.name not in after or after[c.name].p < 0.5]
            out.append(f"  {'->' if k == 0 and not self.within_noise else '  '} {o.action}: "
                       f"u {o.u_after / ARCSEC:.3f} ± {o.u_after_noise / ARCSEC:.3f}″ "
                       f"({100 * (1 - o.u_after / self.u_before):.1f} % lower) in "
                       f"{o.minutes:g} min"
                       + (f"; likely no longer carries {', '.join(left)}" if left else ""))
        return out


def _target(lin: Linearisation, disposition: Mapping | None) -> tuple[str, str]:
    angles = (disposition or {}).get("angles") or []
    if angles:
        a = min(angles, key=lambda a: a["margin_arcsec"] - a["guard_arcsec"])
        why = (f"{disposition['verdict']}, margin {a['margin_arcsec']:+.2f}″, "
               f"guard band {a['guard_arcsec']:.2f}″")
        if a["verdict"] == "FAIL":
            why += ("; it is outside its tolerance by more than the guard band: a smaller u "
                    "leaves it a FAIL")
        return a["name"], why
    u = predict(lin).u
    k = int(np.argmax(u))
    return E_NAMES[k], "no tolerance: the largest u"


def _scaled(g: Group, factor: float) -> Group:
    """The group with its scatter (C less its Type B terms) × ``factor``, its Type B bounds
    kept."""
    B = sum((c for _, c in g.type_b), np.zeros_like(g.C))
    return Group(g.source, g.kind, g.A, (g.C - B) * factor + B, g.type_b, g.meta)


def _halved(g: Group, kind: str) -> Group:
    """The group with its scatter halved (twice the data), its Type B bounds kept; its
    ``meta`` says how far the u the new data will state may differ (``RESTATED_U_NOISE``)."""
    h = _scaled(g, 0.5)
    return Group(h.source, h.kind, h.A, h.C, h.type_b,
                 {**g.meta, "relative_sd": str(2 * RESTATED_U_NOISE[kind])})


def prediction_noise(lin: Linearisation, add: Sequence[Group], drop: Sequence[str]
                     ) -> np.ndarray:
    """Standard deviation [rad] of the six predicted u after adding ``add`` (and dropping
    ``drop``), from the scatter of the added groups' own variances: each added group's
    ``meta['relative_sd']`` is the relative standard deviation of its scatter variance (a
    new image's own u² about its camera's mean; a repeated input's u² about the halved one).
    First order: the derivative of u with respect to each group's log-variance, by a 5 %
    step (u² is smooth in it), times that relative SD, in quadrature over the groups (their
    draws are independent)."""
    u = predict(lin, add, drop, redraw=False).u
    var = np.zeros_like(u)
    for i, g in enumerate(add):
        rel = float(g.meta.get("relative_sd", 0.0))
        if rel <= 0:
            continue
        step = 0.05
        moved = [*add[:i], _scaled(g, 1 + step), *add[i + 1:]]
        du = (predict(lin, moved, drop, redraw=False).u - u) / np.log1p(step)
        var += (du * rel) ** 2
    return np.sqrt(var)


def _own_var(g: Group) -> float:
    """An image row's own variance [rad²]: its u² less what the camera's lens shares (the lens
    is carried as parameters the row is coupled to through its Jacobian, budget.linearise)."""
    return float(g.C[0, 0])


def image_noise(images: Sequence[Group]) -> float:
    """The relative standard deviation of one image's own variance about its camera's mean,
    pooled over the cameras with ≥ 2 images (each image's u carries terms read from that image
    — its groove profile, its background — that scatter from image to image); 1 when no camera
    has two images (the scatter is then unknown: taken as large as the variance itself).
    Dimensionless."""
    cams: dict[str, list[float]] = {}
    for g in images:
        cams.setdefault(g.meta.get("camera", "?"), []).append(_own_var(g))
    r2, dof = 0.0, 0
    for v in cams.values():
        if len(v) > 1:
            r2 += float(np.sum((np.asarray(v) / np.mean(v) - 1) ** 2))
            dof += len(v) - 1
    return float(np.sqrt(r2 / dof)) if dof else 1.0


def expected_image(g: Group, images: Sequence[Group], source: str, A: np.ndarray | None = None
                   ) -> Group:
    """One more image like ``g`` (its housing, its view, its camera): the expected row.

    Its Jacobian is the mean of the rows of that housing in that view (``A`` overrides it: a
    reversed view's): the angle's dependence on E and the camera's roll, and its coupling to
    the camera's lens parameters — a lens error common to the camera's images does not
    average down with more of them, and the new row shares it. Its own variance is the mean of
    the camera's images' own variances: the terms each image reads from itself (noise, groove
    profile, background) are new draws for a new image, whose expectation is their mean, not
    the value of the one image copied.
    """
    cam = g.meta.get("camera")
    same = [h for h in images if (h.meta.get("housing"), h.meta.get("view"))
            == (g.meta.get("housing"), g.meta.get("view"))] or [g]
    own = [_own_var(h) for h in images if h.meta.get("camera") == cam] or [_own_var(g)]
    A = np.mean([h.A for h in same], axis=0) if A is None else A
    rel = image_noise(images) * np.sqrt(1 + 1 / len(own))  # a new draw; the mean's own error
    return Group(source, "image", A, np.array([[float(np.mean(own))]]), (),
                 {**g.meta, "relative_sd": str(rel)})


def options(lin: Linearisation, minutes: Mapping[str, float] = MINUTES,
            camera_roll_u: float = CAMERA_ROLL_U_ARCSEC * ARCSEC
            ) -> list[tuple[str, str, float, list[Group], list[str], dict[str, str]]]:
    """The hypothetical measurements: (action, kind, minutes, groups to add, sources to
    drop, detail). ``camera_roll_u`` [rad]: the u of a camera roll after its calibration."""
    out = []
    images = [g for g in lin.groups if g.kind == "image"]
    seen = set()
    for g in images:
        key = (g.meta.get("housing"), g.meta.get("view"))
        if key in seen:
            continue
        seen.add(key)
        out.append((f"another image of housing {key[0]} in view {key[1]} (camera "
                    f"{g.meta.get('camera', '?')})", "image", minutes["image"],
                    [expected_image(g, images, f"image {key[0]} in {key[1]} (again)")], [],
                    {"housing": str(key[0]), "view": str(key[1])}))
    views: dict[str, list[Group]] = {}
    for g in images:
        views.setdefault(g.meta.get("view", "?"), []).append(g)
    for view, gs in views.items():
        flipped = []
        for g in gs:
            A = g.A.copy()
            A[:, :6] *= -1
            flipped.append(expected_image(g, images, g.source + " (reversed)", A))
        exists = all(any(np.allclose(f.A, h.A, rtol=1e-3, atol=1e-9 * np.abs(f.A).max())
                         for h in images) for f in flipped)
        if not exists:
            out.append((f"a reversed view of {view} (the platform turned 180° on the table, "
                        f"the same camera; {len(gs)} images)", "reversed view",
                        minutes["reversed view"] + len(gs) * minutes["image"], flipped, [],
                        {"view": view}))
    for g in lin.groups:
        if g.kind == "gonio":
            out.append((f"a log twice as long ({g.source})", "gonio", minutes["gonio"],
                        [_halved(g, "gonio")], [g.source], {"source": g.source}))
        elif g.kind == "calibration":
            out.append(("a second tumble (as many poses again)", "tumble", minutes["tumble"],
                        [_halved(g, "tumble")], [g.source], {"source": g.source}))
        elif g.kind == "static":
            out.append(("the platform static poses repeated", "static", minutes["static"],
                        [_halved(g, "static")], [g.source], {"source": g.source}))
    rolls = [(label[len("camera roll "):], idx) for label, idx in lin.nuisances
             if label.startswith("camera roll ")]
    # a roll the fusion carries as not excluded: calibrating it resolves it
    rolls += [(name[len(ROLL) + 1:-1], idx) for name, idx, *_ in lin.held
              if name.startswith(ROLL + "[")]
    for cam, idx in rolls:
        A = np.zeros((1, len(lin.params)))
        A[0, idx[0]] = 1.0
        out.append((f"calibrate camera {cam}'s roll (to ±{camera_roll_u / ARCSEC:g}″)",
                    "camera", minutes["camera"],
                    [Group(f"camera {cam} roll calibration", "calibration", A,
                           np.array([[camera_roll_u ** 2]]))], [],
                    {"camera": cam}))
    return out


def _resolution(c: Carried, every: Sequence[Option], k: int) -> str:
    """What resolves carried candidate ``c``: the best option (``every``, best first) after
    which it is more likely not carried; else the one that lowers its share of angle ``k``
    most (to less than half), saying so; else what separates its kind from E."""
    def after(o: Option) -> Carried | None:
        return next((a for a in o.carried if a.name == c.name), None)

    o = next((o for o in every if (after(o) is None or after(o).p < 0.5)), None)
    if o is not None:
        return o.action
    o = min(every, key=lambda o: after(o).share[k], default=None)
    if o is not None and after(o).share[k] < c.share[k] / 4:
        return (f"{o.action} (its share of {E_NAMES[k]} {np.sqrt(c.share[k]) / ARCSEC:.2f}"
                f" -> {np.sqrt(after(o).share[k]) / ARCSEC:.2f}″)")
    return RESOLVES.get(c.name.partition("[")[0], "a measurement that separates it from E")


def plan(lin: Linearisation, disposition: Mapping | None = None,
         minutes: Mapping[str, float] = MINUTES,
         camera_roll_u: float = CAMERA_ROLL_U_ARCSEC * ARCSEC) -> Plan:
    """Rank the options of :func:`options` for the critical angle of ``disposition`` (the
    session result's ``disposition`` dict, or None); ``camera_roll_u`` [rad] as there."""
    target, why = _target(lin, disposition)
    k = E_NAMES.index(target)
    now = predict(lin)
    u0 = now.u
    ranked, every = [], []
    for action, kind, mins, add, drop, detail in options(lin, minutes, camera_roll_u):
        # a camera's roll calibrated is declared: no longer a candidate (session.toml)
        declared = [f"{ROLL}[{detail['camera']}]"] if kind == "camera" else []
        after = predict(lin, add, drop, declared=declared)
        u = after.u
        o = Option(action, kind, mins, float(u[k]), tuple(map(float, u)), detail,
                   float(np.hypot(prediction_noise(lin, add, drop)[k], after.u_sd[k])),
                   after.carried)
        every.append(o)
        if u[k] < u0[k] * (1 - MIN_GAIN):
            ranked.append(o)
    ranked.sort(key=lambda o: -(u0[k] - o.u_after) / o.minutes)
    every.sort(key=lambda o: -(u0[k] - o.u_after) / o.minutes)
    resolves = {c.name: _resolution(c, every, k) for c in now.carried}
    return Plan(target, why, float(u0[k]), tuple(ranked), now.carried, resolves)


def plan_from_result(js: Mapping | LoadedSession, where: str = "the result") -> Plan:
    """:func:`plan` from a session result (``align run --json``; its JSON is read by the one
    reader, :class:`~align.session_json.LoadedSession`)."""
    r = js if isinstance(js, LoadedSession) else LoadedSession.from_dict(js, where)
    if not r.ok or r.verdict == "NOT MEASURED":
        failed = [e.stage for e in r.errors]
        raise InputError(f"{r.where}: the session was NOT MEASURED (not ok"
                         + (f": {', '.join(failed)} failed" if failed else "")
                         + "): its u are not a basis for planning; fix what failed (its "
                         "warnings and errors say what) and run it again")
    b = r.budget
    if not r.fused or not b or not b.get("model"):
        raise InputError(f"{r.where}: no fused misalignment with its budget (a failed session, "
                         "or a result written before budgets existed): nothing to plan from")
    return plan(Linearisation.from_dict(b["model"]), r.disposition)
