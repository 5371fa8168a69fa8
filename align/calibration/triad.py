"""The triad's data types: the poses of a static test and the calibrated triad model.

Inverse model (the forward one is u_i = k_i (1 + A_i sign x_i) (x_i + K2_i x_i^2 + K3_i x_i^3),
x = R (a + b(t, T))):

    x_i = v_i - K2_i v_i^2 - K3_i v_i^3,   v_i = u_i / (k_i (1 + A_i sign u_i))
                                        (first-order inverse of K2, K3; K2 x, K3 x^2 ~ 1e-4)
    a   = R^-1 x - b - bdot (t - t_ref) - bddot (t - t_ref)^2 - c_T (T - T_ref)

These types import nothing of the fit (:mod:`align.calibration.model`) nor of the orchestrator
(:mod:`align.calibration.pipeline`), so every module of the package can use them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from align.calibration.ellipsoid import r_matrix, row_norms
from align.calibration.settling import Settling, settle_samples
from align.calibration.slopes import pose_slopes
from align.calibration.steps import PoseStep, pose_steps
from align.calibration.walk import walk_levels
from align.errors import InputError
from axisbase.covariance import cov_of

AXES = ("x", "y", "z")


def per_axis(*groups: str) -> tuple[str, ...]:
    """The parameter names of per-axis groups, in the model's naming: ``per_axis("beta",
    "bias")`` is ``("beta_x", "beta_y", "beta_z", "bias_x", "bias_y", "bias_z")``."""
    return tuple(f"{g}_{a}" for g in groups for a in AXES)


CORE = per_axis("k", "beta", "bias")
"""The nine parameters every model fits, in the covariance's first nine places."""


@dataclass(frozen=True)
class Poses:
    """Per-pose means of a static test: u (N, 3) [V or counts], t [s], temp [K], sigma of the
    mean output per component (N, 3) or None, sample counts, and labels."""

    u: np.ndarray
    t: np.ndarray
    temp: np.ndarray | None
    sigma_u: np.ndarray | None
    count: np.ndarray
    labels: tuple[str, ...]
    ordered: bool = True
    """Whether the poses were held in the order of ``t`` (times given, or a recording): only
    then is the turn into each pose known (bias hysteresis)."""
    walk_rate: np.ndarray | None = None
    """The bias random walk's rate per axis [output unit² / s] the samples within the poses
    show (:func:`align.calibration.walk.walk_levels`), or None (white noise)."""
    walk_bound: np.ndarray | None = None
    """The largest such rate the samples do not exclude [output unit² / s], or None (too
    short, or no times)."""
    slope: np.ndarray | None = None
    """Each pose's trend per axis while static (N, 3) [output unit/s], NaN where too short
    (:func:`align.calibration.slopes.pose_slopes`), or None (means only, no times)."""
    slope_u: np.ndarray | None = None
    """Its standard uncertainty (N, 3) [output unit/s] (inf where too short), or None."""
    settling: Settling | None = None
    """The test for a transient after each turn (:mod:`align.calibration.settling`; found:
    the means are of the corrected samples, ``sigma_u`` carries the correction), or None
    (not testable: means only, no times, short poses)."""
    steps: tuple[PoseStep, ...] = ()
    """The poses whose samples stepped (:mod:`align.calibration.steps`), left out of
    ``walk_rate``."""


def poses_from_samples(pose: np.ndarray, u: np.ndarray, t: np.ndarray,
                       labels: Sequence[str] | None = None) -> Poses:
    """Per-pose means (and their standard errors) from samples tagged with pose ids 0..N-1."""
    ids = np.unique(pose)
    sel = [pose == i for i in ids]
    samples, times = [u[s] for s in sel], [t[s] for s in sel]
    sigma = np.array([x.std(0, ddof=1) / np.sqrt(len(x)) for x in samples])
    samples, du, settled = settle_samples(samples, times)
    if du is not None:
        sigma = np.sqrt(sigma**2 + du**2)
    names = tuple(labels) if labels is not None else tuple(str(i) for i in ids)
    steps = pose_steps(samples, times, names)
    rate, bound = walk_levels(samples, times, [s.pose for s in steps])
    trend = pose_slopes(samples, times, rate)
    return Poses(np.array([x.mean(0) for x in samples]), np.array([t[s].mean() for s in sel]),
                 None, sigma, np.array([s.sum() for s in sel]),
                 names, True, rate, bound,
                 *(trend[:2] if trend is not None else (None, None)), settled, steps)


