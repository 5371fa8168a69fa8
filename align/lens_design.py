"""The lens solver's building blocks: the plausible ranges of a lens (Type B), one mark as
the solver sees it, and each mark's design (how every lens parameter bows it and turns its
angle), cached per lens vector. See :mod:`align.lens` for how they are used."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_triangular

from align.lens_search import SearchPoint, StackedLines
from axisbase.errors import InputError, NotApplicable
from imaging import fit_line_only, line_frame
from imaging.lens import PARAMS, undistortion_jacobian


class LensFolds(NotApplicable):
    """The lens (as estimated or probed) folds the image along a mark: no undistortion exists
    there. Caught where a lens estimate is tried; never a ``ValueError`` (a defect raising
    one is not mistaken for a folding lens)."""

PP_STABILITY_PX = 0.5
"""The default :attr:`LensRanges.pp_stability_px` [px] (docs/camera.md, "A camera bumped after
calibration": a fixed lens in use, not knocked; the figures behind it there)."""


@dataclass(frozen=True)
class LensRanges:
    """Plausible range of each lens parameter (Type B, uniform over +- the value).

    Attributes
    ----------
    k1, k2 : float
        Radial distortion at the image half-diagonal (OpenCV's k1 = k1 (f/R)^2) —
        dimensionless.
    p : float
        Tangential distortion at the half-diagonal (p = p f/R) — dimensionless.
    aspect : float
        |fy/fx - 1| — dimensionless.
    pp_px : float
        Principal point from the image centre [px], per axis. The default 40 covers the
        project's own real camera (opencv-chessboard, left: 20.8 px in x from plain OpenCV)
        and a decentring as large again: 20 left that camera at its edge and a user's
        (+16 px) beyond it, with the angles' u not covering their error (z to 3.98).
    max_u_arcsec : float
        An angle whose lens-limited u exceeds this [″] is not ok ("calibrate the camera").
    pp_stability_px : float
        With a camera model only: how far its principal point may have moved since the
        calibration [px], per axis (uniform over +- the value; the lens knocked or
        re-seated on the sensor). Carried as the Type B term ``camera_pp_stability``
        (:mod:`align.lens_bump`, docs/camera.md "A camera bumped after calibration").
    pp_stability_declared : bool
        (unit —) Whether the user stated ``pp_stability_px`` (``--lens pp_stability_px=``,
        ``[cameras.X] lens_pp_stability_px``; 0 included: "the camera was not knocked")
        rather than left the default, which has no measured basis. A declared stability
        decides a principal point's move against bent marks where one frame cannot
        (:func:`align.lens_bump.move_or_bent`); the default does not. Set from the keys
        given (:meth:`of`), never from the value.
    """

    k1: float = 0.3
    k2: float = 0.05
    p: float = 1e-3
    aspect: float = 0.005
    pp_px: float = 40.0
    max_u_arcsec: float = 60.0
    pp_stability_px: float = PP_STABILITY_PX
    pp_stability_declared: bool = False

    @classmethod
    def of(cls, vals: Mapping[str, float]) -> LensRanges:
        """The ranges from the :data:`RANGE_KEYS` the user gave (the rest their defaults),
        the principal point's stability marked declared where it is among them."""
        return cls(**vals, pp_stability_declared="pp_stability_px" in vals)

    @classmethod
    def none(cls, max_u_arcsec: float = 60.0) -> LensRanges:
        """A camera declared free of distortion (a telecentric or already-corrected optic):
        nothing fitted, nothing carried."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, max_u_arcsec)

    def vector(self) -> np.ndarray:
        return np.array([self.k1, self.k2, self.p, self.p, self.aspect, self.pp_px,
                         self.pp_px])

    def to_dict(self) -> dict:
        return {"k1": self.k1, "k2": self.k2, "p": self.p, "aspect": self.aspect,
                "pp_px": self.pp_px, "max_u_arcsec": self.max_u_arcsec,
                "pp_stability_px": self.pp_stability_px,
                "pp_stability_declared": self.pp_stability_declared}

    @classmethod
    def from_dict(cls, d: Mapping) -> LensRanges:
        return cls(**{k: float(v) for k, v in d.items() if k in RANGE_KEYS},
                   pp_stability_declared=bool(d.get("pp_stability_declared", False)))

    @classmethod
    def parse(cls, text: str, where: str = "--lens", beside: str = "") -> LensRanges:
        """``k1=0.1,p=0,aspect=0.001,pp_px=5,max_u_arcsec=30`` (keys not given keep their
        defaults); one line naming the flag and the bad item on error. ``beside`` names a
        camera model given too (``--camera``): then only ``max_u_arcsec`` and
        ``pp_stability_px`` may be given (the model is the lens; any other range would be
        silently ignored)."""
        vals: dict[str, float] = {}
        for item in filter(None, (x.strip() for x in text.split(","))):
            key, eq, val = item.partition("=")
            key = key.strip()
            if not eq or key not in RANGE_KEYS:
                raise InputError(f"{where}: {item!r}: expected KEY=VALUE with KEY one of "
                                 f"{', '.join(RANGE_KEYS)}")
            try:
                v = float(val)
            except ValueError:
                raise InputError(f"{where}: {item!r}: {val.strip()!r} is not a number") from None
            if not np.isfinite(v) or v < 0 or (key == "max_u_arcsec" and v == 0):
                raise InputError(f"{where}: {item!r}: expected a finite number >= 0"
                                 + (" (> 0 for max_u_arcsec)" if key == "max_u_arcsec" else ""))
            vals[key] = v
        ignored = replaced_by_model(vals) if beside else []
        if ignored:
            raise InputError(f"{where} {','.join(ignored)} with {beside}: the camera model is "
                             f"the lens (its u is carried); {where} ranges are for a camera "
                             "without one (only max_u_arcsec and pp_stability_px apply beside it)")
        return cls.of(vals)


def replaced_by_model(keys: Iterable[str]) -> list[str]:
    """Which of ``keys`` (LensRanges field names) a camera model makes meaningless: a model
    *is* the lens, so ranges of k1, k2, p, aspect, principal point given beside it would be
    silently ignored (``max_u_arcsec`` still applies: the bound on a lens-limited u)."""
    return [k for k in keys if k in RANGE_KEYS and k not in BESIDE_MODEL]


RANGE_KEYS = ("k1", "k2", "p", "aspect", "pp_px", "max_u_arcsec", "pp_stability_px")
"""The :class:`LensRanges` keys a user gives (``--lens KEY=…``, ``[cameras.X] lens_KEY``);
``pp_stability_declared`` is not one: it records which of them were given."""

BESIDE_MODEL = ("max_u_arcsec", "pp_stability_px")
"""The :class:`LensRanges` keys that apply beside a camera model."""


DEFAULT_RANGES = LensRanges()
"""The default plausible ranges (the issue's: |k1| <= 0.3 at the half-diagonal, ...)."""


@dataclass(frozen=True)
class LineGeometry:
    """One mark as the lens solver sees it: raw centres relative to the image centre [px],
    their sigma across the line [px] and correlation factor (None: independent)."""

    points: np.ndarray
    sigma: np.ndarray
    chol: np.ndarray | None = None


@dataclass(frozen=True)
class _Design:
    angle: float
    s: np.ndarray            # d angle / d lam [rad per unit], per parameter
    G: np.ndarray            # whitened bow columns (straight-line part projected out)
    z: np.ndarray            # whitened residual of the straight-line fit
    w: np.ndarray            # whitened bow (quadratic along the mark), projected, unit norm
    s_pp_var: np.ndarray | None = None  # var of s over the principal point's range [rad^2]
    q: np.ndarray | None = field(default=None, repr=False, compare=False)  # undistorted [px]
    dq: np.ndarray | None = field(default=None, repr=False, compare=False)  # dq/dlam (N,2,P)
    offset: float = field(default=np.nan, repr=False, compare=False)  # the line's, with angle

    @property
    def bow_z(self) -> float:
        """The residual's bow in units of its standard uncertainty (N(0, 1) when straight)."""
        return float(self.w @ self.z)


def _whiten(line: LineGeometry, X: np.ndarray) -> np.ndarray:
    """Columns ``X`` (one row per centre) whitened by the centres' noise."""
    X = X / line.sigma[:, None]
    return X if line.chol is None else solve_triangular(line.chol, X, lower=True,
                                                          check_finite=False)


def _fit_columns(line: LineGeometry, q: np.ndarray, jac: np.ndarray
                 ) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The straight line through the undistorted centres ``q`` [px] and, whitened by the
    centres' noise, its columns (slope, offset), the perpendicular displacement ``jac``
    (dq/dlam, (N, 2, P)) makes, the bow's and the residual: (angle, offset, Jw, Ew, bw,
    rw)."""
    angle, offset = fit_line_only(q, line.sigma, chol=line.chol)
    u, n = line_frame(angle)
    E = jac[:, 0, :] * n[0] + jac[:, 1, :] * n[1]  # perpendicular displacement per unit
    J = np.column_stack([q @ u, -np.ones(len(q))])
    r = q @ n - offset
    t = q @ u
    bow = ((t - (t.min() + t.max()) / 2) / max(np.ptp(t), 1.0)) ** 2
    X = _whiten(line, np.column_stack([J, E, bow, r]))
    return angle, offset, X[:, :2], X[:, 2:-2], X[:, -2], X[:, -1]


def _design(line: LineGeometry, lam: np.ndarray, scale: float,
            only: Sequence[int] | None = None) -> _Design:
    q, jac = undistortion_jacobian(line.points, lam, scale, only)
    if not np.all(np.isfinite(q)) or not np.all(np.isfinite(jac)):
        raise LensFolds("the lens folds the image along this mark")
    angle, offset, Jw, Ew, bw, rw = _fit_columns(line, q, jac)
    coef = np.linalg.lstsq(Jw, np.column_stack([Ew, bw]), rcond=None)[0]
    G = Ew - Jw @ coef[:, :-1]
    w = bw - Jw @ coef[:, -1]
    # Moving the points by E dlam moves the fitted angle by -(J^T J)^-1 J^T E dlam (row 0).
    return _Design(angle, -coef[0, :-1], G, rw, w / max(np.linalg.norm(w), 1e-300), q=q,
                   dq=jac, offset=offset)


class _DesignCache:
    """Each line's design per lens vector, computed once: the solver revisits the same
    vectors (zero before and in the first step, the converged lens after the loop, the
    principal point's probes in :func:`_pp_spread` and :func:`_pp_probe_s`)."""

    def __init__(self, lines: Sequence[LineGeometry], scale: float) -> None:
        self.lines, self.scale = lines, scale
        self._memo: dict[tuple, _Design] = {}
        self._index = list(range(len(lines)))
        self._stack: StackedLines | None = None
        self._point: tuple[bytes, SearchPoint] | None = None

    def without(self, k: int) -> _DesignCache:
        """The cache of the lines but line ``k``, sharing this one's designs (keyed by the
        line's index here): the leave-one-out solves revisit the lens vectors of the
        others (zero, and the principal point's probes about it)."""
        sub = _DesignCache([ln for i, ln in enumerate(self.lines) if i != k], self.scale)
        sub._memo = self._memo
        sub._index = [j for i, j in enumerate(self._index) if i != k]
        return sub

    def search(self, lam: np.ndarray) -> SearchPoint:
        """All the lines at ``lam`` for a search over lens vectors
        (:func:`align.lens_exact.plausible_exact`: their bows and the bows' slopes, all the
        lines at once, :mod:`align.lens_search`; the same bows as the designs' to rounding,
        kept apart from the designs the angles read). The last one is kept: a search reads
        its bows and then, at the same vector, their slopes. :class:`LensFolds` where the
        lens folds any line."""
        key = lam.tobytes()
        if self._point is not None and self._point[0] == key:
            return self._point[1]
        if self._stack is None:
            self._stack = StackedLines(self.lines, self.scale)
        point = self._stack.at(lam)
        if point is None:
            raise LensFolds("the lens folds the image along a mark")
        self._point = (key, point)
        return point

    def one(self, k: int, lam: np.ndarray, only: tuple[int, ...] | None = None) -> _Design:
        """Line ``k``'s design at ``lam`` (:class:`LensFolds` where the lens folds it)."""
        key = (self._index[k], lam.tobytes(), only)
        d = self._memo.get(key)
        if d is None:
            d = self._memo[key] = _design(self.lines[k], lam, self.scale, only)
        return d

    def cached(self, k: int, lam: np.ndarray) -> _Design | None:
        """Line ``k``'s full design at ``lam`` if already computed."""
        return self._memo.get((self._index[k], lam.tobytes(), None))

    def all(self, lam: np.ndarray) -> list[_Design]:
        """Every line's design at ``lam`` (:class:`LensFolds` where the lens folds any)."""
        return [self.one(k, lam) for k in range(len(self.lines))]

    def bow_jacobian(self, lam: np.ndarray, cols: Sequence[int]) -> np.ndarray:
        """d bow_z / d lam[cols] of every line at ``lam`` [per unit], shape (lines, cols):
        each line's centres moved by their first-order displacement (exact to first order:
        along the mark too, which bends the bow's own column; ``G`` alone misses it, 15 % of
        a bowed line's slope) and the line stepped there, a forward difference of 1e-4 px
        (:meth:`align.lens_search.SearchPoint.bow_jacobian`, on :meth:`search`'s lines).
        :class:`LensFolds` where the lens folds any line."""
        return self.search(lam).bow_jacobian(cols)


def gauss_newton(cache: _DesignCache, applied: list[int], rng: np.ndarray, iters: int,
                 start: np.ndarray | None = None, search: bool = False) -> np.ndarray:
    """The lens vector fitting the parameters ``applied`` to the lines' bows (Gauss-Newton
    from ``start``, zero by default, the other entries held there; stopped, and left for the
    caller to refuse, running away beyond any range or where no step improves the fit).
    ``search``: the lines read all at once (:meth:`_DesignCache.search`, the same sums to
    rounding) for a fit that only decides (a sign), not the lens the angles are read under."""
    lam = np.zeros(len(PARAMS)) if start is None else start.copy()
    if not applied:
        return lam
    A = np.ix_(applied, applied)

    def cost_at(x: np.ndarray) -> float:
        if search:
            return cache.search(x).normal[2]
        return sum(float(d.z @ d.z) for d in cache.all(x))

    try:
        cost = cost_at(lam)
    except LensFolds:
        return lam
    for _ in range(iters):
        if search:
            F, b, _ = cache.search(lam).normal
        else:
            designs = cache.all(lam)  # (cached: the vector's cost read them)
            F = sum(d.G.T @ d.G for d in designs)
            b = sum(d.G.T @ d.z for d in designs)
        step = -np.linalg.solve(F[A], b[applied])
        # The step linearised at zero overshoots a strong lens's higher terms (k2 -0.16
        # for -0.04 after a k1 -0.17): halved until the lines fit better (and the lens
        # does not fold), so that a lens is judged beyond its range only where the fit
        # itself ends up there.
        for _ in range(8):
            trial = lam.copy()
            trial[applied] += step
            try:
                t_cost = cost_at(trial)
            except LensFolds:
                step = step / 2
                continue
            if t_cost <= cost:
                break
            step = step / 2
        else:
            break  # no step improves: stay
        lam, cost = trial, t_cost
        if np.any(np.abs(lam[applied]) > 10 * rng[applied]):
            break  # running away, beyond any lens: refused by the caller
        if np.all(np.abs(step) < 1e-3 * rng[applied]):
            break
    return lam
