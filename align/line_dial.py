"""A dial: lines of one image that meet at a point (a protractor's, a rotary scale's
graduations), measured as one — the increment between neighbouring lines, its uniformity,
and the point they meet at (:func:`line_dial`; the groups come from :mod:`imaging.dials`,
the frame's lens's share from :mod:`align.family_stage`). Moved out of :mod:`align.family`
(a family of parallel lines) whole.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)

DIAL_FORMAT_VERSION = 1


@dataclass(frozen=True)
class LineDial:
    """Lines of one image that meet at a point (a graduated dial) measured as one.

    Centre: the point P minimising chi2_c = sum((n_i . P - d_i)^2 / s_i^2) (n_i, d_i each
    line's normal and offset; s_i^2 = u(d_i)^2 + (r_i u(a_i))^2, r_i the distance from P to
    its middle), on n - 2 dof. Directions: each line's angle a_i turned to point away from P,
    theta_i [rad, from +x towards -y], ordered round P; steps k_i = round((theta_i -
    theta_0) / g_min); theta_i = theta_0 + increment k_i by weighted least squares (w_i =
    1 / u(a_i)^2, each line's own u without the lens's share); chi2 of the residuals on n - 2
    dof says whether the graduation is uniform within the lines' u; u(increment) is widened
    by sqrt(chi2/dof) when chi2 is significant.

    Attributes
    ----------
    members : tuple of int
        Mark indices, ordered round the centre — dimensionless.
    centre_px, centre_u_px : (float, float)
        P (x, y) [px, relative to the image centre, x right, y down] and its u [px].
    centre_chi2, centre_dof, centre_p : float, int, float
        chi2_c, n - 2, its upper-tail probability (lines that miss one point: p small) —
        dimensionless.
    increment_rad, increment_u_rad : float
        Angle between neighbouring graduations [rad] and its u [rad].
    steps : tuple of int
        Each member's step k_i round the dial — dimensionless.
    residuals_rad : tuple of float
        theta_i minus the uniform graduation's [rad].
    spread_rad : float
        RMS of the residuals [rad] (the graduation's non-uniformity, as imaged).
    chi2, dof, p_value : float, int, float
        The residuals' chi2, n - 2, upper-tail probability — dimensionless.
    lens : str
        As :attr:`LineFamily.lens`; unit —.
    increment_u_lens_rad : float
        The frame's lens's share of ``increment_u_rad`` [rad]: the increment is a weighted
        sum of the members' angles, so per lens error direction the same sum of their
        signed lens couplings (one lens moves them together), the directions in quadrature
        (0: no lens u). The centre's u holds the lines' own u only.
    """

    members: tuple[int, ...]
    centre_px: tuple[float, float]
    centre_u_px: tuple[float, float]
    centre_chi2: float
    centre_dof: int
    centre_p: float
    increment_rad: float
    increment_u_rad: float
    steps: tuple[int, ...]
    residuals_rad: tuple[float, ...]
    spread_rad: float
    chi2: float
    dof: int
    p_value: float
    lens: str = "none"
    increment_u_lens_rad: float = 0.0

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    def uniform(self, alpha: float = 1e-3) -> bool:
        """Whether the lines meet at one point and are evenly spaced within their u."""
        return bool(self.p_value >= alpha and self.centre_p >= alpha)

    def to_dict(self) -> dict:
        """The ``dial`` block of a member's entry in ``align marks --json``."""
        arc = float(np.rad2deg(1) * 3600)
        return {"format_version": DIAL_FORMAT_VERSION, "members": list(self.members),
                "lines": len(self.members), "centre_px": list(self.centre_px),
                "centre_u_px": list(self.centre_u_px), "centre_chi2": self.centre_chi2,
                "centre_dof": self.centre_dof, "centre_p": self.centre_p,
                "increment_rad": self.increment_rad, "increment_u_rad": self.increment_u_rad,
                "increment_deg": float(np.rad2deg(self.increment_rad)),
                "increment_u_arcsec": self.increment_u_rad * arc, "steps": list(self.steps),
                "residuals_rad": list(self.residuals_rad), "spread_rad": self.spread_rad,
                "spread_arcsec": self.spread_rad * arc, "chi2": self.chi2, "dof": self.dof,
                "chi2_dof": self.chi2_dof, "p_value": self.p_value, "lens": self.lens,
                "increment_u_lens_rad": self.increment_u_lens_rad,
                "increment_u_lens_arcsec": self.increment_u_lens_rad * arc}

    @classmethod
    def from_dict(cls, d: Mapping) -> LineDial:
        """From :meth:`to_dict`'s keys; a newer format version is refused."""
        if int(d.get("format_version", 1)) > DIAL_FORMAT_VERSION:
            raise ValueError(f"dial block format_version {d['format_version']}: newer than "
                             f"this tool reads ({DIAL_FORMAT_VERSION})")
        f = float
        return cls(tuple(int(i) for i in d["members"]),
                   (f(d["centre_px"][0]), f(d["centre_px"][1])),
                   (f(d["centre_u_px"][0]), f(d["centre_u_px"][1])), f(d["centre_chi2"]),
                   int(d["centre_dof"]), f(d["centre_p"]), f(d["increment_rad"]),
                   f(d["increment_u_rad"]), tuple(int(k) for k in d["steps"]),
                   tuple(f(v) for v in d["residuals_rad"]), f(d["spread_rad"]),
                   f(d["chi2"]), int(d["dof"]), f(d["p_value"]), str(d.get("lens", "none")),
                   f(d.get("increment_u_lens_rad", 0.0)))

    def summary(self) -> str:
        """One line for the terminal."""
        arc = float(np.rad2deg(1) * 3600)
        s = (f"dial of {len(self.members)} lines: centre ({self.centre_px[0]:+.2f}, "
             f"{self.centre_px[1]:+.2f}) ± ({self.centre_u_px[0]:.2f}, "
             f"{self.centre_u_px[1]:.2f}) px from the image centre (p {self.centre_p:.2g}), "
             f"increment {np.rad2deg(self.increment_rad):.5f}° ± "
             f"{self.increment_u_rad * arc:.1f}″, chi2/dof {self.chi2_dof:.2f} "
             f"(p {self.p_value:.2g}), spread {self.spread_rad * arc:.1f}″, lens: {self.lens}")
        if not self.uniform():
            s += "; NOT UNIFORM"
        return s


def line_dial(indices: Sequence[int], angles: np.ndarray, angle_u: np.ndarray,
              offsets: np.ndarray, offset_u: np.ndarray, middles: np.ndarray,
              lens: str = "none", alpha: float = 1e-3,
              lens_coupling: Sequence[Mapping[str, float]] = ()) -> LineDial:
    """The dial of lines with these angles [rad] (own u [rad]), offsets from the image
    centre along their normals [px] (u [px]) and middles (N, 2) [px]; ``lens_coupling``:
    each line's angle's signed components on the frame lens's error directions [rad]
    (:attr:`align.mark_result.MarkResult.lens_coupling`); formulas in :class:`LineDial`."""
    a = np.asarray(angles, float)
    au = np.asarray(angle_u, float)
    d = np.asarray(offsets, float)
    du = np.asarray(offset_u, float)
    mid = np.asarray(middles, float)
    n = np.column_stack([np.sin(a), np.cos(a)])
    p = np.zeros(2)
    for _ in range(4):
        r = np.hypot(*(mid - p).T)
        s2 = du**2 + (r * au) ** 2
        A = (n / s2[:, None]).T @ n
        p = np.linalg.solve(A, (n / s2[:, None]).T @ d)
    cov = np.linalg.inv(A)
    res_c = n @ p - d
    m = len(a)
    c_chi2 = float(np.sum(res_c**2 / s2))
    c_dof = m - 2
    c_p = float(special.chdtrc(c_dof, c_chi2)) if c_dof > 0 else 1.0
    # Each line's direction away from the centre (display angles: +x towards -y).
    out = np.arctan2(-(mid[:, 1] - p[1]), mid[:, 0] - p[0])
    th = a + np.pi * (np.cos(a - out) < 0)
    order = np.argsort(np.mod(th - th[0], 2 * np.pi))
    th, w_u = np.unwrap(th[order]), au[order]
    th = th - 2 * np.pi * np.floor((th[0] + np.pi) / (2 * np.pi))
    gaps = np.diff(th)
    g0 = float(np.min(gaps)) if gaps.size else float("nan")
    k = np.rint((th - th[0]) / g0)
    w = 1 / w_u**2
    X = np.column_stack([np.ones(m), k])
    C = np.linalg.inv((X * w[:, None]).T @ X)
    beta = C @ ((X * w[:, None]).T @ th)
    res = th - X @ beta
    dof = m - 2
    chi2 = float(np.sum(w * res**2))
    pv = float(special.chdtrc(dof, chi2)) if dof > 0 else 1.0
    inc_u = float(np.sqrt(C[1, 1]))
    if pv < alpha:
        inc_u *= float(np.sqrt(chi2 / dof))
    inc_lens = 0.0
    if len(lens_coupling) == m:
        # The increment's weights on the members' angles (theta_i = a_i + a half turn or
        # not: d theta_i / d a_i = 1), applied to each lens direction's components.
        c = (C @ (X * w[:, None]).T)[1]
        cpl = [lens_coupling[i] for i in order]
        keys = sorted({k for t in cpl for k in t})
        inc_lens = float(np.sqrt(sum(sum(c[i] * cpl[i].get(key, 0.0) for i in range(m)) ** 2
                                     for key in keys)))
        inc_u = float(np.hypot(inc_u, inc_lens))
    return LineDial(tuple(int(indices[i]) for i in order), (float(p[0]), float(p[1])),
                    (float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1]))), c_chi2, c_dof, c_p,
                    float(beta[1]), inc_u, tuple(int(v) for v in k),
                    tuple(float(v) for v in res), float(np.sqrt(np.mean(res**2))), chi2, dof,
                    pv, lens, inc_lens)