@dataclass(frozen=True)
class TriadModel:
    """A calibration of the triad: u = K R (a + b) and its optional effects; ``cov`` is over
    ``names``.

    Attributes
    ----------
    k : numpy.ndarray
        Scale factors K (3,) [output unit/g].
    beta : numpy.ndarray
        Misalignment angles of the seed paper's R (3,) [rad].
    bias : numpy.ndarray
        Bias (3,) [g].
    k2 : numpy.ndarray
        Second-order scale terms (3,) [1/g].
    drift : numpy.ndarray
        Bias drift (3,) [g/s] about ``t_ref``.
    temp_coeff : numpy.ndarray
        Bias change per kelvin (3,) [g/K] about ``temp_ref``.
    drift2 : numpy.ndarray
        Quadratic bias drift (3,) [g/s²].
    t_ref : float
        Reference time of the drifts [s].
    temp_ref : float
        Reference temperature [K] (or the readings' temperature unit).
    cov : numpy.ndarray or None
        Covariance over ``names`` [products of the parameters' units]; :meth:`cov_of` reads it
        by name.
    names : tuple of str
        The fitted parameters, in ``cov``'s order (``k_x``, ``beta_y``, ``bias_z``, ...); unit —.
    cross : numpy.ndarray
        Cross-axis second-order terms [1/g]: row i (output axis), columns the products
        x_x x_y, x_x x_z, x_y x_z of the inputs (IEEE Std 1293's K_ip, K_io).
    scale_drift : numpy.ndarray
        Relative scale-factor change per second [1/s] about ``t_ref``.
    scale_temp : numpy.ndarray
        Relative scale-factor change per kelvin [1/K] about ``temp_ref``.
    scale_warmup : numpy.ndarray
        Relative scale-factor warm-up amplitude: s = 1 + w (exp(-(t - t_ref)/tau) - 1) —
        dimensionless.
    warmup_tau_s : float
        Time constant of the scale-factor warm-up [s] (0: none).
    hysteresis : numpy.ndarray
        Bias hysteresis [g]: each pose's bias is offset by this x the sign of the change of its
        axis's input in the turn into the pose. Readings without their turns cannot be
        corrected for it: ``bias`` is the middle of the two branches.
    k3 : numpy.ndarray
        Third-order scale terms (3,) [1/g²] (IEEE Std 1293's K3).
    asymmetry : numpy.ndarray
        Scale-factor asymmetry (3,) (k+ - k-) / (k+ + k-) [1]: ``k`` is (k+ + k-) / 2.
    """

    k: np.ndarray
    beta: np.ndarray
    bias: np.ndarray
    k2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    temp_coeff: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drift2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t_ref: float = 0.0
    temp_ref: float = 0.0
    cov: np.ndarray | None = None
    names: tuple[str, ...] = ()
    cross: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    """Cross-axis second-order terms [1/g]: row i (output axis), columns the products
    x_x x_y, x_x x_z, x_y x_z of the inputs (IEEE Std 1293's K_ip, K_io)."""
    scale_drift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Relative scale-factor change per second [1/s] about ``t_ref``."""
    scale_temp: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Relative scale-factor change per kelvin [1/K] about ``temp_ref``."""
    scale_warmup: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Relative scale-factor warm-up amplitude: s = 1 + w (exp(-(t - t_ref)/tau) - 1) [1]."""
    warmup_tau_s: float = 0.0
    """Time constant of the scale-factor warm-up [s] (0: none)."""
    hysteresis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Bias hysteresis [g]: each pose's bias is offset by this x the sign of the change of its
    axis's input in the turn into the pose. Readings without their turns cannot be corrected
    for it: ``bias`` is the middle of the two branches."""
    k3: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Third-order scale terms [1/g²] (IEEE Std 1293's K3)."""
    asymmetry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Scale-factor asymmetry (k+ - k-) / (k+ + k-) [1] (IEEE Std 1293)."""

    def scale_of(self, t: np.ndarray | float = 0.0,
                 temp: np.ndarray | float | None = None) -> np.ndarray:
        """Relative scale factor s (N, 3) at times t [s] and temperatures [K] (1 at the
        references)."""
        dt = np.atleast_1d(np.asarray(t, float)) - self.t_ref
        s = 1.0 + np.multiply.outer(dt, self.scale_drift)
        if self.warmup_tau_s > 0:
            s = s + np.multiply.outer(np.expm1(-dt / self.warmup_tau_s), self.scale_warmup)
        if temp is not None:
            s = s + np.multiply.outer(np.atleast_1d(np.asarray(temp, float)) - self.temp_ref,
                                      self.scale_temp)
        return s

    def specific_force(self, u: np.ndarray, t: np.ndarray | float = 0.0,
                       temp: np.ndarray | float | None = None) -> np.ndarray:
        """Specific force a (N, 3) [g] in the unit's convenient frame from outputs u."""
        v = np.asarray(u, float) / self.k
        if np.any(self.scale_drift) or np.any(self.scale_warmup) or np.any(self.scale_temp):
            s = self.scale_of(t, temp)
            v = v / (s if v.ndim == 2 else s[0])
        if np.any(self.asymmetry):
            v = v / (1.0 + np.sign(v) * self.asymmetry)
        x = v - self.k2 * v * v - self.k3 * v**3
        if np.any(self.cross):
            vv = np.atleast_2d(v)
            prod = np.stack([vv[:, 0] * vv[:, 1], vv[:, 0] * vv[:, 2], vv[:, 1] * vv[:, 2]], 1)
            x = x - (prod @ self.cross.T).reshape(x.shape)
        a = np.linalg.solve(r_matrix(self.beta), x.T).T
        dt = np.asarray(t, float) - self.t_ref
        a = (a - self.bias - np.multiply.outer(dt, self.drift)
             - np.multiply.outer(dt * dt, self.drift2))
        if temp is not None:
            a = a - np.multiply.outer(np.asarray(temp, float) - self.temp_ref, self.temp_coeff)
        return a

    def sensitivity(self) -> np.ndarray:
        """Scale factor along each sensitive axis: output per g along s_i [output/g].

        The model's ``k`` is the paper's K of u = K R (a + b), whose R (eq. 5) has rows of
        length 1 + O(beta^2): k_i |r_i| is what the axis reads per g along itself (what a
        metrology user calls the scale factor; differs from k_i by ~beta^2/2, ~1e-5 at 15').
        """
        return self.k * row_norms(self.beta)[0]

    def sensitivity_u(self) -> np.ndarray:
        """Standard uncertainty of :meth:`sensitivity`, propagated from the covariance of
        (k, beta) (nan where not determined or without a covariance)."""
        names = per_axis("k", "beta")
        if self.cov is None or any(n not in self.names for n in names):
            return np.full(3, np.nan)
        n, dn = row_norms(self.beta)
        J = np.hstack([np.diag(n), self.k[:, None] * dn])
        var = np.einsum("ij,jk,ik->i", J, self.cov_of(*names), J)
        return np.where(var >= 0, np.sqrt(np.abs(var)), np.nan)

    def cov_of(self, *names: str) -> np.ndarray:
        """The covariance of the named parameters (of :attr:`names`, e.g. ``cov_of("k_x",
        "beta_y")``; :func:`per_axis` names a group) in the order given [products of their
        units]; ``KeyError`` for a parameter not fitted, ``ValueError`` without a
        covariance."""
        if self.cov is None:
            raise ValueError("this model carries no covariance")
        return cov_of(self.cov, self.names, names)

    def u_of(self, name: str) -> float:
        """Standard uncertainty of one parameter [its unit]; nan when not fitted, without a
        covariance, or not determined (a negative variance)."""
        if self.cov is None or name not in self.names:
            return float("nan")
        v = float(self.cov_of(name)[0, 0])
        return float(np.sqrt(v)) if v >= 0 else float("nan")  # nan: not determined

    def u_per_axis(self, group: str) -> np.ndarray:
        """Standard uncertainties of a per-axis group (``"beta"``, ``"bias"``, ``"k"``) in
        x, y, z order [its unit]."""
        return np.array([self.u_of(n) for n in per_axis(group)])

    def to_dict(self) -> dict:
        """The model as JSON-ready numbers (SI/radians/g), covariance included."""
        return {"k_v_per_g": self.k.tolist(), "beta_rad": self.beta.tolist(),
                "bias_g": self.bias.tolist(), "k2_per_g": self.k2.tolist(),
                "drift_g_per_s": self.drift.tolist(), "drift2_g_per_s2": self.drift2.tolist(),
                "temp_coeff_g_per_k": self.temp_coeff.tolist(), "t_ref_s": self.t_ref,
                "temp_ref_k": self.temp_ref, "cross_per_g": self.cross.tolist(),
                "scale_drift_per_s": self.scale_drift.tolist(),
                "scale_temp_per_k": self.scale_temp.tolist(),
                "scale_warmup": self.scale_warmup.tolist(), "warmup_tau_s": self.warmup_tau_s,
                "hysteresis_g": self.hysteresis.tolist(), "k3_per_g2": self.k3.tolist(),
                "scale_asymmetry": self.asymmetry.tolist(), "parameter_names": list(self.names),
                "covariance": None if self.cov is None else self.cov.tolist()}

    @classmethod
    def from_dict(cls, d: dict, where: str = "calibration") -> TriadModel:
        """Read :meth:`to_dict`'s output back (clear error for anything else, or for a
        model that cannot be applied: see :func:`_checked`)."""
        try:
            cov = d.get("covariance")
            m = cls(
                np.array(d["k_v_per_g"], float), np.array(d["beta_rad"], float),
                np.array(d["bias_g"], float), np.array(d.get("k2_per_g", [0, 0, 0]), float),
                np.array(d.get("drift_g_per_s", [0, 0, 0]), float),
                np.array(d.get("temp_coeff_g_per_k", [0, 0, 0]), float),
                np.array(d.get("drift2_g_per_s2", [0, 0, 0]), float),
                float(d.get("t_ref_s", 0.0)), float(d.get("temp_ref_k", 0.0)),
                None if cov is None else np.array(cov, float),
                tuple(d.get("parameter_names", ())),
                np.array(d.get("cross_per_g", np.zeros((3, 3))), float),
                np.array(d.get("scale_drift_per_s", [0, 0, 0]), float),
                np.array(d.get("scale_temp_per_k", [0, 0, 0]), float),
                np.array(d.get("scale_warmup", [0, 0, 0]), float),
                float(d.get("warmup_tau_s", 0.0)),
                np.array(d.get("hysteresis_g", [0, 0, 0]), float),
                np.array(d.get("k3_per_g2", [0, 0, 0]), float),
                np.array(d.get("scale_asymmetry", [0, 0, 0]), float))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: not a calibration model ({exc!s}); expected the "
                             "'model' block that 'align calibrate --json' writes") from None
        return _checked(m, where)


