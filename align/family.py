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
terms averaged with the mean's weights. What the lens moves unlike (an undetermined k1
turns the lines on either side of the centre opposite ways) is in chi2 and z when the
members' signed lens couplings c_i are known: their covariance V = diag(u_i^2) + C C^T,
chi2 = r' V^-1 r about the generalised least-squares mean, z_i each member's residual
given the others (:func:`_lens_chi2`); a spread of angles the lens (undetermined) can
explain is then no "not parallel" (a 23-line scale through an undeclared k1 -0.3 lens: 15
lines so named before).

Ruling: each member's middle projected on the mean normal, q_i [px]; the ruling steps k_i
counted gap by gap, each gap in whole single steps (:func:`ruling_steps`: a missing
graduation skips a step); q_i = q_0 + pitch k_i by least squares. Uniformity: the residuals
from that uniform ruling [px], their RMS (``pitch_spread_px``), and u(pitch) from the larger
of that scatter and the members' own offset u. The scatter s is a Type A estimate on
nu = n - 2 dof (3 to 7 for a 5-9 line scale): its z follows Student's t, whose standard
deviation is sqrt(nu / (nu - 2)) (1.73 at nu = 3), so s is taken times that factor (times
sqrt 3, nu = 3's, for 3-4 lines, where it is unbounded): 64 stage-micrometer frames' pitch
z had RMS 1.26 and |z| up to 4.1 with s alone. The background's shading across each member
(its groove fit's slope over its level, gamma) weights its dip's two sides unequally: the
groove's centre moves by about gamma M2 (M2 = w^2 / 12 + blur^2, the profile's second moment:
a fit of a symmetric profile to a multiplicatively shaded one) — the same for every member
under a uniform slope, but vignetting's slope changes across the scale, and its linear part
is a pitch no residual shows; the pitch's slope of those moves is ``pitch_u_shading_px``, in
u(pitch) (:func:`shading_shift`). A step between the first and the last member
that holds no measured line is said (``missing_steps``; the result is then not ok): a
regular family with a line missing is never reported as complete.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
from scipy import special  # (not scipy.stats: ~0.8 s of CPU to import; the same functions)
from scipy.special import ndtri

from imaging import line_frame
from imaging.ends import checked_ends
from imaging.ends_blur import ends_at_their_blur

R = TypeVar("R")

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
    lengths_px, lengths_max_px : tuple of float
        Each member's visible length and the longest it can be [px] (:mod:`imaging.ends`:
        larger only when an end lies under an obstruction — dust, ink — whose far side
        bounds it), in ``members`` order.
    hidden_ends : tuple of int
        Each member's ends under an obstruction (0, 1 or 2), in ``members`` order —
        dimensionless.
    typical_length_px : float
        Median visible length of the members with both ends seen [px] (nan: none).
    pitch_u_lens_px : float
        The frame's lens's share of the pitch's u [px] (:mod:`align.family_stage`: what the
        lens's u moves the members' positions by), in ``pitch_u_px`` (0: none).
    pitch_u_shading_px : float
        The background's shading's share of the pitch's u [px] (:func:`shading_shift`: how
        far each member's centre may sit off its groove's middle under it), in
        ``pitch_u_px`` (0: none).
    lens_fitted : int
        Lens directions fitted from the members' angles with their mean (bounds on the
        frame's lens the family sees, :func:`lens_directions`): each takes one of the
        chi2's dof — dimensionless.
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
    lengths_px: tuple[float, ...] = ()
    lengths_max_px: tuple[float, ...] = ()
    hidden_ends: tuple[int, ...] = ()
    typical_length_px: float = float("nan")
    pitch_u_lens_px: float = 0.0
    lens_fitted: int = 0
    pitch_u_shading_px: float = 0.0

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def missing_steps(self) -> tuple[int, ...]:
        """Steps of the ruling between its first and last member that hold no measured
        line (a graduation missing from the scale, not found, or not measured) —
        dimensionless."""
        have = set(self.steps)
        return tuple(k for k in range(max(self.steps, default=0) + 1) if k not in have)

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
                "angle_u_lens_arcsec": float(np.rad2deg(self.angle_u_lens_rad) * 3600),
                "lengths_px": list(self.lengths_px), "lengths_max_px": list(self.lengths_max_px),
                "hidden_ends": list(self.hidden_ends),
                "typical_length_px": self.typical_length_px,
                "pitch_u_lens_px": self.pitch_u_lens_px,
                "lens_fitted": self.lens_fitted,
                "pitch_u_shading_px": self.pitch_u_shading_px,
                "missing_steps": list(self.missing_steps)}

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
                   num(d.get("angle_u_lens_rad", 0.0)),
                   tuple(num(v) for v in d.get("lengths_px", ())),
                   tuple(num(v) for v in d.get("lengths_max_px", ())),
                   tuple(int(v) for v in d.get("hidden_ends", ())),
                   num(d.get("typical_length_px")), num(d.get("pitch_u_lens_px", 0.0)),
                   int(d.get("lens_fitted", 0)), num(d.get("pitch_u_shading_px", 0.0)))

    def summary(self) -> str:
        """One line for the terminal."""
        s = (f"family of {len(self.members)} lines: angle {np.rad2deg(self.angle_rad):+.6f}° "
             f"± {np.rad2deg(self.angle_u_rad) * 3600:.2f}″, chi2/dof {self.chi2_dof:.2f} "
             f"(p {self.p_value:.2g}"
             + (f", {self.lens_fitted} lens direction{'s' if self.lens_fitted > 1 else ''} "
                "fitted" if self.lens_fitted else "")
             + f"), pitch {self.pitch_px:.3f} ± {self.pitch_u_px:.3f} px"
             + (f" ({self.pitch_u_lens_px:.3f} of it the lens)" if self.pitch_u_lens_px else "")
             + ", "
             f"spread {self.pitch_spread_px:.3f} px, lens: {self.lens}")
        if np.isfinite(self.typical_length_px):
            s += f", typical length {self.typical_length_px:.0f} px"
        if any(self.hidden_ends):
            s += f", {sum(1 for h in self.hidden_ends if h)} with an end hidden"
        if self.deviant:
            s += f"; NOT PARALLEL: marks {', '.join(map(str, self.deviant))}"
        if self.missing_steps:
            s += f"; LINES MISSING at steps {', '.join(map(str, self.missing_steps))}"
        return s


