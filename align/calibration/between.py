"""A bias step between two poses: the bias held one value for the poses before and another
for those after (a jump during a turn, a knock, a bias that follows a gravity reversal).

The samples within the poses do not see it (:mod:`align.calibration.steps` locates a step
inside a pose); the pose means do. With a step of s on axis i after pose j, the poses after
j read |a| through b_i + s: the ellipsoid's residuals split into the poses before and after,
and the bias from the poses before disagrees with the bias from those after. The test: the
declared model with one bias step, at each boundary between poses in time order and on each
axis (3 (N − 1) fits, linearised at the loop's fits: |a| is linear in the bias to parts in
10⁶ over mg), against the model without it; a likelihood ratio beyond :data:`STEP_ALPHA`
Bonferroni-corrected over the boundaries and axes. The noise is the stage's and the largest
bias walk the samples within the poses do not exclude (a step must beat the wander every
triad has, not white noise). The loop's effects (a bias drift, hysteresis, a misalignment)
may take a step's signal; the step then counts when it stays beyond the effects, or when
its fit is as good as theirs (its BIC, the search over the boundaries counted, within
:data:`~align.calibration.widen.AMBIGUOUS_BIC` of theirs or better): the bias is then not
one value the poses determine, and the result is not ok (:meth:`BetweenStep.problem`).
Hand-written: a scan of one regressor over a few dozen positions in numpy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from align.calibration.model import CalibrationStage, walk_physical
from align.calibration.steps import AXES
from align.calibration.triad import pose_gradient
from align.calibration.walk import walk_covariance
from align.calibration.widen import AMBIGUOUS_BIC
from align.loop import LoopReport

STEP_ALPHA = 1e-3
"""Significance of a bias step between poses, over all boundaries and axes (Bonferroni)."""
MIN_SIDE = 2
"""Fewest poses on either side of a boundary that is tested (one pose alone after a step is
one outlier, not a bias the poses determine)."""


@dataclass(frozen=True)
class BetweenStep:
    """The bias step between two poses that best explains the pose means.

    Attributes
    ----------
    axis : int
        The axis whose bias stepped (0, 1, 2) — dimensionless.
    before : str
        The label of the last pose before it; unit —.
    after : str
        The label of the first pose after it; unit —. The poses between these two do not
        tell on which side of the step they were (the axis about level in them).
    t_s : float
        Its time, midway between the mean times of the poses either side of the best
        boundary [s].
    size_g : float
        The bias after less before [g].
    size_u_g : float
        Its standard uncertainty [g].
    p : float
        The likelihood ratio's p-value, Bonferroni over the boundaries and axes, against
        the declared model — dimensionless.
    p_effects : float
        The same beyond the loop's effects (1 when none was added) — dimensionless.
    d_bic : float
        The step model's BIC less the loop's final fit's (the search counted) —
        dimensionless.
    effects : str
        The loop's effects, joined by " + " ("" for none); unit —.
    """

    axis: int
    before: str
    after: str
    t_s: float
    size_g: float
    size_u_g: float
    p: float
    p_effects: float
    d_bic: float
    effects: str = ""

    @property
    def found(self) -> bool:
        """The step is beyond the noise and the walk, and the loop's effects do not explain
        the data better (by :data:`~align.calibration.widen.AMBIGUOUS_BIC`)."""
        return bool(self.p < STEP_ALPHA and (self.p_effects < STEP_ALPHA
                                             or self.d_bic < AMBIGUOUS_BIC))

    def problem(self) -> str:
        """The line that makes the result not ok."""
        other = (f"; the loop's {self.effects} fit no better, the poses cannot tell them "
                 "from it" if self.effects and self.p_effects >= STEP_ALPHA else "")
        return (f"the {AXES[self.axis]} bias stepped by {self.size_g * 1e6:+.4g} ± "
                f"{self.size_u_g * 1e6:.2g} µg between pose {self.before} and pose "
                f"{self.after} (t ≈ {self.t_s:.1f} s; p = {self.p:.2g} over the "
                f"boundaries{other}): the bias is not one value over the run: recalibrate")

    def to_dict(self) -> dict:
        return {"axis": AXES[self.axis], "before": self.before, "after": self.after,
                "t_s": self.t_s, "size_g": self.size_g, "size_u_g": self.size_u_g,
                "p": self.p, "p_effects": self.p_effects, "d_bic": self.d_bic,
                "effects": self.effects}

    @classmethod
    def from_dict(cls, d: dict) -> BetweenStep:
        return cls(AXES.index(d["axis"]), str(d["before"]), str(d["after"]),
                   float(d["t_s"]), float(d["size_g"]), float(d["size_u_g"]), float(d["p"]),
                   float(d["p_effects"]), float(d["d_bic"]), str(d.get("effects", "")))


def _noise_whitener(stage: CalibrationStage) -> np.ndarray:
    """L⁻¹ (N, N) [1/g] of the poses' noise: the stage's, and where it is white the largest
    bias walk the samples allow (``Poses.walk_bound``)."""
    p = stage.poses
    C = np.diag(stage.sigma**2)
    if stage.whiten is not None:
        return stage.whiten
    bound = p.walk_bound
    if bound is not None and walk_physical(bound / stage.start.k**2, p.t):
        C = C + walk_covariance(np.asarray(bound, float), pose_gradient(stage.start, p), p.t)
    return np.linalg.inv(np.linalg.cholesky(C))


def _scan(e: np.ndarray, G: np.ndarray, cols: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Per candidate column c (N, M): the chi2 drop of adding it to the fit of ``e`` (N,)
    on ``G`` (N, P), the coefficient that minimises |e + G δ + c s|² and its u, each
    divided (the u multiplied) by the root of the extended fit's chi2/dof where that
    exceeds 1 (as the loop's likelihood-ratio test: a scatter beyond the stated noise, the
    hand placement of real poses, does not make a step); and the extended fit's chi2."""
    q, _ = np.linalg.qr(G)
    r = e - q @ (q.T @ e)
    c = cols - q @ (q.T @ cols)
    cc = np.maximum(np.einsum("ij,ij->j", c, c), 1e-300)
    cr = c.T @ r
    drop = cr**2 / cc
    s2 = np.maximum((r @ r - drop) / max(len(e) - G.shape[1] - 1, 1), 1.0)
    return drop / s2, -cr / cc, np.sqrt(s2 / cc), float(r @ r) - drop


