"""Observation equations of every instrument for the misalignment E (exact, not first order).

Frames (design.md): platform P with X, Y horizontal and Z up; accelerometer i's sensing axis
s_i = normalise(e_i + sum_j E_ij e_j), E with zero diagonal [rad]. Every observation block holds
measured values, their covariance and a ``predict(axes, nuis)`` giving the same quantities from
the unit axes (rows of a 3x3 array) and the nuisance parameters (name -> array) the loop has
added. Angles in radians, readings in g.

* camera mark: the angle of s_i projected on a view's (right, up) plane,
  atan2(s.up, s.right), minus its nominal (0 horizontal, pi/2 vertical), wrapped to a half turn,
  plus the roll of the view's camera;
* goniometer face: the azimuth of housing i's face normal (along +-s_i's horizontal projection)
  relative to the reference face, minus nominal; the reference face's own azimuth offset is a
  nuisance;
* ellipsoid: cosines of the angles between the calibrated axes (the calibration's own frame
  floats, angles between its axes do not);
* platform static: a calibrated off-axis reading w_i = |r_i| s_i . g of a pose whose gravity
  direction g in P is known (levelled at a table angle; the table axis's tilt turns with the
  table angle), with the calibration's bias error as a nuisance whose prior sits in the
  ellipsoid block (jointly with beta: one fit gave both).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from align.calibration import r_matrix

Nuisances = Mapping[str, np.ndarray]
HOUSINGS = ("x", "y", "z")
# E's six off-diagonal angles in parameter order: (row i, column j).
E_INDEX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
E_NAMES = tuple(f"E_{HOUSINGS[i]}{'XYZ'[j]}" for i, j in E_INDEX)
ROLL = "camera_roll"
REF = "reference_face_offset"
TILT = "platform_tilt"
LEVEL = "platform_level"


def wrap_half(a: np.ndarray | float) -> np.ndarray:
    """Wrap line directions to [-pi/2, pi/2)."""
    return (np.asarray(a) + np.pi / 2) % np.pi - np.pi / 2


def axes_from(e6: np.ndarray) -> np.ndarray:
    """Unit sensing axes (rows) from the six small angles in ``E_INDEX`` order."""
    S = np.eye(3)
    for v, (i, j) in zip(e6, E_INDEX, strict=True):
        S[i, j] = v
    return S / np.linalg.norm(S, axis=1, keepdims=True)


def e_matrix(e6: np.ndarray) -> np.ndarray:
    E = np.zeros((3, 3))
    for v, (i, j) in zip(e6, E_INDEX, strict=True):
        E[i, j] = v
    return E


@dataclass(frozen=True)
class Block:
    """Observations of one source: ``values`` (n,), ``cov`` (n, n), ``labels``, and
    ``predict(axes, nuis) -> (n,)``. ``unit`` names what the values are (rad or g)."""

    source: str
    labels: tuple[str, ...]
    values: np.ndarray
    cov: np.ndarray
    predict: Callable[[np.ndarray, Nuisances], np.ndarray]
    unit: str | tuple[str, str] = "rad"  # or (unit of the first 3, unit of the rest)
    # Which nuisance names this block can see (for identifiability messages).
    sees: tuple[str, ...] = ()
    # For the uncertainty budget (align.fusion.budget): what the block is called there
    # ("goniometer gonio.csv"; default: ``source``); for blocks of independent rows (a
    # diagonal cov), one name per row ("image x_A.png") and what each row is (housing, view,
    # camera); the Type B parts of ``cov`` (name, (n, n) covariance), each included in it.
    budget_source: str = ""
    row_sources: tuple[str, ...] = ()
    row_meta: tuple[Mapping[str, str], ...] = ()
    type_b: tuple[tuple[str, np.ndarray], ...] = ()
    # Degrees of freedom of a covariance *estimated* from the data (the fewest of its rows':
    # a pose mean's u from the scatter of its n samples has n - 1), None when stated; the
    # fusion's tests then take the estimate's error into their null distributions.
    noise_dof: float | None = None
    # Errors several rows share, included in ``cov`` (name, rows, G: len(rows) × m): the rows'
    # covariance holds G Gᵀ, i.e. m unit-variance errors (a camera's lens) reach those rows
    # with the weights G. The budget carries them as the parameters they are (budget.py).
    shared: tuple[tuple[str, tuple[int, ...], np.ndarray], ...] = ()

    @property
    def u(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov))

    def unit_of(self, k: int) -> str:
        if isinstance(self.unit, str):
            return self.unit
        return self.unit[0] if k < 3 else self.unit[1]


# ----------------------------------------------------------------------------- camera marks

@dataclass(frozen=True)
class MarkObs:
    """One mark: housing index, view's right/up unit vectors in P, camera id, nominal angle
    [rad] (0 or pi/2), measured image angle [rad] (ccw as displayed) and its u."""

    label: str
    housing: int
    right: np.ndarray
    up: np.ndarray
    camera: str
    nominal: float
    angle: float
    u: float
    declared_roll: float = 0.0
    file: str = ""
    view: str = ""
    # The lens terms of u as signed components [rad] on the lens's error directions, and
    # the lens solve they belong to (align.marks.MarkResult.lens_coupling / lens_group):
    # marks of one camera's solve share its lens error.
    coupling: Mapping[str, float] = field(default_factory=dict)
    lens_group: str = ""


def _lens_shared(marks: list[MarkObs]) -> tuple[tuple[str, tuple[int, ...], np.ndarray], ...]:
    """Each lens solve's rows and the weights its errors reach them with (Block.shared)."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i, m in enumerate(marks):
        if m.coupling and m.lens_group:
            groups.setdefault((m.camera, m.lens_group), []).append(i)
    out = []
    for (cam, _), rows in groups.items():
        keys = sorted({k for i in rows for k in marks[i].coupling})
        G = np.array([[marks[i].coupling.get(k, 0.0) for k in keys] for i in rows])
        out.append((f"lens of camera {cam}", tuple(rows), G))
    return tuple(out)