def family_gaps(r: object) -> tuple[int, ...]:
    """The missing steps of the family a mark result belongs to (() when none, or no
    family): a regular family with lines missing is not ok."""
    fam = getattr(r, "family", None)
    return fam.missing_steps if fam is not None else ()


def member_ends(image: np.ndarray, r: R) -> tuple[R, tuple[float, float, int]]:
    """A measured member (an ``align.marks.MarkResult``) with its ends checked for
    obstructions (:func:`imaging.ends.groove_ends`): its ``length_px`` the visible length,
    a note when an end is hidden (the length is then a lower bound, the far side of the
    obstruction its upper one); and (visible length, longest length [px], ends hidden)."""
    m = r.measurement
    if m is None:
        return r, (r.length_px, r.length_px, 0)
    e = checked_ends(image, m.profile, m.extent_px, m.centres, m.ends_check)
    # A defocus gradient misfits the band's one blur at both ends (imaging/ends_blur.py).
    e = ends_at_their_blur(image, m.profile, m.extent_px, m.centres, m.blur, e)
    n_hidden = sum(e.hidden)
    notes = tuple(r.notes)
    if n_hidden:
        notes += (f"{r.image} mark {r.index}: {'both ends' if n_hidden == 2 else 'one end'} "
                  f"under an obstruction (dust or print): length {e.length_px:.0f} px seen, "
                  f"up to {e.length_max_px:.0f} px long with what it may hide (its angle is "
                  "measured on what is seen)",)
    return (replace(r, length_px=e.length_px, notes=notes),
            (e.length_px, e.length_max_px, n_hidden))


