"""A pose sequence that makes the triad's effects identifiable (``align calibrate --plan N``).

The seed paper's 14 poses (6 faces, then 8 vertices) cannot tell apart a K2, a cross-axis
product K_ij a_i a_j and a scale factor drifting in time: on the cube's vertices every
|a_i| = 1/sqrt(3), so K_x,xy a_x^2 a_y and K_z,yz a_z^2 a_y are the same column, and the faces
all come before the vertices, so a drift looks like an attitude pattern. The plan:

* attitudes: the faces, vertices and edges of the cube (on an edge one component is 0, so
  the products separate), as many as fit in N/2;
* each attitude held twice, once in the first half of the run and once in the second (the
  same attitude early and late: a drift changes its reading, an attitude effect does not);
* the second visits in the order that reverses the most (attitude, axis) turn directions of
  the first (each attitude reached from both directions: the bias hysteresis is the
  difference), searched over random orders (seeded).

:func:`identifiability` checks a plan by simulation: noise-free poses of a nominal triad in
the planned order, the Jacobian of the model with each effect alone, the effect's standard
uncertainty per 1 µg of pose noise and the condition number.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from align.calibration.ellipsoid import r_matrix
from align.calibration.model import (
    DRIFT,
    EFFECTS,
    HYSTERESIS,
    NONLIN,
    SCALE_DRIFT,
    TURN_G,
    CalibrationStage,
    _spans,
)
from align.calibration.triad import Poses
from axisbase.errors import InputError, NotApplicable

MIN_POSES = 28
"""Fewest poses of a plan: 14 attitudes each held twice. An attitude effect is a function of
the direction only, so repeats add no equation for it: the ellipsoid's 9 parameters, K2's 3
and one more effect beside them need 14 distinct directions (checked by
:func:`identifiability`: 10 attitudes leave K2 a condition number of 1e16)."""
DWELL_S, MOVE_S = 10.0, 5.0
"""Hold and turn times [s] of the simulated plan (the reading's time axis)."""


def attitudes() -> tuple[list[str], np.ndarray]:
    """Labels and up directions (unit vectors, unit frame) of the cube's faces, vertices and
    edges, in that order."""
    labels, dirs = [], []
    for i, ax in enumerate("xyz"):
        for s in (1, -1):
            v = np.zeros(3)
            v[i] = s
            labels.append(f"{'+' if s > 0 else '-'}{ax}")
            dirs.append(v)
    for sx in (1, -1):
        for sy in (1, -1):
            for sz in (1, -1):
                labels.append("".join(f"{'+' if s > 0 else '-'}{a}"
                                      for s, a in zip((sx, sy, sz), "xyz", strict=True)))
                dirs.append(np.array([sx, sy, sz]) / np.sqrt(3))
    for i, j in ((0, 1), (0, 2), (1, 2)):
        for si in (1, -1):
            for sj in (1, -1):
                v = np.zeros(3)
                v[i], v[j] = si, sj
                labels.append(f"{'+' if si > 0 else '-'}{'xyz'[i]}"
                              f"{'+' if sj > 0 else '-'}{'xyz'[j]}")
                dirs.append(v / np.sqrt(2))
    return labels, np.array(dirs)


@dataclass(frozen=True)
class Plan:
    """An N-pose order: ``labels`` and ``up`` (N, 3) unit vectors of each pose in order,
    ``reversed_fraction``: the fraction of (attitude, axis) pairs that are reached from both
    directions."""

    labels: tuple[str, ...]
    up: np.ndarray
    reversed_fraction: float

    def lines(self) -> list[str]:
        """The plan for the terminal: each pose, its attitude, and the turn into it."""
        out = [f"{'#':>3s}  {'attitude (up)':14s} {'up vector':>24s}   turn into it "
               "(angle, axis; input change per axis)"]
        for p, (lab, v) in enumerate(zip(self.labels, self.up, strict=True)):
            vec = " ".join(f"{c:+.3f}" for c in v)
            if p == 0:
                out.append(f"{p + 1:3d}  {lab:14s} {vec:>24s}   start")
                continue
            prev = self.up[p - 1]
            ang = float(np.degrees(np.arccos(np.clip(prev @ v, -1, 1))))
            ax = np.cross(prev, v)
            n = np.linalg.norm(ax)
            axis = (" ".join(f"{c:+.2f}" for c in ax / n) if n > 1e-9 else "any horizontal")
            d = v - prev
            moves = " ".join(f"{a}{'↑' if c > TURN_G else '↓' if c < -TURN_G else '='}"
                             for a, c in zip("xyz", d, strict=True))
            out.append(f"{p + 1:3d}  {lab:14s} {vec:>24s}   {ang:5.1f}° about ({axis}); "
                       f"{moves}")
        out.append(f"each attitude held twice (first and second half of the run); "
                   f"{self.reversed_fraction:.0%} of the (attitude, axis) turns reached from "
                   "both directions")
        return out


def _signs(up: np.ndarray) -> np.ndarray:
    d = np.diff(up, axis=0)
    s = np.where(np.abs(d) > TURN_G, np.sign(d), 0.0)
    return np.vstack([np.zeros((1, 3)), s])


def plan(n: int, seed: int = 0, tries: int = 2000) -> Plan:
    """An ``n``-pose plan (see the module); ``n`` >= :data:`MIN_POSES`, odd n holds one
    attitude a third time at the end."""
    if n < MIN_POSES:
        raise InputError(f"--plan {n}: at least {MIN_POSES} poses ({MIN_POSES // 2} "
                         "attitudes, each held twice: early and late, reached from both "
                         "directions)")
    labels, dirs = attitudes()
    # Faces first, then vertices (a tetrahedron's first) and edges taken in turn: the edges'
    # zero component is what separates a cross-axis product from K2.
    verts = [6, 9, 10, 13, 7, 8, 11, 12]
    edges = [14, 19, 24, 17, 15, 20, 25, 16, 18, 21, 22, 23]
    pick = list(range(6)) + [x for pair in zip(verts, edges[:8], strict=True) for x in pair]
    pick += edges[8:]
    labels = [labels[i] for i in pick]
    dirs = dirs[pick]
    m = min(n // 2, len(dirs))
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(tries):
        first, second = rng.permutation(m), rng.permutation(m)
        order = np.concatenate([first, second])
        reps = n - 2 * m
        order = np.concatenate([order, rng.permutation(m)[:reps] if reps else []]).astype(int)
        s = _signs(dirs[order])
        # For each attitude and axis: seen from + and from - ? (counts of each by attitude
        # (m, 3): the poses' one-hot attitudes times the turns' signs)
        hot = (order[None, :] == np.arange(m)[:, None]).astype(float)
        up_, down = hot @ (s > 0) > 0, hot @ (s < 0) > 0
        total = int(np.sum(up_ | down))
        both = int(np.sum(up_ & down))
        score = both / max(total, 1)
        if best is None or score > best[0]:
            best = (score, order)
    score, order = best
    return Plan(tuple(labels[i] for i in order), dirs[order], float(score))


def paper14() -> np.ndarray:
    """The seed paper's 14 poses in its order (faces, then vertices)."""
    return attitudes()[1][:14]


EFFECTS_CHECKED = (NONLIN, "cross_x_xy", "cross_z_yz", SCALE_DRIFT, DRIFT, HYSTERESIS)


def identifiability(up: np.ndarray, sigma_g: float = 1e-6) -> dict[str, dict[str, float]]:
    """Per effect: its standard uncertainty per pose noise ``sigma_g`` [g] when added alone to
    the model on these poses in this order, as the reach at 1 g over the run [g] (comparable
    across effects), the condition number of the column-normalised Jacobian, and the worst
    condition number with one other effect of the list beside it (``pair_condition``, with
    ``worst_pair``; inf: more parameters than poses, or the two are one column).

    Noise-free poses of a nominal triad (unit scale factors, small non-orthogonality and
    biases): the linearised covariance does not depend on the noise draw."""
    n = len(up)
    t = np.arange(n) * (DWELL_S + MOVE_S) + DWELL_S / 2
    beta = np.array([6e-4, 4e-4, -6e-5])
    bias = np.array([5e-4, -3e-4, 4e-4])
    u = (up + bias) @ r_matrix(beta).T
    # sigma of each pose mean per component, so that |a| has sigma_g.
    poses = Poses(u, t, None, np.full((n, 3), sigma_g), np.ones(n, int),
                  tuple(str(i) for i in range(n)))
    stage = CalibrationStage(poses, (1, 1, 1))
    out = {}
    for e in EFFECTS_CHECKED:
        try:
            m, _, _ = stage.refine([e])
        except NotApplicable:
            continue
        us = np.array([m.u_of(name) for _, _, name in EFFECTS[e].slots])
        reach = float(np.max(us)) * EFFECTS[e].size(*_spans(poses))
        out[e] = {"u_reach_g": reach, "condition": stage.condition[(e,)]}
    for i, e1 in enumerate(EFFECTS_CHECKED):
        for e2 in EFFECTS_CHECKED[i + 1:]:
            try:
                stage.refine([e1, e2])
                cond = stage.condition[(e1, e2)]
            except NotApplicable:  # more parameters than poses
                cond = float("inf")
            for e in (e1, e2):
                if e in out and cond > out[e].get("pair_condition", 0.0):
                    out[e]["pair_condition"] = cond
                    out[e]["worst_pair"] = e2 if e == e1 else e1
    return out


def plan_report(n: int, seed: int = 0) -> list[str]:
    """What ``align calibrate --plan N`` prints: the plan, then each effect's identifiability
    on it against the seed paper's 14 poses (u per 1 µg of pose noise as its reach at 1 g
    [µg], the condition number with the worst other effect beside it)."""
    p = plan(n, seed)
    mine, paper = identifiability(p.up), identifiability(paper14())
    out = [f"pose plan of {n} poses (hold each still, in this order; note the time of "
           "each, or record t):", *p.lines(), "",
           "identifiability by simulation (u of the effect per 1 µg pose noise, as µg at 1 g "
           "over the run; condition number with the worst other effect beside it):",
           f"  {'effect':18s} {'this plan':>22s} {'paper 14 poses':>26s}"]
    for e in EFFECTS_CHECKED:
        a, b = mine.get(e, {}), paper.get(e, {})

        def cell(d):
            if not d:
                return "not applicable"
            return (f"{d['u_reach_g'] * 1e6:6.2f} µg, cond {d.get('pair_condition', 0):8.2g}")

        out.append(f"  {e:18s} {cell(a):>22s} {cell(b):>26s}")
    return out