def mark_block(marks: list[MarkObs]) -> Block:
    values = np.array([wrap_half(m.angle - m.nominal - m.declared_roll) for m in marks])
    h = np.array([m.housing for m in marks])
    R = np.array([m.right for m in marks])
    U = np.array([m.up for m in marks])
    nom = np.array([m.nominal for m in marks])
    cams = [m.camera for m in marks]

    def predict(axes: np.ndarray, nuis: Nuisances) -> np.ndarray:
        s = axes[h]
        ang = np.arctan2((s * U).sum(1), (s * R).sum(1))
        roll = np.array([nuis[f"{ROLL}[{c}]"][0] if f"{ROLL}[{c}]" in nuis else 0.0
                         for c in cams])
        return wrap_half(ang - nom) + roll

    # A row's own part is its u² less its lens part; one lens's error reaches all its rows.
    shared = _lens_shared(marks)
    own = np.array([m.u**2 for m in marks])
    cov = np.zeros((len(marks), len(marks)))
    for _, rows, G in shared:
        own[list(rows)] -= (G**2).sum(1)
        cov[np.ix_(rows, rows)] += G @ G.T
    # (a floor keeps the covariance positive definite where a lens term is all of a u)
    cov += np.diag(np.maximum(own, 1e-6 * np.array([m.u**2 for m in marks])))
    return Block("camera", tuple(m.label for m in marks), values, cov, predict,
                 sees=tuple(sorted({f"{ROLL}[{c}]" for c in cams})),
                 row_sources=tuple(f"image {m.file or m.label}" for m in marks),
                 row_meta=tuple({"housing": HOUSINGS[m.housing], "view": m.view,
                                 "camera": m.camera, "label": m.label} for m in marks),
                 shared=shared)


# ----------------------------------------------------------------------------- goniometer

