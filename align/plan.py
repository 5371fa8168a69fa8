"""What to measure next: the added measurement that lowers u of the critical angle most per
minute of work, predicted from the fused solve's linearisation (:mod:`align.fusion.budget`).

The critical angle is the one nearest to (or furthest beyond) its acceptance limit (smallest
margin − guard band of the disposition), or, without a tolerance, the one with the largest u.
Each option is a hypothetical change of the observations, with the noise of the existing ones
of that kind; its information is added to the session's and the new information inverted:

* another image of a housing in a view: one more row like that image's (same Jacobian, same u);
* a reversed view (the platform turned 180° on the table, the same camera): the view's rows with
  the sign of their dependence on E flipped and that on the camera's roll kept — what separates
  a roll from E;
* a goniometer log twice as long: the log's covariance without its Type B terms halved (more
  revolutions average the scatter, not a bound);
* a second tumble (as many poses again): the calibration's covariance halved;
* the platform static poses repeated: their covariance halved;
* a calibrated camera (only when the loop estimated its roll): the roll known to
  ±``CAMERA_ROLL_U_ARCSEC``.

Minutes per option are the documented defaults ``MINUTES`` (a site changes them in code or by
keyword). The prediction is first order in the data (the linearisation does not move) and keeps
the nuisances the loop chose; a new view may let the loop choose differently.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from align.errors import InputError
from align.fusion.budget import Group, Linearisation
from align.fusion.observations import E_NAMES
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
    """

    action: str
    kind: str
    minutes: float
    u_after: float
    u_after_all: tuple[float, ...]
    detail: Mapping[str, str] = field(default_factory=dict)
    """What exactly: an image's ``housing`` and ``view``, a reversal's ``view``, a
    camera's ``camera``, a replaced input's ``source``."""

    def to_dict(self, u_before: float) -> dict:
        return {"action": self.action, "kind": self.kind, "minutes": self.minutes,
                "detail": dict(self.detail),
                "u_after_arcsec": self.u_after / ARCSEC,
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
    """

    target: str
    why: str
    u_before: float
    options: tuple[Option, ...]

    @property
    def best(self) -> Option | None:
        return self.options[0] if self.options else None

    def to_dict(self) -> dict:
        return {"format_version": FORMAT_VERSION, "target": self.target, "why": self.why,
                "u_before_arcsec": self.u_before / ARCSEC,
                "options": [o.to_dict(self.u_before) for o in self.options]}

    def lines(self) -> list[str]:
        out = [f"what to measure next for {self.target} ({self.why}; u now "
               f"{self.u_before / ARCSEC:.3f}″):"]
        for k, o in enumerate(self.options):
            out.append(f"  {'->' if k == 0 else '  '} {o.action}: u {o.u_after / ARCSEC:.3f}″ "
                       f"({100 * (1 - o.u_after / self.u_before):.1f} % lower) in "
                       f"{o.minutes:g} min")
        if not self.options:
            out.append("  no measurement of the kinds known here lowers it")
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
    u = lin.u_with()
    k = int(np.argmax(u))
    return E_NAMES[k], "no tolerance: the largest u"


def _halved(g: Group) -> Group:
    """The group with its scatter halved (twice the data), its Type B bounds kept."""
    B = sum((c for _, c in g.type_b), np.zeros_like(g.C))
    return Group(g.source, g.kind, g.A, (g.C - B) / 2 + B, g.type_b, g.meta)


def options(lin: Linearisation, minutes: Mapping[str, float] = MINUTES
            ) -> list[tuple[str, str, float, list[Group], list[str], dict[str, str]]]:
    """The hypothetical measurements: (action, kind, minutes, groups to add, sources to
    drop, detail)."""
    out = []
    images = [g for g in lin.groups if g.kind == "image"]
    seen = set()
    for g in images:
        key = (g.meta.get("housing"), g.meta.get("view"))
        if key in seen:
            continue
        seen.add(key)
        out.append((f"another image of housing {key[0]} in view {key[1]} (like "
                    f"{g.source[len('image '):]})", "image", minutes["image"],
                    [Group(g.source + " (again)", "image", g.A, g.C, (), g.meta)], [],
                    {"housing": str(key[0]), "view": str(key[1])}))
    views: dict[str, list[Group]] = {}
    for g in images:
        views.setdefault(g.meta.get("view", "?"), []).append(g)
    for view, gs in views.items():
        flipped = []
        for g in gs:
            A = g.A.copy()
            A[:, :6] *= -1
            flipped.append(Group(g.source + " (reversed)", "image", A, g.C, (), g.meta))
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
                        [_halved(g)], [g.source], {"source": g.source}))
        elif g.kind == "calibration":
            out.append(("a second tumble (as many poses again)", "tumble", minutes["tumble"],
                        [_halved(g)], [g.source], {"source": g.source}))
        elif g.kind == "static":
            out.append(("the platform static poses repeated", "static", minutes["static"],
                        [_halved(g)], [g.source], {"source": g.source}))
    for label, idx in lin.nuisances:
        if label.startswith("camera roll "):
            A = np.zeros((1, len(lin.params)))
            A[0, idx[0]] = 1.0
            cam = label[len("camera roll "):]
            out.append((f"calibrate camera {cam}'s roll (to ±{CAMERA_ROLL_U_ARCSEC:g}″)",
                        "camera", minutes["camera"],
                        [Group(f"camera {cam} roll calibration", "calibration", A,
                               np.array([[(CAMERA_ROLL_U_ARCSEC * ARCSEC) ** 2]]))], [],
                        {"camera": cam}))
    return out


def plan(lin: Linearisation, disposition: Mapping | None = None,
         minutes: Mapping[str, float] = MINUTES) -> Plan:
    """Rank the options of :func:`options` for the critical angle of ``disposition`` (the
    session result's ``disposition`` dict, or None)."""
    target, why = _target(lin, disposition)
    k = E_NAMES.index(target)
    u0 = lin.u_with()
    ranked = []
    for action, kind, mins, add, drop, detail in options(lin, minutes):
        u = lin.u_with(add=add, drop=drop)
        if u[k] < u0[k] * (1 - MIN_GAIN):
            ranked.append(Option(action, kind, mins, float(u[k]), tuple(map(float, u)),
                                 detail))
    ranked.sort(key=lambda o: -(u0[k] - o.u_after) / o.minutes)
    return Plan(target, why, float(u0[k]), tuple(ranked))


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
