"""One weighted least-squares solve for the six small angles E, its loop, and the result.

Each block is whitened by the Cholesky factor of its covariance, so the stacked residual is
N(0, 1) per entry when the instruments agree; chi2 and the per-observation normalised residuals
are the consistency check between instruments. Nuisances (camera roll per camera, the
reference face's azimuth offset, the table-axis tilt) enter as loop terms, only when the data
call for them; a term the data cannot separate from E (rank-deficient) is not offered.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.optimize import least_squares

from align.errors import InputError
from align.fusion.budget import Budget, Linearisation, linearise, with_type_b
from align.fusion.diagnosis import (
    SourceDisagreement,
    disagreement_from_dict,
    jacobian,
    leave_one_source_out,
    name_disagreement,
    with_disagreement,
    with_pairs,
)
from align.fusion.observations import (
    E_NAMES,
    LEVEL,
    REF,
    ROLL,
    TILT,
    Block,
    axes_from,
    e_matrix,
)
from align.fusion.plausible import admissible, not_excluded
from align.fusion.undetermined import Undetermined, default_sigma, undetermined
from align.loop import Candidate, LoopReport, LoopSummary, StageFit, Term, f_test, run_loop
from axisbase.covariance import cov_of
from axisbase.errors import NotApplicable
from axisbase.units import ARCSEC

TERM_WIDTH = {TILT: 2, LEVEL: 2}

NOMINAL_LIMIT_DEG = 10.0
"""How far an axis, a mark or a platform pose may lie from its declared nominal direction
[deg]. The fusion measures small angles: misalignments of arc-minutes, a table tilt and
camera rolls under a degree (session.toml caps a declared roll at 10°). A direction further
off is not a misalignment but a wrong declaration — images swapped, a pose label, a column
or a scale sign — and is refused naming it rather than fused (a 90° or 180° error would move
E by degrees)."""

U_MISJUDGED_MAX = 10.0
"""The most by which every stated uncertainty of a fusion may be too small together and the
result still be a measurement (a larger disagreement is gross: ``FusionResult.gross``). The
uncertainties come from the instruments' own scatter (a pose's sample standard deviation, a
line fit's residual, counter statistics); misjudged noise makes them too small by a few
times at most: samples correlated over the whole of a 50-sample pose — the worst case of
treating coloured noise as white — understate a mean's u by sqrt(50) ~ 7. Beyond ten times,
in all observations at once, the data do not describe one set-up — a sign, a label, a unit or
a file is wrong (a sign error moves E by hundreds of arc-seconds, many times even the
inflated u), or an effect no model here describes dominates (an undeclared K2 of 50 ug/g^2
that a 14-pose tumble cannot separate gives chi2/dof ~ 250) — and an inflated u is no longer
an uncertainty but a guess."""
TERM_UNIT = {TILT: "rad", REF: "rad", LEVEL: "rad"}


def _width(name: str) -> int:
    return TERM_WIDTH.get(name, 1)


@dataclass(frozen=True)
class Solution:
    """What one fit gives: parameters, covariance, whitened residuals, names."""

    params: np.ndarray
    cov: np.ndarray
    names: tuple[str, ...]
    residuals: np.ndarray
    predicted: tuple[np.ndarray, ...]
    layout: tuple[tuple[str, int], ...] = ()


class FusionStage:
    """The fusion as a stage of the residual loop (``fit(terms) -> StageFit``)."""

    def __init__(self, blocks: Sequence[Block]):
        if not blocks:
            raise InputError("fusion: no observations")
        self.blocks = list(blocks)
        self.whiten = [np.linalg.inv(np.linalg.cholesky(b.cov)) for b in self.blocks]
        self.base_nuis = ({"bias": 3} if any(b.source == "platform static" for b in blocks)
                          else {})
        self.n = sum(len(b.values) for b in self.blocks)
        # The fewest dof of an estimated covariance among the blocks (None: all stated): the
        # loop's effect and structure tests use F- and t-type nulls on it (align.loop) — a
        # bound, since each row's u was estimated on its own (their errors partly average).
        dofs = [b.noise_dof for b in self.blocks if b.noise_dof is not None]
        self.noise_dof = min(dofs) if dofs else None

    def _layout(self, terms: Sequence[Term]) -> list[tuple[str, int]]:
        return [*self.base_nuis.items(), *((t.name, _width(t.name)) for t in terms)]

    def _unpack(self, p: np.ndarray, layout: list[tuple[str, int]]
                ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        nuis, i = {}, 6
        for name, w in layout:
            nuis[name] = p[i:i + w]
            i += w
        return axes_from(p[:6]), nuis

    def _residual(self, p: np.ndarray, layout: list[tuple[str, int]]) -> np.ndarray:
        axes, nuis = self._unpack(p, layout)
        return np.concatenate([W @ (b.values - b.predict(axes, nuis))
                               for b, W in zip(self.blocks, self.whiten, strict=True)])

    def solve(self, terms: Sequence[Term] = ()) -> Solution:
        layout = self._layout(terms)
        names = E_NAMES + tuple(f"{n}[{k}]" if w > 1 else n for n, w in layout
                                for k in range(w))
        x0 = np.zeros(len(names))
        if self.n < len(x0):
            raise np.linalg.LinAlgError("fewer observations than parameters")
        res = least_squares(self._residual, x0, args=(layout,), method="lm", xtol=1e-14,
                            ftol=1e-14, x_scale=1e-3)
        off = np.arccos(np.clip(np.diag(axes_from(res.x[:6])), -1.0, 1.0))
        if off.max() > np.deg2rad(NOMINAL_LIMIT_DEG):
            if terms:  # a candidate that runs away is not this data's effect
                raise np.linalg.LinAlgError("the fit left the small angles")
            raise InputError(self._far_message(off))
        J = res.jac
        s = np.linalg.svd(J, compute_uv=False)
        if s[-1] < 1e-9 * s[0]:
            raise np.linalg.LinAlgError("parameters not separable by these observations")
        cov = np.linalg.inv(J.T @ J)
        axes, nuis = self._unpack(res.x, layout)
        pred = tuple(b.predict(axes, nuis) for b in self.blocks)
        return Solution(res.x, cov, names, res.fun, pred, tuple(layout))

    def jacobian(self, terms: Sequence[Term], params: np.ndarray) -> np.ndarray:
        """The whitened residuals' Jacobian (n × parameters) at ``params`` (E's six angles, the
        base nuisances, then ``terms``' components), by central differences."""
        layout = self._layout(terms)
        J = np.zeros((self.n, len(params)))
        step = 1e-7  # [rad, or g for the bias]: well inside the linear range, above rounding
        for k in range(len(params)):
            d = np.zeros(len(params))
            d[k] = step
            J[:, k] = (self._residual(params + d, layout)
                       - self._residual(params - d, layout)) / (2 * step)
        return J

    def _far_message(self, off: np.ndarray) -> str:
        """The refusal of observations that only an axis far from nominal would fit (``off``:
        each axis's angle from its nominal [rad]), naming those furthest from the nominal
        set-up (E = 0)."""
        k = int(np.argmax(off))
        layout = self._layout(())
        r0 = self._residual(np.zeros(6 + sum(w for _, w in layout)), layout)
        labels = [f"{b.source} {lab}" for b in self.blocks for lab in b.labels]
        worst = "; ".join(f"{labels[i]} ({r0[i]:+.3g} u)" for i in np.argsort(-np.abs(r0))[:3])
        return (f"fusion: the observations fit only with axis {'xyz'[k]} "
                f"{np.rad2deg(off[k]):.1f}° from its nominal (a misalignment is arc-minutes): "
                "they disagree "
                "with the declared set-up — a swapped column, a sign, a pose label or a file; "
                f"furthest from the nominal set-up: {worst}")

    def fit(self, terms: Sequence[Term]) -> StageFit:
        sol = self.solve(terms)
        u = np.sqrt(np.diag(sol.cov))
        effects, components = {}, {}
        i = 6 + sum(self.base_nuis.values())
        for t in terms:
            w = _width(t.name)
            vals, us = sol.params[i:i + w], u[i:i + w]
            if w == 1:
                effects[t.name] = (float(vals[0]), float(us[0]))
            else:
                # A vector effect's one number is its length (no one component stands for
                # it); its u from the components' covariance, to first order.
                size = float(np.linalg.norm(vals))
                C = sol.cov[i:i + w, i:i + w]
                g = vals / size if size > 0 else np.full(w, np.sqrt(1.0 / w))
                effects[t.name] = (size, float(np.sqrt(g @ C @ g)))
                components[t.name] = tuple((lab, float(v), float(uu)) for lab, v, uu in
                                           zip(("x", "y"), vals, us, strict=True))
            i += w
        quantities = {n: (float(sol.params[k]), float(u[k])) for k, n in enumerate(E_NAMES)}
        idx = np.arange(self.n, dtype=float)
        return StageFit(sol.residuals, np.ones(self.n), len(sol.params), {"index": idx},
                        "index", effects, quantities, components, payload=sol,
                        noise_dof=self.noise_dof)


