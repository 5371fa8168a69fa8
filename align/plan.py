"""What to measure next: the added measurement that lowers u of the critical angle most per
minute of work, predicted from the fused solve's linearisation (:mod:`align.fusion.budget`).

The critical angle is the one nearest to (or furthest beyond) its acceptance limit (smallest
margin − guard band of the disposition), or, without a tolerance, the one with the largest u.
Each option is a hypothetical change of the observations, with the noise of the existing ones
of that kind; its information is added to the session's and the new information inverted:

* another image of a housing in a view: the expected image of that camera (:func:`expected_image`):
  the Jacobian of that housing in that view, coupled to the camera's lens errors as its images
  are (a lens they share does not average down), and the mean information 1/u² of the
  camera's images (what each image reads from itself — noise, groove profile, background —
  is a new draw);
* a reversed view (the platform turned 180° on the table, the same camera): the view's rows with
  the sign of their dependence on E flipped and that on the camera's roll kept — what separates
  a roll from E — each an expected image of the camera;
* a goniometer log twice as long: the log's covariance without its Type B terms halved (more
  revolutions average the scatter, not a bound);
* a second tumble (as many poses again): the calibration's covariance halved;
* the platform static poses repeated: their covariance halved;
* a calibrated camera (when the loop estimated its roll, or carries it as not excluded or
  over its plausible range): the roll known to ±``CAMERA_ROLL_U_ARCSEC``;
* the X/Y-up static poses, an azimuth datum (when the reference face's offset is carried over
  its plausible range and the session has levelled static poses, whose noise they share).

The nuisances the fusion cannot determine (``Linearisation.ranged``) are carried over their
plausible range before and after: each option's information gives their new u freed and E
shift (:func:`align.plan_carried.ranged_after`), so an option that separates one from E
(a reversal view, a roll calibration, the azimuth datum) drops or narrows its term.

The candidates the fusion carries as not excluded are part of u before and after: each
option's prediction includes them as they would be after it (:mod:`align.plan_carried`), and
the plan names, per carried candidate, the measurement that resolves it.

Each prediction carries its noise (:func:`prediction_noise`): the new data's own u is not
known before they are taken; half the width of u's 68 % predictive interval, the image of
the new data's information's (for an image Student's t over the camera's images' scatter,
:func:`image_interval`). When no option's gain exceeds ``NOISE_K`` times it, the plan says
that no measurement improves the angle by more than the noise of its prediction.

Minutes per option are the documented defaults ``MINUTES`` (a site changes them in code or by
keyword). The prediction is first order in the data (the linearisation does not move) and keeps
the nuisances the loop chose; a new view may let the loop choose differently.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from align.errors import InputError
from align.fusion.budget import Group, Linearisation
from align.fusion.observations import E_NAMES, REF, ROLL
from align.fusion.undetermined import Undetermined
from align.plan_carried import RESOLVES, Carried, predict
from align.session_json import LoadedSession
from axisbase.units import ARCSEC

FORMAT_VERSION = 1
MINUTES = {
    "image": 2.0,           # re-seat the camera on a housing, focus, shoot
    "reversed view": 10.0,  # turn the platform 180° and re-level (plus its images)
    "gonio": 15.0,          # a log as long again
    "tumble": 15.0,         # 14 more poses at ~1 min each
    "static": 10.0,         # the 8 platform poses again
    "datum": 5.0,           # the 4 side poses (X up, X down, Y up, Y down)
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
    ranged : tuple of Undetermined
        The undetermined nuisances the fusion would still carry over their plausible range
        after it, with their shift then (:func:`align.plan_carried.ranged_after`); unit —.
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
    ranged: tuple[Undetermined, ...] = ()

    def to_dict(self, u_before: float) -> dict:
        return {"action": self.action, "kind": self.kind, "minutes": self.minutes,
                "detail": dict(self.detail), "carried_after": {c.name: c.p for c in self.carried},
                "undetermined_after": [r.name for r in self.ranged],
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
        Per carried candidate and undetermined nuisance, the measurement after which it would
        no longer be carried (the best option that does, else what separates that kind from
        E, ``RESOLVES``, or the nuisance's ``measure``); unit —.
    ranged : tuple of Undetermined
        The nuisances the data cannot determine, carried over their plausible range (included
        in ``u_before``, :mod:`align.fusion.undetermined`); unit —.
    """

    target: str
    why: str
    u_before: float
    options: tuple[Option, ...]
    carried: tuple[Carried, ...] = ()
    resolves: Mapping[str, str] = field(default_factory=dict)
    ranged: tuple[Undetermined, ...] = ()

    @property
    def best(self) -> Option | None:
        return self.options[0] if self.options else None

    def to_dict(self) -> dict:
        return {"format_version": FORMAT_VERSION, "target": self.target, "why": self.why,
                "u_before_arcsec": self.u_before / ARCSEC, "within_noise": self.within_noise,
                "carried": [dict(c.to_dict(), resolved_by=self.resolves.get(c.name))
                            for c in self.carried],
                "undetermined": [dict(r.to_dict(), resolved_by=self.resolves.get(r.name))
                                 for r in self.ranged],
                "options": [o.to_dict(self.u_before) for o in self.options]}

    @property
    def within_noise(self) -> bool:
        """No option's gain exceeds ``NOISE_K`` standard deviations of its prediction (or
        there is no option at all)."""
        return not any(self.u_before - o.u_after > NOISE_K * o.u_after_noise
                       for o in self.options)

    def _negligible(self, share: float) -> bool:
        """A term whose removal would lower the target's u by less than ``MIN_GAIN`` of it
        (``share`` [rad]: its shift of the target): not worth a line (its JSON entry stays)."""
        u = self.u_before
        return u - np.sqrt(max(u**2 - share**2, 0.0)) < MIN_GAIN * u

    def lines(self) -> list[str]:
        out = [f"what to measure next for {self.target} ({self.why}; u now "
               f"{self.u_before / ARCSEC:.3f}″):"]
        t = E_NAMES.index(self.target)
        for c in self.carried:
            if self._negligible(c.shift[t]):
                continue
            out.append(f"  its u carries {c.label}: {abs(c.shift[t]) / ARCSEC:.3f}″ of it; "
                       f"resolved by {self.resolves.get(c.name, '?')}")
        for r in self.ranged:
            if self._negligible(r.shift[t]):
                continue
            out.append(f"  its u carries {r.label}: {abs(r.shift[t]) / ARCSEC:.3f}″ of it; "
                       f"resolved by {self.resolves.get(r.name, r.measure)}")
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
            left += [f"{r.name} (undetermined)" for r in self.ranged
                     if r.name not in {a.name for a in o.ranged}]
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
    ``drop``): half the width of their predictive interval over the draws of the added groups'
    information. Each added group's ``meta['relative_sd']`` is the half-width of the
    predictive interval of its information (1 / its scatter variance) relative to the one
    predicted (a new image's about its camera's mean, :func:`expected_image`; a repeated
    input's about the halved one). u after is monotone in each group's information, so the
    interval's ends map to u's exactly (the secant, not the tangent: an image's information
    scatters by 70-140 % of itself on user 16's cameras, where u is far from linear in it);
    an end at no information is the group not added. The groups' draws are independent:
    their half-widths in quadrature."""
    u = predict(lin, add, drop, redraw=False).u
    var = np.zeros_like(u)
    for i, g in enumerate(add):
        rel = float(g.meta.get("relative_sd", 0.0))
        if rel <= 0:
            continue
        rest = [*add[:i], *add[i + 1:]]
        more = predict(lin, [*rest, _scaled(g, 1 / (1 + rel))], drop, redraw=False).u
        less = predict(lin, [*rest, *([_scaled(g, 1 / (1 - rel))] if rel < 1 else [])], drop,
                       redraw=False).u
        var += ((less - more) / 2) ** 2
    return np.sqrt(var)


def _own_var(g: Group) -> float:
    """An image row's own variance [rad²]: its u² less what the camera's lens shares (the lens
    is carried as parameters the row is coupled to through its Jacobian, budget.linearise)."""
    return float(g.C[0, 0])


def _own_info(g: Group) -> float:
    """An image row's own information [rad⁻²]: 1 / :func:`_own_var` (a row whose u is all its
    camera's lens adds its full weight: not infinite, bounded by rounding)."""
    return 1.0 / max(_own_var(g), 1e-300)


def image_noise(images: Sequence[Group]) -> tuple[float, int]:
    """The relative standard deviation of one image's information (1 / its own variance)
    about its camera's mean, pooled over the cameras with ≥ 2 images (each image's u carries
    terms read from that image — its length, its groove profile, its background — that
    scatter from image to image), and its degrees of freedom (the images less one per such
    camera); (1, 0) when no camera has two images (the scatter is then unknown: taken as
    large as the information itself). Dimensionless, —."""
    cams: dict[str, list[float]] = {}
    for g in images:
        cams.setdefault(g.meta.get("camera", "?"), []).append(_own_info(g))
    r2, dof = 0.0, 0
    for v in cams.values():
        if len(v) > 1:
            r2 += float(np.sum((np.asarray(v) / np.mean(v) - 1) ** 2))
            dof += len(v) - 1
    return (float(np.sqrt(r2 / dof)), dof) if dof else (1.0, 0)


def image_interval(images: Sequence[Group], n: int) -> float:
    """Half-width of the 68 % predictive interval of one more image's information about its
    camera's mean of ``n`` images, relative to that mean [—]: the new draw and the mean's
    own error (× √(1 + 1/n)), the scatter read from the images (:func:`image_noise`, ν
    degrees of freedom) so that the interval is Student's t's (× t_ν at 84.1 %: 1.84 for
    ν = 1, 1.32 for 2, 1.09 for 6), not the normal's a known scatter would give."""
    s, dof = image_noise(images)
    return s * np.sqrt(1 + 1 / n) * (float(special.stdtrit(dof, special.ndtr(1.0))) if dof
                                     else 1.0)


def expected_image(g: Group, images: Sequence[Group], source: str, A: np.ndarray | None = None
                   ) -> Group:
    """One more image like ``g`` (its housing, its view, its camera): the expected row.

    Its Jacobian is the mean of the rows of that housing in that view (``A`` overrides it: a
    reversed view's): the angle's dependence on E and the camera's roll, and its coupling to
    the camera's lens parameters — a lens error common to the camera's images does not
    average down with more of them, and the new row shares it. Its own variance is the one of
    the mean information of the camera's images (the harmonic mean of their own variances):
    the terms each image reads from itself (noise, length, groove profile, background) are
    new draws for a new image, and what a draw adds to the fusion is its information 1/u²,
    whose expectation is the mean information — not the mean u², which a single poor image
    sets (user 16: one camera's images' u 2.5-7.6″; over 9 options realised the obtained u
    was below the prediction by z -1.62 on average, now -0.62: docs/decision.md), nor the
    value of the one image copied. Its ``relative_sd`` is the half-width of the new
    information's predictive interval (:func:`image_interval`).
    """
    cam = g.meta.get("camera")
    same = [h for h in images if (h.meta.get("housing"), h.meta.get("view"))
            == (g.meta.get("housing"), g.meta.get("view"))] or [g]
    own = [_own_info(h) for h in images if h.meta.get("camera") == cam] or [_own_info(g)]
    A = np.mean([h.A for h in same], axis=0) if A is None else A
    rel = image_interval(images, len(own))
    return Group(source, "image", A, np.array([[1.0 / float(np.mean(own))]]), (),
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
    out += _datum(lin, minutes)
    rolls = [(label[len("camera roll "):], idx) for label, idx in lin.nuisances
             if label.startswith("camera roll ")]
    # a roll the fusion carries as not excluded: calibrating it resolves it
    # and one it carries over its plausible range (undetermined): calibrating it narrows that
    rolls += [(name[len(ROLL) + 1:-1], idx) for name, idx, *_ in (*lin.held, *lin.ranged)
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


SIDE_POSES = (("X", 1.0), ("X", -1.0), ("Y", 1.0), ("Y", -1.0))
"""The azimuth datum's static poses: the platform's X then Y axis up and down."""


def _datum(lin: Linearisation, minutes: Mapping[str, float]
           ) -> list[tuple[str, str, float, list[Group], list[str], dict[str, str]]]:
    """The X/Y-up static poses (an azimuth datum) when the reference face's offset is carried
    over its range and the session has static poses (levelled only) whose noise the new ones
    share: axis i's reading with axis J up (sign s) is s E_iJ + bias_i
    (:func:`align.fusion.observations.static_block`; the up/down pair separates E from the
    calibrated bias), each with the mean variance of the session's static readings."""
    static = [g for g in lin.groups if g.kind == "static"]
    bias = [f"bias[{i}]" for i in range(3)]
    if (not static or not any(name == REF for name, *_ in lin.ranged)
            or not all(b in lin.params for b in bias)):
        return []
    var = float(np.mean(np.concatenate([np.diag(g.C) for g in static])))
    rows = []
    for up, sign in SIDE_POSES:
        for i, axis in enumerate("xyz"):
            if axis.upper() == up:
                continue
            a = np.zeros(len(lin.params))
            a[E_NAMES.index(f"E_{axis}{up}")] = sign
            a[lin.params.index(bias[i])] = 1.0
            rows.append(a)
    g = Group("X/Y-up static poses", "static", np.array(rows), var * np.eye(len(rows)), (),
              {"relative_sd": str(2 * RESTATED_U_NOISE["static"])})
    return [("the X/Y-up static poses (an azimuth datum: the platform's X and Y axes up and "
             "down)", "datum", minutes["datum"], [g], [], {})]


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


def _ranged_resolution(r: Undetermined, every: Sequence[Option], k: int) -> str:
    """What resolves undetermined nuisance ``r``: the best option (``every``, best first)
    after which the fusion no longer carries it over its range, or narrows its share of angle
    ``k`` to under a quarter, saying so; else what separates its kind from E
    (``r.measure``)."""
    for o in every:
        a = next((a for a in o.ranged if a.name == r.name), None)
        if a is None:
            return o.action
        if a.shift[k] ** 2 < r.shift[k] ** 2 / 4:
            return (f"{o.action} (its share of {E_NAMES[k]} {abs(r.shift[k]) / ARCSEC:.2f} -> "
                    f"{abs(a.shift[k]) / ARCSEC:.2f}″)")
    return r.measure


def predicted(lin: Linearisation, target: str, minutes: Mapping[str, float] = MINUTES,
              camera_roll_u: float = CAMERA_ROLL_U_ARCSEC * ARCSEC) -> list[Option]:
    """Every option of :func:`options` with its prediction for angle ``target`` (those that
    lower nothing too, unranked); ``camera_roll_u`` [rad] as there."""
    k = E_NAMES.index(target)
    out = []
    for action, kind, mins, add, drop, detail in options(lin, minutes, camera_roll_u):
        # a camera's roll calibrated is declared: no longer a candidate (session.toml)
        declared = {f"{ROLL}[{detail['camera']}]": camera_roll_u} if kind == "camera" else {}
        after = predict(lin, add, drop, declared=declared)
        u = after.u
        out.append(Option(action, kind, mins, float(u[k]), tuple(map(float, u)), detail,
                          float(np.hypot(prediction_noise(lin, add, drop)[k], after.u_sd[k])),
                          after.carried, after.ranged))
    return out


def plan(lin: Linearisation, disposition: Mapping | None = None,
         minutes: Mapping[str, float] = MINUTES,
         camera_roll_u: float = CAMERA_ROLL_U_ARCSEC * ARCSEC) -> Plan:
    """Rank the options of :func:`options` for the critical angle of ``disposition`` (the
    session result's ``disposition`` dict, or None); ``camera_roll_u`` [rad] as there."""
    target, why = _target(lin, disposition)
    k = E_NAMES.index(target)
    now = predict(lin)
    u0 = now.u
    every = predicted(lin, target, minutes, camera_roll_u)
    ranked = [o for o in every if o.u_after < u0[k] * (1 - MIN_GAIN)]
    ranked.sort(key=lambda o: -(u0[k] - o.u_after) / o.minutes)
    every.sort(key=lambda o: -(u0[k] - o.u_after) / o.minutes)
    resolves = {c.name: _resolution(c, every, k) for c in now.carried}
    resolves |= {r.name: _ranged_resolution(r, every, k) for r in now.ranged}
    return Plan(target, why, float(u0[k]), tuple(ranked), now.carried, resolves, now.ranged)


def plan_from_result(js: Mapping | LoadedSession, where: str = "the result") -> Plan:
    """:func:`plan` from a session result (``align run --json``; its JSON is read by the one
    reader, :class:`~align.session_json.LoadedSession`)."""
    r = js if isinstance(js, LoadedSession) else LoadedSession.from_dict(js, where)
    if not r.ok or r.verdict == "NOT MEASURED":
        failed = [e.stage for e in r.errors]
        # (a FAIL beside an angle the data cannot measure is not ok either: docs/decision.md)
        what = ("NOT MEASURED (not ok" if r.verdict in (None, "NOT MEASURED")
                else f"not ok (verdict {r.verdict}")
        raise InputError(f"{r.where}: the session was {what}"
                         + (f": {', '.join(failed)} failed" if failed else "")
                         + "): its u are not a basis for planning; fix what failed (its "
                         "warnings and errors say what) and run it again")
    b = r.budget
    if not r.fused or not b or not b.get("model"):
        raise InputError(f"{r.where}: no fused misalignment with its budget (a failed session, "
                         "or a result written before budgets existed): nothing to plan from")
    p = plan(Linearisation.from_dict(b["model"]), r.disposition)
    stated = r.u_rad[E_NAMES.index(p.target)] if r.u_rad is not None else p.u_before
    if not abs(p.u_before - stated) <= STATED_U_RTOL * stated:
        # The plan predicts from its own model of the result's u; where that model does not
        # give the u the result states (a carried term it reads otherwise: a held nuisance
        # nearly degenerate with an effect the fusion added), its figures would be wrong.
        raise InputError(f"{r.where}: the plan's model gives u({p.target}) = "
                         f"{p.u_before / ARCSEC:.4g}″ where the result states "
                         f"{stated / ARCSEC:.4g}″ (carried: "
                         f"{', '.join(c.name for c in p.carried) or 'none'}): its predictions "
                         "would not be about this result; not planned")
    return p


STATED_U_RTOL = 0.01
"""Largest relative difference between the plan's u of its target and the result's stated u
[—] on which :func:`plan_from_result` plans."""