def gonio_block(faces: list[str], angles: np.ndarray, cov: np.ndarray, nominal: np.ndarray,
                direction: int, declared_offset: float = 0.0,
                type_b: Mapping[str, np.ndarray] | None = None, name: str = "") -> Block | None:
    """Face-azimuth deviations of housings x and y relative to the reference face (face 0).

    ``angles``/``nominal`` [rad]: table angle from face k to k+1 in passing order; ``cov``
    their covariance. Counter-clockwise (direction +1) faces pass in order of decreasing
    azimuth: psi_k - psi_0 = -sum_{m<k} A_m. A face of housing z carries no information on E
    (its turn about its own axis); it is not used.
    """
    n = len(faces)
    rows, labels, which = [], [], []
    for k, f in enumerate(faces):
        if k == 0 or f not in ("x", "y"):
            continue
        row = np.zeros(n)
        row[:k] = -direction
        rows.append(row)
        labels.append(f"face {f}")
        which.append(HOUSINGS.index(f))
    if not rows:
        return None
    L = np.array(rows)
    values = L @ (angles - nominal)
    values = wrap_half(values)
    C = L @ cov @ L.T
    which_a = np.array(which)

    def predict(axes: np.ndarray, nuis: Nuisances) -> np.ndarray:
        s = axes[which_a]
        az = np.arctan2(s[:, 1], s[:, 0])
        nom = np.where(which_a == 0, 0.0, np.pi / 2)
        off = declared_offset + (nuis[REF][0] if REF in nuis else 0.0)
        return wrap_half(az - nom) - off

    parts = tuple((f"Type B: {k}", L @ np.outer(v, v) @ L.T) for k, v in (type_b or {}).items())
    return Block("goniometer", tuple(labels), values, C, predict, sees=(REF,),
                 budget_source=name, type_b=parts)


# ----------------------------------------------------------------------------- ellipsoid

def _row_cosines(beta: np.ndarray) -> np.ndarray:
    R = r_matrix(beta)
    R = R / np.linalg.norm(R, axis=1, keepdims=True)
    return np.array([R[0] @ R[1], R[0] @ R[2], R[1] @ R[2]])


def _calibration_quantities(theta: np.ndarray, with_bias: bool) -> np.ndarray:
    """(beta, bias) -> cosines between the axes and, with_bias, the per-axis bias R b [g]."""
    c = _row_cosines(theta[:3])
    return np.concatenate([c, r_matrix(theta[:3]) @ theta[3:6]]) if with_bias else c


def ellipsoid_block(beta: np.ndarray, cov: np.ndarray, bias: np.ndarray | None = None
                    ) -> Block:
    """What the ellipsoid calibration says about the axes: cosines of the angles x-y, x-z, y-z
    between them (its frame floats, its angles do not) [-, i.e. rad from 90 deg]; with
    ``bias`` [g] also the prior on the per-axis bias error of the platform readings (0, with
    the calibration's uncertainty), jointly: beta and bias come from one fit and are
    correlated. ``cov``: covariance of beta (3x3) or of (beta, bias) (6x6)."""
    with_bias = bias is not None
    theta = np.concatenate([beta, bias]) if with_bias else np.asarray(beta, float)
    q0 = _calibration_quantities(theta, with_bias)
    J = np.zeros((len(q0), len(theta)))
    for j in range(len(theta)):
        h = 1e-7
        d = np.zeros(len(theta))
        d[j] = h
        J[:, j] = (_calibration_quantities(theta + d, with_bias)
                   - _calibration_quantities(theta - d, with_bias)) / (2 * h)
    pairs = ((0, 1), (0, 2), (1, 2))
    values = np.concatenate([q0[:3], np.zeros(3)]) if with_bias else q0

    def predict(axes: np.ndarray, nuis: Nuisances) -> np.ndarray:
        cos = np.array([axes[i] @ axes[j] for i, j in pairs])
        return np.concatenate([cos, nuis["bias"]]) if with_bias else cos

    # cos of the angle between two axes = sin of its departure from 90 deg: shown as an angle.
    labels = ("non-orthogonality x-y", "non-orthogonality x-z", "non-orthogonality y-z")
    if with_bias:
        labels += tuple(f"bias error {h} (prior)" for h in HOUSINGS)
    return Block("ellipsoid", labels, values, J @ cov @ J.T, predict,
                 unit=("rad", "g") if with_bias else "rad", budget_source="calibration")