def candidates(stage: FusionStage) -> tuple[Candidate, ...]:
    seen = {s for b in stage.blocks for s in b.sees}
    out = []
    for name in sorted(seen):
        if name.startswith(ROLL):
            desc = f"roll of camera {name[len(ROLL) + 1:-1]} about its optical axis"
        elif name == REF:
            desc = "azimuth offset of the goniometer's reference face"
        elif name == TILT:
            desc = "tilt of the table axis under the levelled platform (x, y)"
        elif name == LEVEL:
            # Separable from E_xZ, E_yZ only where the cameras see those angles (else the
            # solve finds it rank-deficient and the loop passes it by).
            desc = ("platform not level: the levelled poses' up direction off the platform's "
                    "Z (x, y), fixed on the platform")
        else:
            continue
        out.append(Candidate(
            name, "rad", desc,
            lambda fit, name=name: Term(name, "rad", np.zeros((fit.n, _width(name))))))
    return tuple(out)


@dataclass(frozen=True)
class ObservationRow:
    """One observation of the fusion beside what the fit predicts.

    Attributes
    ----------
    source : str
        The instrument or file it came from; unit —.
    label : str
        Which observation; unit —.
    value, predicted : float
        Observed and predicted value [``unit``].
    u : float
        Its standard uncertainty [``unit``].
    unit : str
        The unit of ``value``, ``predicted`` and ``u`` (``rad``, ``g``); unit —.
    """

    source: str
    label: str
    value: float
    predicted: float
    u: float
    unit: str

    @property
    def normalised(self) -> float:
        return (self.value - self.predicted) / self.u

    def to_dict(self) -> dict:
        return {"source": self.source, "label": self.label, "value": self.value,
                "predicted": self.predicted, "u": self.u, "unit": self.unit,
                "normalised_residual": self.normalised}

    @classmethod
    def from_dict(cls, d: Mapping) -> ObservationRow:
        return cls(str(d["source"]), str(d["label"]), float(d["value"]),
                   float(d["predicted"]), float(d["u"]), str(d["unit"]))


