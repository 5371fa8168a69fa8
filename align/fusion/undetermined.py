"""What the data cannot determine enters E's u over its plausible range (issue 18).

The loop tests a nuisance (a camera's roll, the reference face's azimuth offset) only where the
data can separate it from E; :mod:`align.fusion.plausible` carries one the data cannot
*exclude*. A nuisance the data cannot *determine* escapes both: its column is degenerate with
E (a roll beside views without their reversals: three observations, three unknowns; the
reference face's offset without an azimuth datum, the X/Y-up static poses), or freed its u is
beyond any plausible size, so its estimate is 0 ± enormous and nothing is seen. Its true value
then moves E by k b unseen (k = dE/db at the final model: what fitting E alone makes of the
nuisance's signature) — a 30″ reference-face offset left E_xY 807 u off, ok.

Such a nuisance is carried over its plausible range: a Type B term σ² k kᵀ in E's covariance,
σ the standard uncertainty of its range (declared in session.toml, else
:data:`DEFAULT_HALF_RANGE_ARCSEC` as a uniform range). Whether the data determine it is read
from the design: its u when freed beside the final model (infinite when its column lies in
E's span) against σ — the data determine it when they know it better than the range does.
This is judged before :mod:`align.fusion.plausible`'s rules, which pass such a nuisance by.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from align.fusion.observations import E_NAMES, REF, ROLL
from align.loop import Candidate, LoopReport
from axisbase.errors import NotApplicable
from axisbase.units import ARCSEC

DEFAULT_HALF_RANGE_ARCSEC = {ROLL: 60.0, REF: 60.0}
"""The plausible range of an undeclared nuisance, ± this [″] (uniform: σ = half / √3), by
kind: a camera squared on its fixture and a reference face set on the goniometer's fixture are
within an arc-minute in a lab that squares them at all (user sessions: rolls of 40-45″, a
30″ offset). A set-up known worse declares its range in session.toml (``roll_u_arcsec``,
``reference_offset_u_arcsec``: the standard uncertainty). The table tilt and the platform's
levelling are not carried here (no default range; see docs/loop.md)."""

UNDETERMINED_TAG = " not determined by these data ("
"""What names an undetermined nuisance's share in E's budget."""

MEASURE = {ROLL: "the reversal views (each mark also seen turned half a turn) or platform "
                 "static poses",
           REF: "the X/Y-up platform static poses (an azimuth datum)"}
"""What separates each kind from E."""


def kind(name: str) -> str:
    """The nuisance's kind (``camera_roll[A]`` -> ``camera_roll``)."""
    return name.split("[", 1)[0]


def default_sigma(name: str) -> float | None:
    """The standard uncertainty [rad] of an undeclared nuisance's plausible range, or None
    (not carried)."""
    half = DEFAULT_HALF_RANGE_ARCSEC.get(kind(name))
    return None if half is None else half * ARCSEC / np.sqrt(3.0)


@dataclass(frozen=True)
class Undetermined:
    """A nuisance the data cannot determine, carried over its plausible range.

    Attributes
    ----------
    name : str
        The nuisance (``camera_roll[A]``, ``reference_face_offset``); unit —.
    sigma : float
        The standard uncertainty of its plausible range [rad].
    u_freed : float
        Its u when freed beside the final model (inf: not separable from E at all) [rad].
    shift : numpy.ndarray
        The six angles' (``E_NAMES``) shift for a nuisance of ``sigma`` (combined with
        ``u_freed``: σ u_f / √(σ² + u_f²)) [rad]: its Type B share of cov(E) is
        ``shift shiftᵀ``.
    declared : bool
        Whether ``sigma`` was declared (else the default range); unit —.
    """

    name: str
    sigma: float
    u_freed: float
    shift: np.ndarray
    declared: bool = False

    def to_dict(self) -> dict:
        return {"name": self.name, "sigma": self.sigma,
                "u_freed": None if not np.isfinite(self.u_freed) else self.u_freed,
                "shift": self.shift.tolist(), "declared": self.declared}

    @classmethod
    def from_dict(cls, d: Mapping) -> Undetermined:
        u = d.get("u_freed")
        return cls(str(d["name"]), float(d["sigma"]), float("inf") if u is None else float(u),
                   np.array(d["shift"], float), bool(d.get("declared", False)))

    @property
    def measure(self) -> str:
        """What to measure to determine it."""
        return MEASURE.get(kind(self.name), "observations that separate it from E")

    @property
    def label(self) -> str:
        """How the budget names its Type B share."""
        freed = ("not separable from E" if not np.isfinite(self.u_freed)
                 else f"its u freed {self.u_freed / ARCSEC:.0f}″")
        src = "declared" if self.declared else "default range"
        return (f"{self.name}{UNDETERMINED_TAG}{freed}; carried over its plausible range, σ "
                f"{self.sigma / ARCSEC:.1f}″, {src}; measure {self.measure})")

    def message(self, u_e: np.ndarray, share: float = 0.5) -> str | None:
        """A warning when it sets more than ``share`` of some angle's u² (``u_e``: the six
        angles' u [rad]), naming the angles and what to measure; else None."""
        frac = self.shift**2 / np.maximum(u_e**2, 1e-300)
        hit = [f"{n} ± {u / ARCSEC:.1f}″" for n, f, u in zip(E_NAMES, frac, u_e, strict=True)
               if f > share]
        if not hit:
            return None
        src = "as declared" if self.declared else "the default range; declare it if known"
        return (f"fusion: {self.name} is not determined by these data; carried over its "
                f"plausible range (σ {self.sigma / ARCSEC:.1f}″, {src}), it sets the u of "
                f"{', '.join(hit)}: measure {self.measure}")