def pose_sigma_g(model: TriadModel, poses: Poses) -> np.ndarray | None:
    """Standard deviation of |a| for each pose mean, from its output scatter [g]."""
    if poses.sigma_u is None:
        return None
    # One sensor, one noise: pool the per-pose estimates (each from a few hundred correlated
    # samples, so +-10 % each) into one per axis, scaled by each pose's sample count. Noisy
    # per-pose weights would cost the ML fit more than it gains.
    n = poses.count.astype(float)
    pooled = np.sqrt(np.sum((poses.sigma_u**2) * n[:, None] ** 2, 0) / np.sum(n))
    sigma_u = pooled[None, :] / np.sqrt(n)[:, None]
    return np.sqrt(np.sum((pose_gradient(model, poses) * sigma_u) ** 2, axis=1))


def pose_gradient(model: TriadModel, poses: Poses) -> np.ndarray:
    """d|a|/du of each pose (N, 3) [g per output unit]."""
    a = model.specific_force(poses.u, poses.t, poses.temp)
    n = a / np.linalg.norm(a, axis=1, keepdims=True)
    return n @ np.linalg.inv(model.k[:, None] * r_matrix(model.beta))


def delta_g(model: TriadModel, poses: Poses) -> np.ndarray:
    """|a| - 1 per pose through the model [g] (the paper's check-pose figure)."""
    return np.linalg.norm(model.specific_force(poses.u, poses.t, poses.temp), axis=1) - 1.0