@dataclass(frozen=True)
class FusionResult:
    """The fused misalignment and how it was reached.

    Attributes
    ----------
    E : numpy.ndarray
        The misalignment (3×3, row i accelerometer, column j platform axis, zero diagonal)
        [rad].
    E_u : numpy.ndarray
        Its standard uncertainties (3×3) [rad].
    cov : numpy.ndarray
        The 6×6 covariance over ``E_NAMES`` [rad²]; :meth:`cov_of` reads it by name.
    axes : numpy.ndarray
        The unit axes (rows of M) in the platform frame — dimensionless.
    chi2 : float
        χ² of the final fit — dimensionless.
    dof : int
        Its degrees of freedom — dimensionless.
    p_value : float
        P(χ² ≥ chi2) — dimensionless.
    rows : tuple of ObservationRow
        Per observation (their fields carry units); unit —.
    loop : LoopReport or LoopSummary
        The loop's before/after; unit —.
    inflation : float
        > 1 when unexplained inconsistency remains and the uncertainties were scaled by
        sqrt(chi2/dof) — dimensionless.
    nuisances : dict
        Per nuisance the loop added: (estimate, u) [rad].
    sources : tuple of str
        The sources fused; unit —.
    budget : Budget or None
        Each input's share of u² of every angle (:mod:`align.fusion.budget`); unit —.
    disagreement : SourceDisagreement or None
        When inconsistent: the source that sees another E, and in which angles (None: none
        singled out, or consistent; :mod:`align.fusion.diagnosis`); unit —.
    undetermined : tuple of Undetermined
        The nuisances the data cannot determine, carried in ``cov`` over their plausible
        range (:mod:`align.fusion.undetermined`); unit —.
    """

    E: np.ndarray
    E_u: np.ndarray
    cov: np.ndarray
    axes: np.ndarray
    chi2: float
    dof: int
    p_value: float
    rows: tuple[ObservationRow, ...]
    loop: LoopReport | LoopSummary
    inflation: float
    nuisances: dict[str, tuple[float, float]]
    sources: tuple[str, ...]
    budget: Budget | None = None
    """Each input's share of u² of every angle (:mod:`align.fusion.budget`)."""
    # When inconsistent: the source that sees another E, and in which angles (None: none
    # singled out, or consistent). See :mod:`align.fusion.diagnosis`.
    disagreement: SourceDisagreement | None = None
    undetermined: tuple[Undetermined, ...] = ()
    """The nuisances the data cannot determine, carried in ``cov`` over their plausible range
    (:mod:`align.fusion.undetermined`)."""

    def cov_of(self, *names: str) -> np.ndarray:
        """The covariance [rad²] of the named angles of E (``E_NAMES``, e.g.
        ``cov_of("E_xY", "E_zX")``) in the order given."""
        return cov_of(self.cov, E_NAMES, names)

    @property
    def consistent(self) -> bool:
        return not self.loop.unexplained_structure

    @property
    def gross_bound(self) -> float:
        """The chi2 beyond which the disagreement is gross: even with every uncertainty
        :data:`U_MISJUDGED_MAX` times larger, chi2 would exceed its upper 1e-3 quantile."""
        return float(U_MISJUDGED_MAX**2 * special.chdtri(max(self.dof, 1), 1e-3))

    @property
    def gross(self) -> bool:
        """The instruments disagree beyond any misjudgement of their noise (see
        :data:`U_MISJUDGED_MAX`): E is not a measurement, whatever its inflated u says."""
        return self.dof > 0 and self.chi2 > self.gross_bound

    def worst_rows(self, n: int = 3) -> list[ObservationRow]:
        """The ``n`` observations with the largest normalised residuals."""
        return sorted(self.rows, key=lambda r: -abs(r.normalised))[:n]

    def gross_message(self) -> str:
        """One line for a gross disagreement: chi2 against its bound, the worst observations."""
        worst = "; ".join(f"{r.source} {r.label} ({r.normalised:+.3g} u)"
                          for r in self.worst_rows())
        return (f"the instruments grossly disagree: chi2 {self.chi2:.4g} / {self.dof} dof, "
                f"beyond {self.gross_bound:.3g} (what even uncertainties "
                f"{U_MISJUDGED_MAX:g} times too small would give): E is not a measurement — "
                "a wrong input (a sign, a pose label, a unit, a mirrored or swapped image) or "
                "an effect no model here describes (see the other warnings); worst "
                f"observations: {worst}"
                + (f"; {self.disagreement.message()}" if self.disagreement else ""))

    def to_dict(self) -> dict:
        """The fusion's part of a session result: E [rad] and [″] with u, the 6×6 covariance
        over ``angle_names`` [rad²], the axes, χ², the loop's effects and every observation
        with its normalised residual."""
        return {
            "misalignment_rad": self.E.tolist(), "misalignment_u_rad": self.E_u.tolist(),
            "misalignment_arcsec": (self.E / ARCSEC).tolist(),
            "misalignment_u_arcsec": (self.E_u / ARCSEC).tolist(),
            "angle_names": list(E_NAMES), "covariance_rad2": self.cov.tolist(),
            "axes": self.axes.tolist(), "chi2": self.chi2, "dof": self.dof,
            "p_value": self.p_value, "uncertainty_inflation": self.inflation,
            "sources": list(self.sources), **self.loop.summary().to_dict(),
            "nuisances": {k: {"estimate": v[0], "u": v[1]} for k, v in self.nuisances.items()},
            "observations": [r.to_dict() for r in self.rows],
            "budget": None if self.budget is None else self.budget.to_dict(),
            "source_disagreement": (None if self.disagreement is None
                                    else self.disagreement.to_dict()),
            "undetermined": [c.to_dict() for c in self.undetermined]}

    @classmethod
    def from_dict(cls, d: Mapping) -> FusionResult:
        """From :meth:`to_dict`'s keys (a session result JSON); the loop comes back as its
        :class:`~align.loop.LoopSummary`."""
        if list(d.get("angle_names", E_NAMES)) != list(E_NAMES):
            raise ValueError(f"angle_names {d.get('angle_names')} are not {list(E_NAMES)}")
        return cls(np.array(d["misalignment_rad"], float), np.array(d["misalignment_u_rad"], float),
                   np.array(d["covariance_rad2"], float), np.array(d["axes"], float),
                   float(d["chi2"]), int(d["dof"]), float(d["p_value"]),
                   tuple(ObservationRow.from_dict(r) for r in d.get("observations", ())),
                   LoopSummary.from_dict(d), float(d.get("uncertainty_inflation", 1.0)),
                   {k: (float(v["estimate"]), float(v["u"]))
                    for k, v in d.get("nuisances", {}).items()},
                   tuple(d.get("sources", ())),
                   Budget.from_dict(d["budget"]) if d.get("budget") else None,
                   (None if not d.get("source_disagreement")
                    else disagreement_from_dict(d["source_disagreement"])),
                   tuple(Undetermined.from_dict(c) for c in d.get("undetermined", ())))