# ----------------------------------------------------------------------------- platform static

@dataclass(frozen=True)
class PlatformPose:
    """A static pose of the platform: ``up`` the nominal 'up' specific-force direction in P
    (a signed axis), ``table`` the table angle [rad] (for levelled poses), ``w`` the calibrated
    per-axis readings [g] (w_i = |r_i| s_i . g), ``u_w`` their standard errors [g],
    ``samples`` the readings averaged into ``w`` whose scatter gave ``u_w`` (0: not known)."""

    label: str
    up: np.ndarray
    table: float
    w: np.ndarray
    u_w: np.ndarray
    samples: int = 0


def gravity_in_platform(up: np.ndarray, table: float, tilt: np.ndarray,
                        level: np.ndarray | None = None) -> np.ndarray:
    """'Up' direction in P: levelled poses see the table axis's tilt (tx, ty) [rad], fixed in
    the room, turned by the table angle, and the platform's own levelling offset ``level``
    (lx, ly) [rad] — the up direction's X, Y components in P, fixed on the platform (it turns
    with the table); commanded side poses are taken as exact."""
    if abs(up[2]) < 0.5:
        return up
    c, s = np.cos(table), np.sin(table)
    g = np.array([c * tilt[0] + s * tilt[1], -s * tilt[0] + c * tilt[1], 1.0]) * np.sign(up[2])
    g = g / np.linalg.norm(g)
    if level is not None:
        g = g + np.array([level[0], level[1], 0.0])
        g = g / np.linalg.norm(g)
    return g


def static_block(poses: list[PlatformPose], row_norms: np.ndarray,
                 declared_tilt: np.ndarray) -> Block:
    """Off-axis readings (the on-axis one measures the scale factor, not E). Every reading
    carries the same calibrated bias error per axis: the nuisance 'bias' (its prior is in the
    ellipsoid block, correlated with beta)."""
    vals, us, labels, which, pidx, meta = [], [], [], [], [], []
    for p, pose in enumerate(poses):
        up_axis = int(np.argmax(np.abs(pose.up)))
        up = ("+" if pose.up[up_axis] > 0 else "-") + "XYZ"[up_axis]
        for i in range(3):
            if i == up_axis:
                continue
            meta.append({"pose": pose.label, "up": up, "housing": HOUSINGS[i]})
            vals.append(pose.w[i])
            us.append(pose.u_w[i])
            labels.append(f"{pose.label} {HOUSINGS[i]}")
            which.append(i)
            pidx.append(p)
    which_a, pidx_a = np.array(which), np.array(pidx)

    def predict(axes: np.ndarray, nuis: Nuisances) -> np.ndarray:
        tilt = declared_tilt + (nuis[TILT] if TILT in nuis else 0.0)
        level = nuis.get(LEVEL)
        g = np.array([gravity_in_platform(poses[p].up, poses[p].table, tilt, level)
                      for p in pidx_a])
        return row_norms[which_a] * (axes[which_a] * g).sum(1) + nuis["bias"][which_a]

    levelled = any(abs(p.up[2]) > 0.5 for p in poses)
    # Each u_w is its pose's sample scatter: estimated on samples - 1 dof (20 samples: a u
    # 0.6x the true one in 1 % of the rows, and a z heavier-tailed than normal).
    n_min = min(p.samples for p in poses)
    return Block("platform static", tuple(labels), np.array(vals), np.diag(np.square(us)),
                 predict, unit="g", sees=(TILT, LEVEL) if levelled else (TILT,),
                 budget_source="static poses", row_meta=tuple(meta),
                 noise_dof=float(n_min - 1) if n_min > 1 else None)
