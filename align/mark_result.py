"""The per-image result of :mod:`align.marks`: one mark (or one failure) with what the loop,
the lens and the frame's families said, and its serialisation (``align marks --json``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from align.family import LineFamily
from align.line_dial import LineDial
from align.loop import LoopReport, LoopSummary
from imaging import MarkMeasurement


@dataclass(frozen=True)
class FrameDistortion:
    """One radial distortion shared by all marks of a frame (joint weighted plumb-line fit), as
    results written before the lens moved to :mod:`align.lens` saved it (read back only).

    Attributes
    ----------
    k1 : float
        Radial distortion at the image half-diagonal — dimensionless.
    k1_u : float
        Its standard uncertainty — dimensionless.
    applied : bool
        It was significant, explained the lines, and the marks were undistorted with it;
        unit —.
    consistent : bool
        The lines are straight within their uncertainties once it is removed (False: the lines
        disagree in a way no single radial distortion explains — bent marks, or lines that are
        not straight in the world — and every mark's u is inflated by sqrt(chi2/dof)); unit —.
    n_lines : int
        Marks in the fit — dimensionless.
    chi2_dof_before, chi2_dof_after : float
        All lines' straightness, χ²/dof — dimensionless.
    p_value : float
        Of the k1 = 0 test — dimensionless.
    """

    k1: float
    k1_u: float
    applied: bool
    consistent: bool
    n_lines: int
    chi2_dof_before: float
    chi2_dof_after: float
    p_value: float

    def to_dict(self) -> dict:
        return {"k1": self.k1, "k1_u": self.k1_u, "applied": self.applied,
                "consistent": self.consistent, "lines": self.n_lines,
                "chi2_dof_before": self.chi2_dof_before,
                "chi2_dof_after": self.chi2_dof_after, "p_value": self.p_value}

    @classmethod
    def from_dict(cls, d: Mapping) -> FrameDistortion:
        """From :meth:`to_dict`'s keys (a non-finite number is saved as null)."""
        return cls(_num(d["k1"]), _num(d["k1_u"]), bool(d["applied"]), bool(d["consistent"]),
                   int(d["lines"]), _num(d["chi2_dof_before"]), _num(d["chi2_dof_after"]),
                   _num(d["p_value"]))


def _num(v: object) -> float:
    """A saved float: strict JSON writes NaN and ±inf as null, read back as NaN."""
    return float("nan") if v is None else float(v)  # type: ignore[arg-type]


@dataclass(frozen=True)
class MarkResult:
    """One mark (or one failure) of one image.

    Attributes
    ----------
    image : str
        The image file; unit —.
    found : bool
        A mark was measured (else ``error`` says why); unit —.
    error : str or None
        Why not; unit —.
    index : int
        The mark's index in its image — dimensionless.
    angle_rad, angle_u_rad : float
        The mark's angle in the image and its standard uncertainty [rad].
    offset_px, offset_u_px : float
        Its distance from the image centre and its standard uncertainty [px] (the lens's
        share included).
    offset_lens_u_px : float
        The lens's share of ``offset_u_px`` [px]: shared by every mark of the frame's lens
        (:func:`align.family_stage.offset_lens_u`).
    length_px : float
        Its length, between the groove's half-depth ends [px].
    width_px : float
        Its width [px].
    blur_px : float
        The edge blur [px].
    dark : bool
        A dark groove on a bright surface (else bright); unit —.
    n_points : int
        Centre points fitted — dimensionless.
    n_rejected : int
        Centre points rejected — dimensionless.
    angle_before_rad : float
        The angle of the declared model, before the loop [rad].
    loop : LoopReport or LoopSummary or None
        The residual loop's report; unit —.
    measurement : MarkMeasurement or None
        The raw measurement (not saved); unit —.
    uncertainty_inflation : float
        Factor on u for structure no effect explains — dimensionless.
    internal_error : bool
        The failure was a defect of the tool; unit —.
    frame : FrameDistortion or None
        The frame's shared distortion (older results); unit —.
    family : LineFamily or None
        The family of parallel lines it belongs to; unit —.
    unreported : int
        Lines found in the image and not reported — dimensionless.
    dial : LineDial or None
        The graduated dial (lines meeting at a point) it belongs to; unit —.
    lens : Mapping or None
        The camera's lens as used (source, parameters fitted or carried; dimensionless, pp in
        [px]).
    u_terms : Mapping
        Named contributions to ``angle_u_rad`` [rad].
    notes : tuple of str
        What the reader must know; unit —.
    lens_limited : bool
        The lens terms of u exceed the limit: not ok, calibrate the camera; unit —.
    lens_coupling : Mapping
        The lens terms of u as signed components on the lens's error directions [rad]
        (:func:`align.lens_terms.angle_coupling`).
    lens_group : str
        The lens solve the mark shares with others (marks of one group share the lens's
        error); unit —.
    bend_off_frame : bool
        A bowed mark runs off the image: its ends, hence its chord (direction), are not in
        it; not ok; unit —.
    kinked : bool
        Two straight grooves meeting at an angle were found as this one mark
        (:mod:`align.mark_kink`): no one direction; not ok; unit —.
    """

    image: str
    found: bool
    error: str | None = None
    index: int = 0
    angle_rad: float = float("nan")
    angle_u_rad: float = float("nan")
    offset_px: float = float("nan")
    offset_u_px: float = float("nan")
    offset_lens_u_px: float = 0.0
    length_px: float = float("nan")
    width_px: float = float("nan")
    blur_px: float = float("nan")
    dark: bool = True
    n_points: int = 0
    n_rejected: int = 0
    angle_before_rad: float = float("nan")
    loop: LoopReport | LoopSummary | None = None
    measurement: MarkMeasurement | None = None
    uncertainty_inflation: float = 1.0
    internal_error: bool = False
    frame: FrameDistortion | None = None
    family: LineFamily | None = None
    unreported: int = 0
    dial: LineDial | None = None
    lens: Mapping | None = None
    u_terms: Mapping[str, float] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    lens_limited: bool = False
    # The lens terms of u as signed components [rad] and the lens solve they belong to:
    # marks of one group share the lens's error (align.lens_terms.angle_coupling).
    lens_coupling: Mapping[str, float] = field(default_factory=dict)
    lens_group: str = ""
    bend_off_frame: bool = False
    kinked: bool = False

    @property
    def offset_own_u_px(self) -> float:
        """The offset's u without the lens's shared share [px] (a family's pitch carries the
        lens through its members' moves together, :mod:`align.family_stage`)."""
        return float(np.sqrt(max(self.offset_u_px**2 - self.offset_lens_u_px**2, 0.0)))

    @property
    def unexplained_structure(self) -> bool:
        return bool(self.loop and self.loop.unexplained_structure)

    @property
    def lens_not_ok(self) -> list[str]:
        """Why the lens makes this mark not ok and what helps, as its own notes say it
        (:func:`align.lens_advice.lens_advice`: the one place the advice is written),
        without the "IMAGE mark K: NOT OK: " prefix; empty when the lens does not."""
        own = f"{self.image} mark {self.index}: NOT OK: "
        return [n.removeprefix(own) for n in self.notes if n.startswith(own) and "lens" in n]

    def to_dict(self) -> dict:
        """The mark as ``align marks --json`` and a session's ``stages.marks`` save it:
        angles in degrees (and radians, exact), the loop's summary
        (:meth:`align.loop.LoopSummary.to_dict`), the frame's shared distortion."""
        d: dict = {"image": self.image, "found": self.found, "error": self.error}
        if self.internal_error:
            d["internal_error"] = True
        if self.unreported:
            d["lines_not_reported"] = self.unreported
        if not self.found:
            return d
        d.update({
            "index": self.index, "angle_deg": float(np.rad2deg(self.angle_rad)),
            "angle_u_deg": float(np.rad2deg(self.angle_u_rad)),
            "angle_u_arcsec": float(np.rad2deg(self.angle_u_rad) * 3600),
            "angle_rad": self.angle_rad, "angle_u_rad": self.angle_u_rad,
            "offset_px": self.offset_px, "offset_u_px": self.offset_u_px,
            "offset_lens_u_px": self.offset_lens_u_px,
            "length_px": self.length_px, "width_px": self.width_px, "blur_px": self.blur_px,
            "polarity": "dark" if self.dark else "bright", "points": self.n_points,
            "rejected_points": self.n_rejected,
            "angle_before_loop_deg": float(np.rad2deg(self.angle_before_rad)),
            "angle_before_loop_rad": self.angle_before_rad,
            "effects": [], "unexplained_structure": self.unexplained_structure,
            "uncertainty_inflation": self.uncertainty_inflation,
        })
        if self.frame is not None:
            d["frame_radial_distortion"] = self.frame.to_dict()
        if self.family is not None:
            d["family"] = self.family.to_dict()
        if self.dial is not None:
            d["dial"] = self.dial.to_dict()
        if self.lens is not None:
            d["lens"] = dict(self.lens)
        d["angle_u_terms_arcsec"] = {k: float(np.rad2deg(v) * 3600)
                                     for k, v in self.u_terms.items()}
        d["angle_u_terms_rad"] = {k: float(v) for k, v in self.u_terms.items()}
        d["notes"] = list(self.notes)
        d["lens_limited"] = self.lens_limited
        d["bent_mark_off_frame"] = self.bend_off_frame
        d["kinked_mark"] = self.kinked
        if self.lens_coupling:
            d["lens_group"] = self.lens_group
            d["angle_lens_coupling_rad"] = {k: float(v) for k, v in self.lens_coupling.items()}
        if self.loop:
            s = self.loop.summary()
            d.update(s.to_dict())
            d["residual_rms_px"] = {"before": s.rms_before, "after": s.rms_after}
            d["chi2_dof"] = {"before": s.chi2_dof_before, "after": s.chi2_dof_after}
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> MarkResult:
        """From :meth:`to_dict`'s keys. What is not saved comes back None: the measurement,
        and the full loop (its saved part is an :class:`align.loop.LoopSummary`, which
        answers ``effects``, ``unexplained_structure`` and ``summary_lines()`` alike)."""
        base = {"image": str(d["image"]), "found": bool(d["found"]),
                "error": None if d.get("error") is None else str(d["error"]),
                "internal_error": bool(d.get("internal_error", False)),
                "unreported": int(d.get("lines_not_reported", 0))}
        if not base["found"]:
            return cls(**base)

        def rad(key: str) -> float:  # radians saved exactly; degrees from older files
            return _num(d[key + "_rad"]) if key + "_rad" in d else np.deg2rad(
                _num(d[key + "_deg"]))

        fr = d.get("frame_radial_distortion")
        return cls(**base, index=int(d["index"]), angle_rad=rad("angle"),
                   angle_u_rad=rad("angle_u"), offset_px=_num(d["offset_px"]),
                   offset_u_px=_num(d["offset_u_px"]),
                   offset_lens_u_px=_num(d.get("offset_lens_u_px", 0.0)),
                   length_px=_num(d["length_px"]),
                   width_px=_num(d["width_px"]), blur_px=_num(d["blur_px"]),
                   dark=d.get("polarity", "dark") == "dark", n_points=int(d["points"]),
                   n_rejected=int(d.get("rejected_points", 0)),
                   angle_before_rad=rad("angle_before_loop"),
                   loop=LoopSummary.from_dict(d) if "loop" in d else None,
                   uncertainty_inflation=_num(d.get("uncertainty_inflation", 1.0)),
                   frame=None if fr is None else FrameDistortion.from_dict(fr),
                   family=LineFamily.from_dict(d["family"]) if "family" in d else None,
                   dial=LineDial.from_dict(d["dial"]) if "dial" in d else None,
                   lens=d.get("lens"),
                   u_terms={str(k): _num(v)
                            for k, v in (d.get("angle_u_terms_rad") or {}).items()},
                   notes=tuple(str(n) for n in d.get("notes", ())),
                   lens_limited=bool(d.get("lens_limited", False)),
                   lens_coupling={str(k): _num(v) for k, v in
                                  (d.get("angle_lens_coupling_rad") or {}).items()},
                   lens_group=str(d.get("lens_group", "")),
                   bend_off_frame=bool(d.get("bent_mark_off_frame", False)),
                   kinked=bool(d.get("kinked_mark", False)))
