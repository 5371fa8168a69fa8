"""What the residual loop reports: each effect added (:class:`EffectReport`), refused or
skipped, the loop as a whole (:class:`LoopReport`) and what a saved result keeps of it
(:class:`LoopSummary`), each owning its JSON form."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from align.loop.fit import StageFit, Term
from align.loop.structure import StructureReport


@dataclass(frozen=True)
class EffectReport:
    """An effect the loop added.

    Attributes
    ----------
    name : str
        The effect; unit —.
    estimate : float
        Its value [``unit``]; of an effect with ``components``, the length of their vector
        (>= 0: each component's sign is in ``components``).
    u : float
        Its standard uncertainty [``unit``].
    unit : str
        The unit of ``estimate`` and ``u``; unit —.
    rms_before, rms_after : float
        The residual RMS before and after adding it [the stage's residual unit].
    delta_bic : float
        The change in BIC — dimensionless.
    p_value : float
        Its significance (look-elsewhere corrected) — dimensionless.
    description : str
        What it is, in words; unit —.
    components : tuple of (str, float, float)
        Per axis (name, estimate, u) [``unit``].
    """

    name: str
    estimate: float
    u: float
    unit: str
    rms_before: float
    rms_after: float
    delta_bic: float
    p_value: float
    description: str = ""
    components: tuple[tuple[str, float, float], ...] = ()

    def to_dict(self) -> dict:
        d = {"name": self.name, "estimate": self.estimate, "u": self.u, "unit": self.unit,
             "rms_before": self.rms_before, "rms_after": self.rms_after,
             "delta_bic": self.delta_bic, "p_value": self.p_value}
        if self.description:
            d["description"] = self.description
        if self.components:
            d["components"] = [{"axis": c, "estimate": e, "u": u} for c, e, u in self.components]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> EffectReport:
        """From :meth:`to_dict`'s output (a non-finite number saved as null reads as NaN)."""
        def num(k: str) -> float:
            v = d.get(k)
            return float("nan") if v is None else float(v)

        return cls(str(d["name"]), num("estimate"), num("u"), str(d.get("unit", "")),
                   num("rms_before"), num("rms_after"), num("delta_bic"), num("p_value"),
                   str(d.get("description", "")),
                   tuple((str(c["axis"]), float(c["estimate"]), float(c["u"]))
                         for c in d.get("components", ())))


@dataclass(frozen=True)
class RefusedEffect:
    """A candidate the tests called for but the stage's ``admissible`` check refused: why, and
    its significance (it was *not* added).

    Attributes
    ----------
    name : str
        The candidate; unit —.
    reason : str
        Why it was refused; unit —.
    p_value : float
        Its significance — dimensionless.
    delta_bic : float
        Its change in BIC — dimensionless.
    """

    name: str
    reason: str
    p_value: float
    delta_bic: float

    def to_dict(self) -> dict:
        return {"name": self.name, "reason": self.reason, "p_value": self.p_value,
                "delta_bic": self.delta_bic}

    @classmethod
    def from_dict(cls, d: Mapping) -> RefusedEffect:
        return cls(str(d["name"]), str(d["reason"]), float(d["p_value"]),
                   float(d["delta_bic"]))


@dataclass(frozen=True)
class SkippedCandidate:
    """A candidate the loop could not try: it does not apply to these data, or its refit was
    singular (``reason`` says which, in the stage's words).

    Attributes
    ----------
    name : str
        The candidate; unit —.
    reason : str
        Why it was skipped; unit —.
    """

    name: str
    reason: str

    def to_dict(self) -> dict:
        return {"name": self.name, "reason": self.reason}

    @classmethod
    def from_dict(cls, d: Mapping) -> SkippedCandidate:
        return cls(str(d["name"]), str(d["reason"]))


@dataclass(frozen=True)
class LoopReport:
    """Before/after of one stage's loop.

    Attributes
    ----------
    effects : tuple of EffectReport
        The effects added, in order, with estimate, u and the RMS before/after.
    before, after : StageFit
        The declared model's fit and the final one.
    structure_before, structure_after : StructureReport
        The residuals' structure tests before and after (``unexplained_structure``: what
        remains after).
    terms : tuple of Term
        The terms of the final model.
    refused : tuple of RefusedEffect
        Significant candidates not added, with why.
    skipped : tuple of SkippedCandidate
        Candidates that could not be tried, with why.

    ``unexplained_structure`` is true when the structure tests still find structure after
    the loop *or* a candidate the data called for was refused: either way the model lacks
    something the residual shows, and the stage must widen u or say not ok.
    """

    effects: tuple[EffectReport, ...]
    before: StageFit
    after: StageFit
    structure_before: StructureReport
    structure_after: StructureReport
    terms: tuple[Term, ...]
    refused: tuple[RefusedEffect, ...] = ()
    skipped: tuple[SkippedCandidate, ...] = ()

    @property
    def unexplained_structure(self) -> bool:
        return self.structure_after.structured or bool(self.refused)

    @property
    def structure_evidence(self) -> tuple[str, float, str]:
        """What shows the structure left: (test or refused candidate, p-value, detail) —
        the structure tests' worst when they find structure, else the most significant
        refused candidate."""
        if self.structure_after.structured or not self.refused:
            w = self.structure_after.worst
            return w.name, w.p_value, w.detail
        r = min(self.refused, key=lambda r: r.p_value)
        return f"{r.name} refused", r.p_value, r.reason

    def summary_lines(self) -> list[str]:
        return self.summary().summary_lines()

    def summary(self) -> LoopSummary:
        """What of this loop a saved result keeps."""
        def chi2_dof(f: StageFit) -> float | None:
            return None if f.sigma is None else f.chi2 / max(f.dof, 1)

        w = self.structure_evidence if self.unexplained_structure else None
        return LoopSummary(self.effects, self.before.rms, self.after.rms,
                           chi2_dof(self.before), chi2_dof(self.after),
                           self.unexplained_structure,
                           None if w is None else w[0], None if w is None else w[1],
                           "" if w is None else w[2], self.refused, self.skipped)


@dataclass(frozen=True)
class LoopSummary:
    """A loop's outcome as a result saves it.

    Attributes
    ----------
    effects : tuple of EffectReport
        The effects added, in order; unit — (theirs are in their fields).
    rms_before, rms_after : float
        Residual RMS of the declared model and of the final one [the stage's residual unit].
    chi2_dof_before, chi2_dof_after : float or None
        χ²/dof against the stated noise (None: noise unknown) — dimensionless.
    unexplained_structure : bool
        Whether structure no candidate explains remains; unit —.
    structure_test, structure_p, structure_detail : str, float, str
        The test that found it, its p-value (dimensionless) and what it saw (None, None, "" if
        none); unit —.
    refused : tuple of RefusedEffect
        Significant candidates the stage's physical checks refused, with why; unit —.
    skipped : tuple of SkippedCandidate
        Candidates not tried (not applicable to these data, or a singular refit), with why;
        unit —.
    """

    effects: tuple[EffectReport, ...]
    rms_before: float
    rms_after: float
    chi2_dof_before: float | None
    chi2_dof_after: float | None
    unexplained_structure: bool
    structure_test: str | None = None
    structure_p: float | None = None
    structure_detail: str = ""
    refused: tuple[RefusedEffect, ...] = ()
    skipped: tuple[SkippedCandidate, ...] = ()

    def summary(self) -> LoopSummary:
        """Itself (a loaded result's loop is already a summary)."""
        return self

    def summary_lines(self) -> list[str]:
        """The loop's before/after for the terminal, one line each."""
        if self.chi2_dof_before is None:
            lines = [f"residual RMS {self.rms_before:.4g} -> {self.rms_after:.4g}; noise "
                     "unknown: no chi2 test, effects judged by F-test"]
        else:
            lines = [f"residual RMS {self.rms_before:.4g} -> {self.rms_after:.4g}; "
                     f"chi2/dof {self.chi2_dof_before:.3f} -> {self.chi2_dof_after:.3f}"]
        for e in self.effects:
            lines.append(f"added {e.name}: {e.estimate:.4g} ± {e.u:.2g} {e.unit} "
                         f"(dBIC {e.delta_bic:.1f}, p {e.p_value:.2g})")
        for r in self.refused:
            lines.append(f"REFUSED {r.name} (p {r.p_value:.2g}): {r.reason}")
        if self.unexplained_structure:
            lines.append(f"UNEXPLAINED STRUCTURE remains: {self.structure_test} "
                         f"p={self.structure_p:.2g} {self.structure_detail}")
        return lines

    def to_dict(self) -> dict:
        """The result-level keys of the JSON contract (``effects``, ``unexplained_structure``)
        and the loop's before/after under ``loop``."""
        return {"effects": [e.to_dict() for e in self.effects],
                "unexplained_structure": self.unexplained_structure,
                "refused_effects": [r.to_dict() for r in self.refused],
                "skipped_candidates": [s.to_dict() for s in self.skipped],
                "loop": {"rms_before": self.rms_before, "rms_after": self.rms_after,
                         "chi2_dof_before": self.chi2_dof_before,
                         "chi2_dof_after": self.chi2_dof_after,
                         "structure_test": self.structure_test,
                         "structure_p": self.structure_p,
                         "structure_detail": self.structure_detail}}

    @classmethod
    def from_dict(cls, d: Mapping) -> LoopSummary:
        lp = d.get("loop") or {}

        def num(k: str) -> float | None:
            v = lp.get(k)
            return None if v is None else float(v)

        nan = float("nan")
        rb, ra = num("rms_before"), num("rms_after")
        return cls(tuple(EffectReport.from_dict(e) for e in d.get("effects", ())),
                   nan if rb is None else rb, nan if ra is None else ra,
                   num("chi2_dof_before"), num("chi2_dof_after"),
                   bool(d.get("unexplained_structure", False)), lp.get("structure_test"),
                   num("structure_p"), str(lp.get("structure_detail", "")),
                   tuple(RefusedEffect.from_dict(r) for r in d.get("refused_effects", ())),
                   tuple(SkippedCandidate.from_dict(s)
                         for s in d.get("skipped_candidates", ())))
