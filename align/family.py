"""A family of lines (ruled scale, grating) measured as one: parallelism and ruling.

The members are lines of one image that the detector grouped (:mod:`imaging.families`);
each was measured on its own (with the frame's lens: a camera model, or the frame's joint
k1 when applied — whatever :func:`align.marks.measure_image` used for every mark).

Parallelism: the weighted mean angle a_bar = sum(w_i a_i) / sum(w_i), w_i = 1 / u_i^2, and
chi2 = sum(w_i (a_i - a_bar)^2) on n - 1 degrees of freedom: ~1 per dof when the members
are parallel and their u right. A member whose z_i = (a_i - a_bar) / sqrt(u_i^2 - u_bar^2)
exceeds the two-sided normal quantile at alpha / n (Bonferroni over the members) is named
deviant (a tilted or bent graduation), the worst first, and left out of a_bar and chi2
(which then run over the n' - 1 others). When chi2 is significant, u(a_bar) is widened by
sqrt(chi2 / dof) (Birge ratio): the stated u then covers the scatter. The lens the frame
shares (its named u terms, :func:`align.marks.finish_mark`) is left out of the members' u for
chi2 — one lens moves them together — and added to the mean's u: per term, the members'
terms averaged with the mean's weights.

Ruling: each member's middle projected on the mean normal, q_i [px]; the ruling steps k_i
= round((q_i - q_0) / g_min) (g_min the smallest gap, so missing graduations are skipped);
q_i = q_0 + pitch k_i by least squares. Uniformity: the residuals from that uniform ruling
[px], their RMS (``pitch_spread_px``), and u(pitch) from the larger of that scatter and the
members' own offset u.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.special import ndtri

FORMAT_VERSION = 1


def _wrap(a: np.ndarray | float) -> np.ndarray:
    return (np.asarray(a) + np.pi / 2) % np.pi - np.pi / 2


@dataclass(frozen=True)
class LineFamily:
    """Parallel lines of one image measured as one.

    Attributes
    ----------
    members : tuple of int
        The members' mark indices in the image, ordered across the lines — dimensionless.
    angle_rad, angle_u_rad : float
        Weighted mean angle of the members [rad] and its standard uncertainty [rad]
        (widened by sqrt(chi2/dof) when the members disagree), the lens's share included.
    angle_u_lens_rad : float
        The lens's share of ``angle_u_rad`` [rad]: per lens term, the members' terms
        averaged with the mean's weights (added linearly: one lens moves them together).
    chi2, dof, p_value : float, int, float
        Members' angles about the weighted mean: chi2, n - 1, upper-tail probability —
        dimensionless.
    z : tuple of float
        Each member's normalised deviation from the mean angle — dimensionless.
    deviant : tuple of int
        Mark indices of the members beyond the Bonferroni limit (tilted or bent lines) —
        dimensionless.
    pitch_px, pitch_u_px : float
        Distance between neighbouring ruling positions [px] and its uncertainty [px].
    steps : tuple of int
        Each member's ruling step (0 for the first; a skipped graduation skips a step) —
        dimensionless.
    pitch_residuals_px : tuple of float
        Each member's position minus the uniform ruling's [px].
    pitch_spread_px : float
        RMS of ``pitch_residuals_px`` [px] (the ruling's non-uniformity, as imaged).
    lens : str
        What corrected the members for the lens: ``camera model``, ``frame lens`` (fitted
        from the frame's lines), ``none``; unit —.
    failed : int
        Lines of the family found but not measured (each is its own failed entry) —
        dimensionless.
    """

    members: tuple[int, ...]
    angle_rad: float
    angle_u_rad: float
    chi2: float
    dof: int
    p_value: float
    z: tuple[float, ...]
    deviant: tuple[int, ...]
    pitch_px: float
    pitch_u_px: float
    steps: tuple[int, ...]
    pitch_residuals_px: tuple[float, ...]
    pitch_spread_px: float
    lens: str = "none"
    failed: int = 0
    angle_u_lens_rad: float = 0.0

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    def consistent(self, alpha: float = 1e-3) -> bool:
        """Whether the members are parallel within their u (chi2 test, none deviant)."""
        return bool(self.p_value >= alpha and not self.deviant)

    def to_dict(self) -> dict:
        """The ``family`` block of a member's entry in ``align marks --json``."""
        return {"format_version": FORMAT_VERSION, "members": list(self.members),
                "lines": len(self.members),
                "angle_deg": float(np.rad2deg(self.angle_rad)),
                "angle_u_arcsec": float(np.rad2deg(self.angle_u_rad) * 3600),
                "angle_rad": self.angle_rad, "angle_u_rad": self.angle_u_rad,
                "chi2": self.chi2, "dof": self.dof, "chi2_dof": self.chi2_dof,
                "p_value": self.p_value, "z": list(self.z), "deviant": list(self.deviant),
                "pitch_px": self.pitch_px, "pitch_u_px": self.pitch_u_px,
                "steps": list(self.steps), "pitch_residuals_px": list(self.pitch_residuals_px),
                "pitch_spread_px": self.pitch_spread_px, "lens": self.lens,
                "failed": self.failed, "angle_u_lens_rad": self.angle_u_lens_rad,
                "angle_u_lens_arcsec": float(np.rad2deg(self.angle_u_lens_rad) * 3600)}

    @classmethod
    def from_dict(cls, d: Mapping) -> LineFamily:
        """From :meth:`to_dict`'s keys; a newer format version is refused."""
        if int(d.get("format_version", 1)) > FORMAT_VERSION:
            raise ValueError(f"family block format_version {d['format_version']}: newer "
                             f"than this tool reads ({FORMAT_VERSION})")

        def num(v: object) -> float:
            return float("nan") if v is None else float(v)  # type: ignore[arg-type]

        return cls(tuple(int(i) for i in d["members"]), num(d["angle_rad"]),
                   num(d["angle_u_rad"]), num(d["chi2"]), int(d["dof"]), num(d["p_value"]),
                   tuple(num(v) for v in d["z"]), tuple(int(i) for i in d["deviant"]),
                   num(d["pitch_px"]), num(d["pitch_u_px"]), tuple(int(k) for k in d["steps"]),
                   tuple(num(v) for v in d["pitch_residuals_px"]), num(d["pitch_spread_px"]),
                   str(d.get("lens", "none")), int(d.get("failed", 0)),
                   num(d.get("angle_u_lens_rad", 0.0)))

    def summary(self) -> str:
        """One line for the terminal."""
        s = (f"family of {len(self.members)} lines: angle {np.rad2deg(self.angle_rad):+.6f}° "
             f"± {np.rad2deg(self.angle_u_rad) * 3600:.2f}″, chi2/dof {self.chi2_dof:.2f} "
             f"(p {self.p_value:.2g}), pitch {self.pitch_px:.3f} ± {self.pitch_u_px:.3f} px, "
             f"spread {self.pitch_spread_px:.3f} px, lens: {self.lens}")
        if self.deviant:
            s += f"; NOT PARALLEL: marks {', '.join(map(str, self.deviant))}"
        return s


def line_family(indices: Sequence[int], angles: np.ndarray, angle_u: np.ndarray,
                middles: np.ndarray, offset_u: np.ndarray, lens: str = "none",
                failed: int = 0, alpha: float = 1e-3,
                lens_terms: Sequence[Mapping[str, float]] = ()) -> LineFamily:
    """The family of lines with these angles [rad] (``angle_u``: each one's own u without
    the lens's share [rad]), middles (N, 2) [px, relative to the image centre] (offset u
    [px]) and the lens's named u terms per member [rad] (the shared lens: they enter the
    mean's u, not the members' chi2); see the module docstring for the formulas."""
    angles = np.asarray(angles, float)
    ref = angles[0]
    d = _wrap(angles - ref)
    u_all = np.asarray(angle_u, float)
    n = len(angles)
    limit = float(-ndtri(alpha / (2 * n)))
    keep = np.ones(n, bool)
    while True:
        # The mean of the members not (yet) named deviant; the worst beyond the limit goes
        # (one at a time: a tilted member pulls the mean towards itself).
        w = 1 / u_all[keep] ** 2
        mean_d = float(np.sum(w * d[keep]) / w.sum())
        u_mean = float(1 / np.sqrt(w.sum()))
        z = (d - mean_d) / np.sqrt(np.maximum(u_all**2 - np.where(keep, u_mean**2, 0), 1e-300))
        worst = int(np.argmax(np.where(keep, np.abs(z), -1)))
        if abs(z[worst]) <= limit or keep.sum() <= 2:
            break
        keep[worst] = False
    dof = int(keep.sum()) - 1
    chi2 = float(np.sum(w * (d[keep] - mean_d) ** 2))
    p = float(special.chdtrc(dof, chi2)) if dof > 0 else 1.0
    deviant = tuple(int(indices[i]) for i in np.flatnonzero(~keep))
    if p < alpha:
        u_mean *= np.sqrt(chi2 / dof)
    u_lens = 0.0
    if lens_terms:
        wk = np.where(keep, 1 / u_all**2, 0.0)
        wk = wk / wk.sum()
        names = sorted({k for t in lens_terms for k in t})
        u_lens = float(np.sqrt(sum(sum(wk[i] * abs(lens_terms[i].get(k, 0.0))
                                       for i in range(n)) ** 2 for k in names)))
        u_mean = float(np.hypot(u_mean, u_lens))
    mean = float(_wrap(ref + mean_d))
    normal = np.array([np.sin(mean), np.cos(mean)])
    q = np.asarray(middles, float) @ normal
    order = np.argsort(q)
    q, ou = q[order], np.asarray(offset_u, float)[order]
    gaps = np.diff(q)
    g0 = float(np.min(gaps)) if gaps.size else float("nan")
    k = np.rint((q - q[0]) / g0) if gaps.size else np.zeros(1)
    if n >= 3 and np.ptp(k) > 0:
        pitch, q0 = np.polyfit(k, q, 1)
        res = q - (q0 + pitch * k)
        scatter = max(float(np.sqrt(np.sum(res**2) / (n - 2))), float(np.median(ou)))
        pitch_u = scatter / float(np.sqrt(np.sum((k - k.mean()) ** 2)))
    else:
        pitch, res, pitch_u = float("nan"), np.full(n, np.nan), float("nan")
    idx = tuple(int(indices[i]) for i in order)
    return LineFamily(idx, mean, u_mean, chi2, dof, p, tuple(float(v) for v in z[order]),
                      deviant, float(pitch), float(pitch_u), tuple(int(v) for v in k),
                      tuple(float(v) for v in res), float(np.sqrt(np.mean(res**2))), lens,
                      failed, u_lens)