def ruling_steps(q: np.ndarray) -> np.ndarray:
    """Each sorted position's ruling step (0 for the first): neighbours' gaps in whole
    steps of the single step, the median of the gaps under 1.5 of the smallest.

    Steps counted gap by gap, not as (q_i - q_0) / g_min: through a lens the image's pitch
    varies across the frame (barrel: 4-6 % smaller at a 1600 x 1200 frame's sides), and the
    smallest gap, taken as the step for the whole ruling, put a skipped step where no line
    is missing (step 16 of 23 at 70 px). Gaps at one step are the local ones, within 25 %."""
    gaps = np.diff(q)
    if not gaps.size:
        return np.zeros(len(q))
    g0 = float(np.min(gaps))
    one = float(np.median(gaps[gaps < 1.5 * g0]))
    return np.concatenate([[0.0], np.cumsum(np.maximum(np.rint(gaps / one), 1.0))])


GAUSSIAN_LENS = ("lens_fit", "camera_")
"""Lens coupling keys whose u is a standard deviation of an estimate (the lens fitted from
the frame's lines, a calibrated camera's): carried in the members' covariance. The others
(``_range``, ``_small``, ``lens_or_bend``, ``lens_pp_cross``) are bounds on where the lens may
be (Type B): the family fits the directions of them it sees (:func:`lens_directions`)."""
SEEN_LENS = 1.0
"""A bounded lens direction that turns the members' angles apart by more than this many of
their own u (whitened, the mean taken out) is fitted from the family; one that turns them
apart by less is left out of their chi2."""