MAX_BETA_RAD = np.pi / 4
"""Largest non-orthogonality a model file may hold: R (eq. 5) is singular at pi/2, and an
axis 45 deg off its place is no triad (real ones are within a degree)."""


def _checked(m: TriadModel, where: str) -> TriadModel:
    """Refuse a model that cannot be applied: a non-finite value anywhere, a zero scale
    factor, a non-orthogonality beyond :data:`MAX_BETA_RAD` (one line naming the key)."""
    keys = {"k_v_per_g": m.k, "beta_rad": m.beta, "bias_g": m.bias, "k2_per_g": m.k2,
            "drift_g_per_s": m.drift, "temp_coeff_g_per_k": m.temp_coeff,
            "drift2_g_per_s2": m.drift2, "t_ref_s": np.atleast_1d(m.t_ref),
            "temp_ref_k": np.atleast_1d(m.temp_ref), "cross_per_g": m.cross.ravel(),
            "scale_drift_per_s": m.scale_drift, "scale_temp_per_k": m.scale_temp,
            "scale_warmup": m.scale_warmup, "warmup_tau_s": np.atleast_1d(m.warmup_tau_s),
            "hysteresis_g": m.hysteresis, "k3_per_g2": m.k3, "scale_asymmetry": m.asymmetry}
    if m.cross.shape != (3, 3):
        raise InputError(f"{where}: model.cross_per_g: shape {m.cross.shape}, a triad has 3x3")
    for key, v in keys.items():
        if key not in ("t_ref_s", "temp_ref_k", "warmup_tau_s", "cross_per_g") and (
                v.shape != (3,)):
            raise InputError(f"{where}: model.{key}: {v.size} values, a triad has 3")
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            at = f"[{bad[0]}]" if v.size > 1 else ""
            raise InputError(f"{where}: model.{key}{at} = {v[bad[0]]}: not a finite number")
    zero = np.flatnonzero(m.k == 0)
    if zero.size:
        raise InputError(f"{where}: model.k_v_per_g[{zero[0]}] = 0: a scale factor cannot be "
                         "zero")
    wide = np.flatnonzero(np.abs(m.beta) >= MAX_BETA_RAD)
    if wide.size:
        raise InputError(f"{where}: model.beta_rad[{wide[0]}] = {m.beta[wide[0]]:.4g} rad: "
                         f"beyond any triad's non-orthogonality (< {MAX_BETA_RAD:.4g} rad)")
    if m.cov is not None and (m.cov.ndim != 2 or m.cov.shape[0] != m.cov.shape[1]
                              or (m.names and m.cov.shape[0] != len(m.names))):
        raise InputError(f"{where}: model.covariance: shape {m.cov.shape} does not match "
                         f"its {len(m.names)} parameter_names")
    return m
