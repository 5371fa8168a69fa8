"""Check poses: independent static poses through the calibration must read 1 g.

For each check pose, dg = |a| - 1 [g] is compared with what it may be when the calibration
holds: the noise of the pose's mean (its own sample scatter, else the calibration poses'
pooled noise), the calibration's uncertainty propagated to |a| (k, beta, b; the effects'
parameters are second order there) and the calibration's own residual scatter beyond its
noise (placement, settling: what its chi2 shows, also present in a check). A pose beyond
the Bonferroni bound of the loop's significance over the check poses disagrees: the check
or the calibration cannot be trusted, and the result says so (``ok: false``, exit 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

from align.calibration.pipeline import Calibration
from align.calibration.triad import CORE, Poses, delta_g, pose_sigma_g
from align.calibration.units import UNIT_SCALE_REFUSE


@dataclass(frozen=True)
class CheckResult:
    """dg [g], its standard uncertainty u [g] and z = dg/u per check pose; ``limit`` the |z|
    beyond which a pose disagrees; ``warnings`` (empty when every pose agrees)."""

    labels: tuple[str, ...]
    dg: np.ndarray
    u: np.ndarray
    z: np.ndarray
    limit: float
    warnings: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.warnings

    def to_list(self) -> list[dict]:
        return [{"pose": lab, "dg_g": float(d), "u_g": float(u), "z": float(z)}
                for lab, d, u, z in zip(self.labels, self.dg, self.u, self.z, strict=True)]


def _model_u(cal: Calibration, check: Poses) -> np.ndarray:
    """u(|a|) per check pose from the covariance of (k, beta, b) (numerical Jacobian)."""
    m = cal.model
    if m.cov is None or len(m.names) < 9:
        return np.zeros(len(check.u))
    from dataclasses import replace

    theta = np.concatenate([m.k, m.beta, m.bias])
    steps = np.concatenate([np.abs(m.k) * 1e-7, np.full(6, 1e-8)])

    def norm_a(th: np.ndarray) -> np.ndarray:
        mm = replace(m, k=th[:3], beta=th[3:6], bias=th[6:9])
        return np.linalg.norm(mm.specific_force(check.u, check.t, check.temp), axis=1)

    J = np.column_stack([(norm_a(theta + h * e) - norm_a(theta - h * e)) / (2 * h)
                         for h, e in zip(steps, np.eye(9), strict=True)])
    var = np.einsum("ij,jk,ik->i", J, np.nan_to_num(m.cov_of(*CORE)), J)
    return np.sqrt(np.maximum(var, 0.0))


def check_poses(cal: Calibration, poses: Poses, check: Poses, alpha: float = 1e-3,
                where: str = "check") -> CheckResult:
    """Judge the check poses ``check`` against the calibration ``cal`` made from ``poses``."""
    m = cal.model
    dg = delta_g(m, check)
    own = delta_g(m, poses)
    sig_cal = pose_sigma_g(m, poses)
    if sig_cal is not None:
        excess = max(0.0, float(np.mean(own**2) - np.mean(sig_cal**2)))
    else:  # noise unknown: the residual (per dof) is the whole scatter of a pose's |a|
        excess = float(np.sum(own**2) / max(cal.loop.after.dof, 1))
    sig = pose_sigma_g(m, check)
    if sig is None:
        # Means only: the calibration poses' noise stands in (same sensor), else none.
        sig = np.full(len(dg), float(np.median(sig_cal)) if sig_cal is not None else 0.0)
    u = np.sqrt(sig**2 + _model_u(cal, check) ** 2 + excess)
    z = dg / np.where(u > 0, u, np.inf)
    limit = float(-special.ndtri(alpha / (2 * len(dg))))
    bad = np.flatnonzero(~(np.abs(z) <= limit))
    warnings: list[str] = []
    if bad.size:
        worst = bad[np.argmax(np.abs(z[bad]))]
        names = ", ".join(check.labels[i] for i in bad[:10]) + (
            f" and {bad.size - 10} more" if bad.size > 10 else "")
        text = (f"{where}: {bad.size} of {len(dg)} check poses disagree with 1 g through the "
                f"calibration ({names}; worst {check.labels[worst]}: |a| - 1 = "
                f"{dg[worst]:+.4g} g, {z[worst]:+.3g} u; |z| > {limit:.2f} at alpha "
                f"{alpha:g}): the check or the calibration cannot be trusted")
        ratio = float(np.median(dg + 1.0))
        if ratio > UNIT_SCALE_REFUSE or ratio < 1 / UNIT_SCALE_REFUSE:
            text += (f"; the check poses read {ratio:.4g} g: in another unit than the static "
                     "file?")
        warnings.append(text)
    return CheckResult(check.labels, dg, u, z, limit, tuple(warnings))