def between_step(stage: CalibrationStage, rep: LoopReport) -> BetweenStep | None:
    """The best bias step between two poses (:class:`BetweenStep`), or None when the noise
    is unknown, the order unknown, or the poses too few to test one."""
    p = stage.poses
    n = len(p.u)
    if stage.sigma is None or not p.ordered or () not in stage.jacobians:
        return None
    order = np.argsort(p.t, kind="stable")
    bounds = list(range(MIN_SIDE, n - MIN_SIDE + 1))
    if not bounds or n - 10 < 2:
        return None
    W = stage.whiten if stage.whiten is not None else np.diag(1.0 / stage.sigma)
    Li = _noise_whitener(stage)
    names = tuple(t.name for t in rep.terms)

    def fit(effects: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # The stage's whitened residual and Jacobian, back to g and into the test's noise.
        e = np.linalg.solve(W, stage.projection[effects][1])
        G = np.linalg.solve(W, stage.jacobians[effects])
        return Li @ e, Li @ G, G[:, 6:9]

    e0, G0, gb = fit(())
    rank = np.empty(n, int)
    rank[order] = np.arange(n)
    cols = np.column_stack([Li @ (gb[:, a] * (rank >= j)) for j in bounds for a in range(3)])
    tests = len(bounds) * 3
    drop, size, u, chi2_0 = _scan(e0, G0, cols)  # (chi2_0: with each step)
    best = int(np.argmax(drop))
    p0 = min(1.0, tests * float(special.chdtrc(1, drop[best])))
    pf, d_bic = 1.0, -np.inf
    if names and names in stage.jacobians:
        ef, Gf, _ = fit(names)
        drop_f = _scan(ef, Gf, cols)[0]
        qf = np.linalg.qr(Gf)[0]
        chi2_f = float(np.sum((ef - qf @ (qf.T @ ef)) ** 2))  # the final fit's, no step
        pf = min(1.0, tests * float(special.chdtrc(1, drop_f[best])))
        searched = sum(t.searched for t in rep.terms)
        # The step: one parameter and the choice of one of `tests` positions (2 ln tests).
        d_bic = ((chi2_0[best] + (G0.shape[1] + 1) * np.log(n) + 2 * np.log(tests))
                 - (chi2_f + (Gf.shape[1] + searched) * np.log(n)))
    j, a = divmod(best, 3)
    # The boundaries the data cannot tell from the best (a pose that does not see the
    # axis, its component of gravity ~0, reads the same either side of the step): those
    # next to it within the 95 % likelihood interval of one parameter.
    near = drop[a::3] >= drop[best] - special.chdtri(1, 0.05)
    lo, hi = j, j
    while lo > 0 and near[lo - 1]:
        lo -= 1
    while hi < len(bounds) - 1 and near[hi + 1]:
        hi += 1
    k = order[bounds[lo] - 1], order[bounds[hi]]
    t = p.t[order[bounds[j] - 1]], p.t[order[bounds[j]]]
    return BetweenStep(a, p.labels[k[0]], p.labels[k[1]], float((t[0] + t[1]) / 2),
                       float(size[best]), float(u[best]), p0, pf, float(d_bic),
                       " + ".join(names))


def between_problem(stage: CalibrationStage, rep: LoopReport) -> tuple[str, ...]:
    """Why the result is not ok (none or one line): a bias step between poses
    (:func:`between_step`, :attr:`BetweenStep.found`) not next to a pose whose samples
    stepped (``Poses.steps``)."""
    s = between_step(stage, rep)
    if s is None or not s.found:
        return ()
    # A step within a pose reads, in the means, as one between it and its neighbour: the
    # samples located it (align.calibration.steps.step_problem names it there).
    inside = {stage.poses.labels[x.pose] for x in stage.poses.steps}
    return () if {s.before, s.after} & inside else (s.problem(),)