def lens_directions(u: np.ndarray, cpl: np.ndarray, gaussian: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The frame's one lens as the family sees it: (F, L) — F (N, m) the members' angle
    moves [rad] along the bounded lens directions their angles determine (fitted from the
    family with the mean, m at most N - 3), L (N, k) the couplings carried in their
    covariance (V = diag(u^2) + L L^T): the Gaussian ones (all of them for 3 members or
    fewer, which leave no dof to fit from).

    A bound carried as a u (the plausible range as a uniform) is right for a lens drawn
    from the range, not for the one lens of a frame: a lens-free scale read chi2/dof 0.63
    on average (0.7-1.4 expected), the spread its lines do not have taken for what the lens
    may have done. Fitted, the lens takes its own dof: chi2/dof ~1 whatever the lens is. A
    bounded direction the family does not see (singular value <= :data:`SEEN_LENS`) is left
    out: carried, these made the chi2/dof 0.78 through a k1 -0.15 lens (39 ``synth`` scales
    800 x 600, seeds 200-239; 0.87 left out); a lens at the edge of its range along one
    adds at most 3 to the chi2 (its u is range / sqrt 3).
    ``u``: the members' own u [rad]; ``cpl`` (N, K) their signed couplings [rad];
    ``gaussian`` (K,) which couplings are Gaussian (:data:`GAUSSIAN_LENS`)."""
    n = len(u)
    carried = cpl[:, gaussian]
    bounded = cpl[:, ~gaussian]
    if not bounded.size or n <= 3:
        return np.zeros((n, 0)), (cpl if n <= 3 else carried)
    h = 1 / u
    b = bounded / u[:, None]
    b = b - np.outer(h, h @ b) / (h @ h)  # (the mean's direction is fitted anyway)
    _, sv, vt = np.linalg.svd(b, full_matrices=False)
    fit = np.flatnonzero(sv > SEEN_LENS)[: n - 3]
    return bounded @ vt[fit].T, carried


def _lens_chi2(d: np.ndarray, u: np.ndarray, vl: np.ndarray, keep: np.ndarray,
               f: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """(z of every member, chi2 of the kept ones) about their generalised least-squares
    mean and lens fit, their covariance V = diag(u^2) + L L^T (``vl`` = L L^T: the carried
    lens couplings [rad^2]), ``f`` (N, m) the fitted lens directions (:func:`lens_directions`).
    A member's z is its residual given all the others (kept ones, and it): (Q d)_i /
    sqrt(Q_ii), Q = V^-1 - V^-1 X (X' V^-1 X)^-1 X' V^-1, X = [1, f] — what the lens, one
    smooth turn over the frame, cannot make of one line."""
    z = np.zeros(len(d))
    chi2 = 0.0
    x_all = np.column_stack([np.ones(len(d)), f]) if f is not None else np.ones((len(d), 1))
    for i in [-1, *np.flatnonzero(~keep)]:
        sel = keep.copy()
        if i >= 0:
            sel[i] = True
        v = np.diag(u[sel] ** 2) + vl[np.ix_(sel, sel)]
        vi = np.linalg.inv(v)
        x = x_all[sel]
        vx = vi @ x
        q = vi - vx @ np.linalg.pinv(x.T @ vx) @ vx.T
        zi = (q @ d[sel]) / np.sqrt(np.maximum(np.diag(q), 1e-300))
        if i < 0:
            z[sel] = zi
            chi2 = float(d[sel] @ q @ d[sel])
        else:
            z[i] = zi[int(np.flatnonzero(sel).tolist().index(i))]
    return z, chi2


def line_family(indices: Sequence[int], angles: np.ndarray, angle_u: np.ndarray,
                middles: np.ndarray, offset_u: np.ndarray, lens: str = "none",
                failed: int = 0, alpha: float = 1e-3,
                lens_terms: Sequence[Mapping[str, float]] = (),
                lengths: Sequence[tuple[float, float, int]] = (),
                lens_shift: np.ndarray | None = None,
                lens_coupling: Sequence[Mapping[str, float]] = (),
                shading: np.ndarray | None = None) -> LineFamily:
    """The family of lines with these angles [rad] (``angle_u``: each one's own u without
    the lens's share [rad]), middles (N, 2) [px, relative to the image centre] (offset u
    [px]) and the lens's named u terms per member [rad] (the shared lens: they enter the
    mean's u, not the members' chi2); ``lengths``: per member (visible length, longest
    length [px], ends hidden); ``lens_shift`` (N, 2, P): how far each lens error direction
    moves each member's middle [px] (its share of the pitch's u, :mod:`align.family_stage`);
    ``lens_coupling``: each member's angle's signed components on the frame lens's error
    directions [rad] (:attr:`align.mark_result.MarkResult.lens_coupling`: what the lens's
    u turns them by, unlike in different places of the frame); ``shading`` (N, 2): how far
    the background's shading may move each member's centre [px] (:func:`shading_shift`); see
    the module docstring for the formulas."""
    angles = np.asarray(angles, float)
    ref = angles[0]
    d = _wrap(angles - ref)
    u_all = np.asarray(angle_u, float)
    n = len(angles)
    vl, fitted = None, None
    if len(lens_coupling) == n and any(lens_coupling):
        keys = sorted({k for c in lens_coupling for k in c})
        cpl = np.array([[float(c.get(k, 0.0)) for k in keys] for c in lens_coupling])
        fitted, carried = lens_directions(u_all, cpl,
                                          np.array([k.startswith(GAUSSIAN_LENS) for k in keys]))
        vl = carried @ carried.T
    m_fit = fitted.shape[1] if fitted is not None else 0
    limit = float(-ndtri(alpha / (2 * n)))
    keep = np.ones(n, bool)
    while True:
        # The mean of the members not (yet) named deviant; the worst beyond the limit goes
        # (one at a time: a tilted member pulls the mean towards itself).
        w = 1 / u_all[keep] ** 2
        mean_d = float(np.sum(w * d[keep]) / w.sum())
        u_mean = float(1 / np.sqrt(w.sum()))
        if vl is None:
            z = (d - mean_d) / np.sqrt(np.maximum(u_all**2 - np.where(keep, u_mean**2, 0),
                                                  1e-300))
            chi2 = float(np.sum(w * (d[keep] - mean_d) ** 2))
        else:
            z, chi2 = _lens_chi2(d, u_all, vl, keep, fitted)
        worst = int(np.argmax(np.where(keep, np.abs(z), -1)))
        if abs(z[worst]) <= limit or keep.sum() <= 2 + m_fit:
            break
        keep[worst] = False
    # (The lens directions fitted from the family take their dof.)
    dof = int(keep.sum()) - 1 - m_fit
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
    k = ruling_steps(q)
    if n >= 3 and np.ptp(k) > 0:
        pitch, q0 = np.polyfit(k, q, 1)
        res = q - (q0 + pitch * k)
        scatter = max(float(np.sqrt(np.sum(res**2) / (n - 2))) * t_sd(n - 2),
                      float(np.median(ou)))
        pitch_u = scatter / float(np.sqrt(np.sum((k - k.mean()) ** 2)))
    else:
        pitch, res, pitch_u = float("nan"), np.full(n, np.nan), float("nan")
    pitch_lens = pitch_shading = 0.0
    kc = k - k.mean()
    if lens_shift is not None and np.isfinite(pitch):
        # Each lens parameter's move of the positions, as the pitch's slope takes it.
        dq = np.einsum("nip,i->np", np.asarray(lens_shift, float), normal)[order]
        pitch_lens = float(np.linalg.norm(kc @ dq / (kc @ kc)))
        pitch_u = float(np.hypot(pitch_u, pitch_lens))
    if shading is not None and np.isfinite(pitch):
        # The shading's moves of the positions, as the pitch's slope takes them: a Type B
        # term, not a correction (gamma M2 is exact for a Gaussian dip only, and the
        # members' own offsets, read alone, carry the same moves).
        dq = (np.asarray(shading, float) @ normal)[order]
        pitch_shading = float(abs(kc @ dq / (kc @ kc)))
        pitch_u = float(np.hypot(pitch_u, pitch_shading))
    idx = tuple(int(indices[i]) for i in order)
    ln = [lengths[i] for i in order] if len(lengths) == n else []
    seen = [v for v, _, h in ln if not h]
    return LineFamily(idx, mean, u_mean, chi2, dof, p, tuple(float(v) for v in z[order]),
                      deviant, float(pitch), float(pitch_u), tuple(int(v) for v in k),
                      tuple(float(v) for v in res), float(np.sqrt(np.mean(res**2))), lens,
                      failed, u_lens, tuple(float(v) for v, _, _ in ln),
                      tuple(float(v) for _, v, _ in ln), tuple(int(h) for _, _, h in ln),
                      float(np.median(seen)) if seen else float("nan"), pitch_lens, m_fit,
                      pitch_shading)


def t_sd(dof: int) -> float:
    """The factor a Type A standard deviation on ``dof`` degrees of freedom is taken times
    for its z to have unit variance: Student's t's standard deviation sqrt(dof / (dof - 2));
    below 3 dof, where that is unbounded, 3 dof's (sqrt 3) — dimensionless."""
    dof = max(int(dof), 3)
    return float(np.sqrt(dof / (dof - 2)))


def shading_shift(angle_rad: float, width_px: float, blur_px: float, background_dn: float,
                  slope_dn_per_px: float) -> np.ndarray:
    """How far [px] (x, y vector, along the mark's normal) the background's shading moves a
    groove's fitted centre: gamma M2, gamma = slope / background [1/px] the shading's relative
    slope across it, M2 = width^2 / 12 + blur^2 [px^2] its profile's second moment (a symmetric
    profile fitted to a dip the shading scales, I = L (1 - a): its brighter side weighs more;
    a Gaussian dip moves by exactly gamma sigma^2). Zeros when the level is not positive."""
    if not (background_dn > 0 and np.isfinite(slope_dn_per_px)):
        return np.zeros(2)
    m2 = width_px**2 / 12 + blur_px**2
    return m2 * slope_dn_per_px / background_dn * line_frame(angle_rad)[1]
