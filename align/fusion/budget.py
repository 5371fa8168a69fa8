"""The uncertainty budget of E from the fused solve's linearisation (JCGM 100 §5.1.3).

At the solution the weighted least squares is linear: with A_g = d(prediction of group g)/dp
(n_g × P, p = the six angles then the nuisances) and C_g its covariance, the information is
I = Σ_g A_gᵀ C_g⁻¹ A_g and cov(p) = I⁻¹. A *group* is what the budget names: each image (a
row of the camera block: its rows are independent), the goniometer log, the calibration, the
static poses.

The budget splits u²(E_ij) into parts that add up exactly:

* **data** — with the nuisances held at their values the estimate is E = G·y with the gain
  G_g = V₀ A_{g,E}ᵀ C_g⁻¹, V₀ = (I_EE)⁻¹, so V₀ = Σ_g G_g C_g G_gᵀ: each group's share is
  G_g C_g G_gᵀ; a Type B term inside C_g (C_g = C_g,A + Σ_b B_b) is its own share G_g B_b G_gᵀ;
* **nuisances** — estimating the nuisances widens V₀ to the marginal cov(E) = (I⁻¹)_EE; each
  nuisance's share is the increase when it is freed, in the order the model holds them (the
  calibration's bias error first, then the loop's terms in the order it added them);
* when the loop left unexplained scatter and inflated u by the factor f = √(χ²/dof), every
  share is multiplied by f² (``inflation``).

The same algebra predicts u for changed data (:meth:`Linearisation.u_with`): remove a group
(leave-one-out) or add a hypothetical one, and invert the new information.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from align.fusion.observations import E_NAMES
from axisbase.units import ARCSEC

FORMAT_VERSION = 1
KINDS = ("image", "gonio", "calibration", "static", "typeB", "nuisance")
_BLOCK_KIND = {"camera": "image", "goniometer": "gonio", "ellipsoid": "calibration",
               "platform static": "static"}
SHARED_PREFIX = "lens of camera "
"""How a shared lens error is named (align.fusion.observations.mark_block)."""
NUISANCE_LABEL = {"bias": "calibration bias error", "camera_roll": "camera roll",
                  "reference_face_offset": "reference face offset",
                  "platform_tilt": "table-axis tilt", "platform_level": "platform levelling offset"}


def inverse(info: np.ndarray) -> np.ndarray:
    """The covariance from an information matrix, inverted in its correlation form (the
    parameters mix radians and g, and a prior may be far stronger than the data): LinAlgError
    when the observations do not determine every parameter."""
    d = np.sqrt(np.clip(np.diag(info), 0.0, None))
    if np.any(d == 0):
        raise np.linalg.LinAlgError("the observations do not determine every parameter")
    scaled = info / np.outer(d, d)
    s = np.linalg.svd(scaled, compute_uv=False)
    if s[-1] <= 1e-12 * s[0]:
        raise np.linalg.LinAlgError("the observations do not determine every parameter")
    return np.linalg.inv(scaled) / np.outer(d, d)


@dataclass(frozen=True)
class Group:
    """One named input of the fusion.

    Attributes
    ----------
    source : str
        Its name ("image x_A.png", "goniometer gonio.csv", "calibration", "static poses"); unit —.
    kind : str
        One of ``KINDS``; unit —.
    A : numpy.ndarray
        The Jacobian (n, P) of its predicted values over the parameters [value unit / parameter
        unit].
    C : numpy.ndarray
        Their covariance (n, n) [value unit²].
    type_b : tuple of (str, numpy.ndarray)
        Its Type B parts (name, (n, n)) [value unit²], included in ``C``.
    meta : Mapping
        An image's housing, view, camera; unit —.
    """

    source: str
    kind: str
    A: np.ndarray
    C: np.ndarray
    type_b: tuple[tuple[str, np.ndarray], ...] = ()
    meta: Mapping[str, str] = field(default_factory=dict)

    def information(self) -> np.ndarray:
        Ci = np.linalg.inv(self.C)
        return self.A.T @ Ci @ self.A

    def to_dict(self) -> dict:
        return {"source": self.source, "kind": self.kind, "A": self.A.tolist(),
                "C": self.C.tolist(), "meta": dict(self.meta),
                "type_b": [{"name": n, "C": c.tolist()} for n, c in self.type_b]}

    @classmethod
    def from_dict(cls, d: Mapping) -> Group:
        return cls(str(d["source"]), str(d["kind"]), np.array(d["A"], float),
                   np.array(d["C"], float),
                   tuple((str(t["name"]), np.array(t["C"], float)) for t in d.get("type_b", ())),
                   dict(d.get("meta", {})))


@dataclass(frozen=True)
class Linearisation:
    """The fused solve linearised at its solution.

    Attributes
    ----------
    params : tuple of str
        Parameter names: the six E_NAMES first, then the nuisances, each nuisance named once
        per component; unit —.
    groups : tuple of Group
        The inputs (their fields carry units); unit —.
    nuisances : tuple of (str, tuple of int)
        The nuisance groups (label, parameter indices) in the order they are freed — dimensionless.
    inflation : float
        The inflation factor f applied to cov(E) — dimensionless.
    held : tuple of (str, tuple of int, tuple of float, float)
        The candidates the fusion carries as not excluded (:mod:`align.fusion.plausible`):
        name, parameter indices, estimate when freed [rad], and the p-value of the loop's
        own test of it (``align.loop.f_test``, before the look-elsewhere corrections). Their
        columns are in every group's ``A`` (what freeing them would do, for ``align plan``)
        but they are held at zero: u, cov(E) and the budget leave them out (their Type B
        share is added apart).
    ranged : tuple of (str, tuple of int, float)
        The nuisances the fusion cannot determine, carried over their plausible range
        (:mod:`align.fusion.undetermined`): name, parameter indices, and the standard
        uncertainty of the range [rad]. Held at zero like ``held`` (their Type B share is
        added apart); ``align plan`` frees them to predict their u after a measurement.
    others : tuple of (str, tuple of int)
        The loop's other candidates (tested, neither named, carried nor undetermined): name
        and parameter indices, held at zero like ``held``. ``align plan`` judges them after a
        measurement by the fusion's rules (:func:`align.fusion.plausible.judge`): beside an
        effect the new data name, one may become undetermined; unit —.
    ranges : tuple of (str, float)
        The standard uncertainty of the plausible range [rad] of each candidate that has one
        (a camera's roll, the reference face's offset), declared in session.toml or the
        default (:func:`align.fusion.undetermined.default_sigma`).
    declared : tuple of str
        The candidates of ``ranges`` whose σ session.toml declares (the others': the
        default), as the fusion's warnings name them; unit —.
    """

    params: tuple[str, ...]
    groups: tuple[Group, ...]
    nuisances: tuple[tuple[str, tuple[int, ...]], ...]
    inflation: float = 1.0
    held: tuple[tuple[str, tuple[int, ...], tuple[float, ...], float], ...] = ()
    ranged: tuple[tuple[str, tuple[int, ...], float], ...] = ()
    others: tuple[tuple[str, tuple[int, ...]], ...] = ()
    ranges: tuple[tuple[str, float], ...] = ()
    declared: tuple[str, ...] = ()

    @property
    def free(self) -> np.ndarray:
        """The indices of the parameters estimated (all but the ``held``, ``ranged`` and
        ``others`` ones)."""
        held = {i for _, idx, *_ in (*self.held, *self.ranged, *self.others) for i in idx}
        return np.array([i for i in range(len(self.params)) if i not in held], int)

    def information(self, groups: Sequence[Group] | None = None) -> np.ndarray:
        """The information over every parameter, ``held`` ones included."""
        gs = self.groups if groups is None else groups
        return sum((g.information() for g in gs), np.zeros((len(self.params),) * 2))

    def _free_information(self, groups: Sequence[Group] | None = None) -> np.ndarray:
        f = self.free
        return self.information(groups)[np.ix_(f, f)]

    def cov_e(self, groups: Sequence[Group] | None = None) -> np.ndarray:
        """cov(E) [rad²] (6×6, inflated) from these groups (default: the session's)."""
        return inverse(self._free_information(groups))[:6, :6] * self.inflation**2

    def u_with(self, add: Sequence[Group] = (), drop: Sequence[str] = ()) -> np.ndarray:
        """u of the six angles [rad] with the groups named in ``drop`` left out and ``add``
        added (LinAlgError when the rest no longer determine the parameters)."""
        gs = [g for g in self.groups if g.source not in drop] + list(add)
        return np.sqrt(np.diag(inverse(self._free_information(gs)))[:6]) * self.inflation

    def budget(self) -> Budget:
        """Every angle's u² split into the groups', Type B terms' and nuisances' shares."""
        I = self.information()  # noqa: E741 (the information matrix; held rows unused)
        V0 = inverse(I[:6, :6])
        shares: list[tuple[str, str, np.ndarray]] = []
        for g in self.groups:
            if not np.any(g.A[:, :6]):  # a prior on shared errors: its share is below
                continue
            K = V0 @ g.A[:, :6].T @ np.linalg.inv(g.C)  # the gain of this group's values
            CA = g.C - sum((c for _, c in g.type_b), np.zeros_like(g.C))
            shares.append((g.source, g.kind, np.diag(K @ CA @ K.T)))
            shares += [(n, "typeB", np.diag(K @ c @ K.T)) for n, c in g.type_b]
        free = list(range(6))
        prev = np.diag(V0)
        for label, idx in self.nuisances:
            free += list(idx)
            now = np.diag(inverse(I[np.ix_(free, free)]))[:6]
            if label.startswith(SHARED_PREFIX):  # a camera's lens: Type B, not a nuisance
                shares.append((label, "typeB", now - prev))
            else:
                shares.append((f"nuisance: {label}", "nuisance", now - prev))
            prev = now
        f2 = self.inflation**2
        angles = {}
        for k, name in enumerate(E_NAMES):
            u2 = prev[k] * f2
            rows = sorted(((s, kd, float(v[k] * f2)) for s, kd, v in shares),
                          key=lambda r: -r[2])
            angles[name] = (float(np.sqrt(u2)), tuple(
                Contribution(s, kd, v, v / u2 if u2 > 0 else 0.0) for s, kd, v in rows))
        return Budget(angles, self.inflation, self)

    def to_dict(self) -> dict:
        return {"parameters": list(self.params), "inflation": self.inflation,
                "nuisances": [{"label": n, "index": list(i)} for n, i in self.nuisances],
                "held": [{"name": n, "index": list(i), "estimate_rad": list(e), "loop_p": p}
                         for n, i, e, p in self.held],
                "ranged": [{"name": n, "index": list(i), "sigma_rad": s}
                           for n, i, s in self.ranged],
                "others": [{"name": n, "index": list(i)} for n, i in self.others],
                "ranges": [{"name": n, "sigma_rad": s} for n, s in self.ranges],
                "declared": list(self.declared),
                "groups": [g.to_dict() for g in self.groups]}

    @classmethod
    def from_dict(cls, d: Mapping) -> Linearisation:
        return cls(tuple(d["parameters"]), tuple(Group.from_dict(g) for g in d["groups"]),
                   tuple((str(n["label"]), tuple(int(i) for i in n["index"]))
                         for n in d["nuisances"]), float(d.get("inflation", 1.0)),
                   tuple((str(h["name"]), tuple(int(i) for i in h["index"]),
                          tuple(float(e) for e in h["estimate_rad"]), float(h["loop_p"]))
                         for h in d.get("held", ())),
                   tuple((str(h["name"]), tuple(int(i) for i in h["index"]),
                          float(h["sigma_rad"])) for h in d.get("ranged", ())),
                   tuple((str(h["name"]), tuple(int(i) for i in h["index"]))
                         for h in d.get("others", ())),
                   tuple((str(h["name"]), float(h["sigma_rad"])) for h in d.get("ranges", ())),
                   tuple(str(n) for n in d.get("declared", ())))


@dataclass(frozen=True)
class Contribution:
    """One input's share of an angle's variance: ``u2`` [rad²] and its ``fraction`` of u²."""

    source: str
    kind: str
    u2: float
    fraction: float


@dataclass(frozen=True)
class Budget:
    """Each input's share of u² of every angle.

    Attributes
    ----------
    angles : Mapping
        Per angle name: (u [rad], contributions largest first, summing to u² [rad²]).
    inflation : float
        The inflation applied — dimensionless.
    model : Linearisation or None
        The linearisation it came from (what 'align plan' works on); unit —.
    """

    angles: Mapping[str, tuple[float, tuple[Contribution, ...]]]
    inflation: float = 1.0
    model: Linearisation | None = None

    def to_dict(self) -> dict:
        a2 = ARCSEC**2
        return {"format_version": FORMAT_VERSION, "inflation": self.inflation,
                "angles": {n: {"u_arcsec": u / ARCSEC, "contributions": [
                    {"source": c.source, "kind": c.kind, "u2_arcsec2": c.u2 / a2,
                     "fraction": c.fraction} for c in cs]}
                    for n, (u, cs) in self.angles.items()},
                "model": None if self.model is None else self.model.to_dict()}

    @classmethod
    def from_dict(cls, d: Mapping) -> Budget:
        a2 = ARCSEC**2
        angles = {n: (float(v["u_arcsec"]) * ARCSEC, tuple(
            Contribution(str(c["source"]), str(c["kind"]), float(c["u2_arcsec2"]) * a2,
                         float(c["fraction"])) for c in v["contributions"]))
            for n, v in d["angles"].items()}
        m = d.get("model")
        return cls(angles, float(d.get("inflation", 1.0)),
                   None if m is None else Linearisation.from_dict(m))

    def table_lines(self, top: int = 6) -> list[str]:
        """The terminal's budget: per angle, u and its ``top`` largest shares."""
        out = ["uncertainty budget (share of u², largest first"
               + (f"; every share × {self.inflation:.2f}² for the unexplained scatter"
                  if self.inflation > 1 else "") + "):"]
        for n, (u, cs) in self.angles.items():
            out.append(f"  {n}: u = {u / ARCSEC:.3f}″")
            for c in cs[:top]:
                out.append(f"    {100 * c.fraction:5.1f} %  {np.sqrt(max(c.u2, 0)) / ARCSEC:7.3f}″"
                           f"  {c.source} ({c.kind})")
            if len(cs) > top:
                rest = sum(c.fraction for c in cs[top:])
                out.append(f"    {100 * rest:5.1f} %  (the other {len(cs) - top})")
        return out


def with_type_b(budget: Budget, label: str, widen: Mapping[str, float]) -> Budget:
    """The budget with a Type B share ``label`` of ``widen[angle]`` [rad²] added to the angles
    named, their u and fractions recomputed."""
    angles = {}
    for n, (u, cs) in budget.angles.items():
        if n not in widen:
            angles[n] = (u, cs)
            continue
        u2 = u**2 + widen[n]
        parts = [Contribution(c.source, c.kind, c.u2, c.u2 / u2) for c in cs]
        parts.append(Contribution(label, "typeB", widen[n], widen[n] / u2))
        angles[n] = (float(np.sqrt(u2)), tuple(sorted(parts, key=lambda c: -c.u2)))
    return replace(budget, angles=angles)


def linearise(blocks: Sequence, predict_all, params: np.ndarray, names: Sequence[str],
              layout: Sequence[tuple[str, int]], inflation: float) -> Linearisation:
    """The linearisation at ``params``: ``predict_all(p) -> [prediction of each block]``;
    ``layout`` the nuisance groups (name, width) after the six angles."""
    P = len(params)
    step = 1e-7  # [rad, or g for the bias]: well inside the linear range, far above rounding
    jac = [np.zeros((len(b.values), P)) for b in blocks]
    for k in range(P):
        d = np.zeros(P)
        d[k] = step
        plus, minus = predict_all(params + d), predict_all(params - d)
        for J, a, b in zip(jac, plus, minus, strict=True):
            J[:, k] = (a - b) / (2 * step)
    # Errors several rows share (a camera's lens, Block.shared) are parameters with a unit
    # prior here: the rows stay independent given them (each image its own group), and the
    # same GLS follows (C = D + G Gᵀ marginalised is D with G's errors estimated).
    shared = [(j, name, rows, G) for j, b in enumerate(blocks) for name, rows, G in b.shared]
    m = sum(G.shape[1] for *_, G in shared)
    names = [*names, *(f"{name}[{k}]" for _, name, _, G in shared for k in range(G.shape[1]))]
    jac = [np.hstack([J, np.zeros((len(J), m))]) for J in jac]
    lens_nuis, col = [], P
    groups: list[Group] = []
    for j, name, rows, G in shared:
        J = jac[j]
        w = G.shape[1]
        J[list(rows), col:col + w] = G
        prior = np.zeros((w, P + m))
        prior[:, col:col + w] = np.eye(w)
        groups.append(Group(name, "typeB", prior, np.eye(w)))
        lens_nuis.append((name, tuple(range(col, col + w))))
        col += w
    for b, J in zip(blocks, jac, strict=True):
        kind = _BLOCK_KIND.get(b.source, b.source)
        if b.row_sources:
            own = b.cov.copy()
            for _, rows, G in b.shared:
                own[np.ix_(rows, rows)] -= G @ G.T
            for r, src in enumerate(b.row_sources):
                meta = b.row_meta[r] if b.row_meta else {}
                groups.append(Group(src, kind, J[r:r + 1], own[r:r + 1, r:r + 1], (), meta))
        else:
            groups.append(Group(b.budget_source or b.source, kind, J, b.cov, b.type_b))
    nuis, i = list(lens_nuis), 6
    for name, w in layout:
        base = name.split("[")[0]
        label = NUISANCE_LABEL.get(base, base)
        if "[" in name:  # camera_roll[A]
            label += " " + name[name.index("[") + 1:-1]
        nuis.append((label, tuple(range(i, i + w))))
        i += w
    return Linearisation(tuple(names), tuple(groups), tuple(nuis), inflation)