def _check_determined(stage: FusionStage) -> None:
    """Raise naming the angles no combination of the sources determines (linearised at 0)."""
    p0 = np.zeros(6 + sum(w for _, w in stage._layout(())))
    J = stage.jacobian((), p0)
    _, s, vt = np.linalg.svd(J)
    s = np.concatenate([s, np.zeros(len(p0) - len(s))])
    null = vt[s < 1e-9 * max(s[0], 1e-300)]
    if not len(null):
        return
    weak = [E_NAMES[k] for k in range(6) if np.any(np.abs(null[:, k]) > 0.1)]
    raise InputError("fusion: the sources given do not determine the misalignment "
                     f"({', '.join(weak) or 'some combination'} undetermined); add a camera "
                     "view, the goniometer log or platform static poses")


def _held(lin: Linearisation, stage: FusionStage, loop: LoopReport,
          cands: Mapping[str, Candidate], extra: Sequence[tuple[str, int]]) -> Linearisation:
    """``lin`` with its last nuisances (``extra``: the carried candidates) held, each with
    its estimate when freed alone with the loop's terms (its components) [rad] and the
    p-value of the loop's test of it."""
    nuis = list(lin.nuisances)
    held = []
    for (name, _), (_, idx) in zip(extra, nuis[len(nuis) - len(extra):], strict=True):
        try:
            fit = stage.fit([*loop.terms, cands[name].build(loop.after)])
        except (NotApplicable, np.linalg.LinAlgError):
            # Carried as an alternative to a named effect it cannot be freed beside (the two
            # not separable): held at zero, its estimate unknown to the plan (p 1: the loop
            # would not name it beside the other).
            held.append((name, idx, (0.0,) * len(idx), 1.0))
            continue
        trial = fit.payload
        k = next(i for i, (n, _) in enumerate(trial.layout) if n == name)
        at = 6 + sum(w for _, w in trial.layout[:k])
        held.append((name, idx, tuple(float(v) for v in trial.params[at:at + len(idx)]),
                     f_test(loop.after, fit, len(idx))))
    return replace(lin, nuisances=tuple(nuis[:len(nuis) - len(extra)]), held=tuple(held))