def carried_variance(sigma: float, u_freed: float) -> float:
    """The variance [rad²] a nuisance of plausible range ``sigma`` [rad] and u freed
    ``u_freed`` [rad] (inf: not separable) adds along its E shift per unit, or 0 when the data
    determine it (``u_freed`` ≤ ``sigma``: the loop's tests judge it). With the nuisance a
    parameter of prior N(0, σ²) beside what the data say of it: σ² u_f² / (σ² + u_f²) — σ²
    when the data say nothing."""
    if not u_freed > sigma:
        return 0.0
    return sigma**2 if not np.isfinite(u_freed) else sigma**2 * u_freed**2 / (
        sigma**2 + u_freed**2)


def freed_u(info: float, scale: float, inflation: float) -> float:
    """A nuisance's u [rad] when freed beside the model from ``info``, the information its
    column adds beyond what E's and the other parameters' columns mimic, and ``scale`` its
    column's own information (infinite when ``info`` is rounding of it)."""
    # Separable when what E cannot mimic of its signature is more than rounding of it.
    return inflation / np.sqrt(info) if info > 1e-16 * scale else float("inf")


def undetermined(stage, candidates: Sequence[Candidate], loop: LoopReport, params: np.ndarray,
                 inflation: float, sigmas: Mapping[str, float] | None = None
                 ) -> list[Undetermined]:
    """The candidates the loop did not add whose u freed beside the final model (``params``:
    its parameters; ``inflation``: its u's scale) exceeds their plausible range's σ
    (``sigmas`` by name [rad], else :func:`default_sigma`), each with its E shift per σ.
    ``stage``: the :class:`~align.fusion.FusionStage`. Judged before
    :func:`align.fusion.plausible.not_excluded`, which passes these by: a candidate the data
    cannot determine is carried over its range, never as a not-excluded estimate (its
    estimate, freed, is a draw of u_f > σ about zero: a 298″ u freed gave a 772″ shift)."""
    added = {t.name for t in loop.terms}
    sigmas = dict(sigmas or {})
    out = []
    m = len(params)
    for cand in candidates:
        if cand.name in added:
            continue
        sigma = sigmas.get(cand.name, default_sigma(cand.name))
        if sigma is None or not sigma > 0:
            continue
        try:
            term = cand.build(loop.after)
        except NotApplicable:
            continue
        if term is None:
            continue
        J = stage.jacobian([*loop.terms, term], np.concatenate([params, np.zeros(1)]))
        if J.shape[1] != m + 1:
            continue  # a vector nuisance: no range is carried for these (see the module doc)
        A, c = J[:, :m], J[:, m]
        k = np.linalg.lstsq(A, c, rcond=None)[0]
        rest = c - A @ k
        u_freed = freed_u(float(rest @ rest), float(c @ c), inflation)
        v = carried_variance(sigma, u_freed)
        if not v > 0:
            continue  # the data know it better than its range: the loop's tests judge it
        out.append(Undetermined(cand.name, float(sigma), float(u_freed), k[:6] * np.sqrt(v),
                                cand.name in sigmas))
    return out