def fuse(blocks: Sequence[Block], alpha: float = 1e-3,
         plausible_u: Mapping[str, float] | None = None) -> FusionResult:
    """Solve for E with the residual loop over the nuisance candidates; ``plausible_u``: the
    declared standard uncertainty [rad] of a nuisance's plausible range by name (a camera's
    roll, the reference face's offset; else the default range,
    :mod:`align.fusion.undetermined`), carried in u where the data cannot determine it."""
    stage = FusionStage(blocks)
    _check_determined(stage)
    cands = candidates(stage)
    # A nuisance beyond any set-up error is refused, never an explanation; a refusal an
    # effect added later explains is dropped — what is not excluded is carried in u below
    # (align/fusion/plausible.py).
    loop = run_loop(stage, cands, alpha=alpha, admissible=admissible, retest_refused=True)
    fit = loop.after
    sol: Solution = fit.payload
    inflation = 1.0
    p_value = float(special.chdtrc(max(fit.dof, 1), fit.chi2))
    if loop.unexplained_structure and fit.dof > 0:
        inflation = float(max(1.0, np.sqrt(fit.chi2 / fit.dof)))
    cov = sol.cov[:6, :6] * inflation**2
    E = e_matrix(sol.params[:6])
    E_u = e_matrix(np.sqrt(np.diag(cov)))
    rows = []
    for b, pred in zip(stage.blocks, sol.predicted, strict=True):
        for k, (lab, v, p, u) in enumerate(zip(b.labels, b.values, pred, b.u, strict=True)):
            rows.append(ObservationRow(b.source, lab, float(v), float(p), float(u),
                                       b.unit_of(k)))
    nuis = {n: (float(sol.params[k]), float(np.sqrt(cov_of(sol.cov, sol.names, (n,))[0, 0]))
                * inflation) for k, n in enumerate(sol.names) if k >= 6}
    sources = tuple(dict.fromkeys(b.source for b in stage.blocks))
    named = None
    if loop.unexplained_structure and len(sources) > 1:
        layout = stage._layout(loop.terms)
        starts = np.cumsum([0, *(len(b.values) for b in stage.blocks)])
        rows_of = [(src, np.concatenate([np.arange(starts[k], starts[k + 1])
                                         for k, b in enumerate(stage.blocks)
                                         if b.source == src])) for src in sources]
        def resid(p: np.ndarray) -> np.ndarray:
            return stage._residual(p, layout)

        J = jacobian(resid, sol.params)
        named = name_disagreement(leave_one_source_out(resid, sol.params, rows_of, J), alpha)
        if named is not None and "platform static" in (named.source, *named.also):
            named = with_pairs(named, resid(sol.params), J, stage.blocks, stage.whiten, starts,
                               alpha)
    if named is not None:
        # Where two sources see different E, E in those angles is the one or the other (or
        # in between): the fused value sits with the more precise source, so u is widened
        # by the whole disagreement (a Type B term, uncorrelated) — the inflation by
        # sqrt(chi2/dof) spreads it over all six angles and covers a 30″ creep by a third.
        widen = np.zeros(6)
        for n, d, _ in named.angles:
            widen[E_NAMES.index(n)] = d**2
        cov = cov + np.diag(widen)
        E_u = e_matrix(np.sqrt(np.diag(cov)))
    # The candidates the data cannot determine: carried over their plausible range (Type B);
    # first, as the rest (determined) are judged by whether the data can exclude them: their
    # shift of E joins its covariance (Type B).
    unknown = undetermined(stage, cands, loop, sol.params, inflation, plausible_u)
    carried = not_excluded(stage, cands, loop, cov, alpha, skip=[c.name for c in unknown])
    for c in carried:
        cov = cov + np.outer(c.shift, c.shift)
    for c in unknown:
        cov = cov + np.outer(c.shift, c.shift)
    if carried or unknown:
        E_u = e_matrix(np.sqrt(np.diag(cov)))
    # The carried and the undetermined candidates' columns join the linearisation held at
    # zero: what freeing them would do, from which 'align plan' predicts whether a
    # measurement resolves them.
    # So do the loop's other candidates: beside an effect a measurement makes the loop name,
    # one of them may no longer be determined (the plan judges them by these rules).
    extra = [(c.name, _width(c.name)) for c in carried]
    ranged = [(c.name, _width(c.name)) for c in unknown]
    judged = {t.name for t in loop.terms} | {n for n, _ in (*extra, *ranged)}
    others = [(c.name, _width(c.name)) for c in cands if c.name not in judged]
    extra += ranged + others
    layout = [*sol.layout, *extra]
    params = np.concatenate([sol.params, np.zeros(sum(w for _, w in extra))])
    names = [*sol.names, *(f"{n}[{k}]" if w > 1 else n for n, w in extra for k in range(w))]

    def predict_all(p: np.ndarray) -> list[np.ndarray]:
        axes, nu = stage._unpack(p, layout)
        return [b.predict(axes, nu) for b in stage.blocks]

    lin = linearise(stage.blocks, predict_all, params, names, layout, inflation)
    sigmas = {c.name: (plausible_u or {}).get(c.name, default_sigma(c.name)) for c in cands}
    at = len(lin.nuisances) - len(others)
    lin = replace(lin, nuisances=lin.nuisances[:at], others=tuple(
        (n, idx) for (n, _), (_, idx) in zip(others, lin.nuisances[at:], strict=True)),
        ranges=tuple((n, float(s)) for n, s in sigmas.items() if s is not None),
        declared=tuple(n for n in sigmas if n in (plausible_u or {})))
    if unknown:
        at = len(lin.nuisances) - len(ranged)
        lin = replace(lin, nuisances=lin.nuisances[:at], ranged=tuple(
            (c.name, idx, c.sigma) for c, (_, idx) in
            zip(unknown, lin.nuisances[at:], strict=True)))
    if carried:
        lin = _held(lin, stage, loop, {c.name: c for c in cands}, extra[:len(carried)])
    budget = lin.budget()
    if named is not None:
        budget = with_disagreement(budget, named)
    for c in carried:
        budget = with_type_b(budget, c.label, dict(zip(E_NAMES, c.shift**2, strict=True)))
    # (Type B beside the linearisation, as the carried candidates': 'align plan' predicts
    # them from the ranged columns, align/plan_carried.py)
    for c in unknown:
        budget = with_type_b(budget, c.label, dict(zip(E_NAMES, c.shift**2, strict=True)))
    return FusionResult(E, E_u, cov, axes_from(sol.params[:6]), fit.chi2, fit.dof, p_value,
                        tuple(rows), loop, inflation, nuis, sources, budget, named,
                        tuple(unknown))
