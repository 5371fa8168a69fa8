"""Whether a chessboard calibration's views are of ONE camera (issue 18: two cameras mixed).

The photographs of a stereo rig's left and right cameras in one folder calibrate as one
"camera" with a confident model: OpenCV fits the average of two principal points, and every
angle measured through it inherits the difference. The views themselves say so: each view
pulls the calibration towards its own camera.

The test (:func:`one_camera_check`):

1. **Propose a split.** The delete-one-view jackknife gives each view's pull, its
   pseudo-value n θ̂ − (n − 1) θ̂₋ᵢ of the intrinsics; the split of the views into two
   groups (each of at least :data:`MIN_GROUP`) that explains the largest share of the
   pseudo-values' scatter in (fx, cx, cy) is a proposal (:func:`best_splits`), with
   each coordinate's median split.
2. **Refine each by the views' own fit.** Each group is calibrated alone and each view
   goes to the group whose model reprojects it better (its pose re-fitted), until stable
   (a mixture's pooled fit scatters the pseudo-values twice as wide as either camera
   alone, so a proposal is often a view or two off); the split whose groups differ most
   (W below) is kept.
3. **Compare the two groups' calibrations** on (fx, cx, cy): W = dᵀ (C₀ + C₁)⁻¹ d, each C
   the group's own covariance — the larger of formal and jackknife, so the views' real
   disagreement (corner errors correlated within a view: the jackknife 2× the formal u on
   one camera) is in it and does not fire the test, where the formal u alone would. W of
   a fixed split is χ²(3); the split was searched for, so its p is multiplied by the
   number of splits (Bonferroni: conservative, never liberal).

By hand: no library tests a set of calibration views for two cameras.

What it cannot see (docs/camera.md, "what the views can tell"): the real photographs' views
scatter φ ≈ 5 times (in variance) what white corner noise explains, so a test that takes
the reprojection residuals' noise for the views' (the likelihood ratio or F-test of one
camera against two) would fire on one real camera; and at that φ even the best possible
test, one that knows the split and the direction of the difference, detects principal
points 10 px apart from 7 + 7 views in about half the sets (90 % needs 14.5 px; the
separation it needs scales as √(φ / views)). Focal lengths 1 % apart stay below 90 % even
with white noise.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
from scipy import special  # (not scipy.stats: slow to import)

from imaging.camera_cov import INTRINSICS, dominating

COLUMNS = tuple(INTRINSICS.index(k) for k in ("fx", "cx", "cy"))
"""The intrinsics tested (fx, cx, cy): where two cameras of one rig differ (focal length,
principal point); fy moves with fx (one board scale) and would add only its noise."""

MIN_GROUP = 3
"""Fewest views in a group: a single odd view (a board badly found) is no second camera."""

JACK_FULL = 5
"""Fewest views whose jackknife covariance of (fx, cx, cy) is taken as it is (rank 4 > 3)."""

MIN_VIEWS = 2 * MIN_GROUP
"""Fewest views the test runs on."""

ALPHA = 0.01
"""Significance at which the views are declared not one camera (false alarms <= 1 %: the
Bonferroni bound makes them fewer)."""

EXHAUSTIVE_MAX = 14
"""Up to this many views every split is proposed from; beyond, a local search (the
proposal only: the p-value's Bonferroni counts every split either way)."""


def _whitened(x: np.ndarray) -> np.ndarray:
    """``x`` (n, q) centred and whitened by its total scatter (Zᵀ Z = I)."""
    xc = x - x.mean(axis=0)
    s, U = np.linalg.eigh(xc.T @ xc)
    keep = s > 1e-12 * max(s.max(), 1e-300)
    return xc @ U[:, keep] / np.sqrt(s[keep])


@lru_cache(maxsize=8)
def _splits(n: int) -> np.ndarray:
    """Every split of n views into two groups of at least :data:`MIN_GROUP` (view 0 always
    outside the indicated group, so each split once), as a 0/1 matrix (splits, n)."""
    rows = [c for c in itertools.product((0, 1), repeat=n - 1)
            if MIN_GROUP <= sum(c) <= n - MIN_GROUP]
    return np.array([(0, *c) for c in rows], dtype=float)


def _best_exhaustive(z: np.ndarray, top: int = 1) -> tuple[float, list[np.ndarray]]:
    """The largest between-group share b over every split of whitened ``z`` (n, q), and the
    ``top`` splits by b."""
    P = _splits(len(z))
    na = P.sum(axis=1)
    s = P @ z
    b = len(z) * np.einsum("ij,ij->i", s, s) / (na * (len(z) - na))
    order = np.argsort(-b)[:top]
    return float(b[order[0]]), [P[i].astype(bool) for i in order]


def _best_local(z: np.ndarray) -> tuple[float, list[np.ndarray]]:
    """The largest b found by threshold splits along a direction, the direction moved to
    the groups' difference until stable, from each axis (many views: 2ⁿ splits too many)."""
    n = len(z)
    best, group = -1.0, np.zeros(n, bool)
    for start in np.eye(z.shape[1]):
        v = start
        for _ in range(20):
            order = np.argsort(z @ v)
            cs = np.cumsum(z[order], axis=0)[MIN_GROUP - 1:n - MIN_GROUP]
            na = np.arange(MIN_GROUP, n - MIN_GROUP + 1)
            b = n * np.einsum("ij,ij->i", cs, cs) / (na * (n - na))
            k = int(np.argmax(b))
            g = np.zeros(n, bool)
            g[order[:na[k]]] = True
            if b[k] > best + 1e-12:
                best, group = float(b[k]), g
            new = z[g].mean(axis=0) - z[~g].mean(axis=0)
            if np.allclose(new / np.linalg.norm(new), v):
                break
            v = new / np.linalg.norm(new)
    return best, [group if not group[0] else ~group]


def best_splits(x: np.ndarray, top: int = 3) -> tuple[float, list[np.ndarray]]:
    """The largest share ``b`` of the rows of ``x`` (n, q)'s scatter a split into two
    groups explains (between-group / total, affine invariant), and the best splits (up to
    ``top``, every split tried up to :data:`EXHAUSTIVE_MAX` rows; beyond, the one a local
    search finds; a boolean per row, row 0 outside the group)."""
    z = _whitened(np.asarray(x, float))
    if len(z) <= EXHAUSTIVE_MAX:
        return _best_exhaustive(z, top)
    return _best_local(z)


def _proposals(x: np.ndarray) -> list[np.ndarray]:
    """Splits to start from: the best by the pooled pseudo-values' b, and each
    coordinate's median split (a mixture's pooled pseudo-values are wide: the first guess
    is often a view or two off)."""
    out = {tuple(g): g for g in best_splits(x, top=1)[1]}
    for col in x.T:
        g = col > np.median(col)
        if MIN_GROUP <= g.sum() <= len(g) - MIN_GROUP:
            g = g if not g[0] else ~g
            out.setdefault(tuple(g), g)
    return list(out.values())


def _classify(group: np.ndarray, view_rms: Callable[[np.ndarray], np.ndarray],
              rounds: int = 4) -> np.ndarray:
    """The split refined by the views' own fit: each group calibrated alone, each view put
    in the group whose model reprojects it better (its pose re-fitted), until stable."""
    for _ in range(rounds):
        rms = view_rms(group)  # (n, 2): each view's RMS [px] under group-0's, group-1's model
        new = rms[:, 1] < rms[:, 0]
        if (new == group).all() or not MIN_GROUP <= new.sum() <= len(new) - MIN_GROUP:
            break
        group = new
    return group


def group_cov(formal: np.ndarray, jack: np.ndarray, views: int) -> np.ndarray:
    """A group's covariance of (fx, cx, cy) (:data:`COLUMNS`, [px²]): at least its formal
    and its jackknife covariance in every direction (:func:`imaging.camera_cov.dominating`).
    Below :data:`JACK_FULL` views the jackknife is rank-deficient or barely more (rank ≤
    views − 1) and a direction it happens not to see would keep the formal u alone, which
    takes the real views' correlated corner errors (the jackknife 2× the formal u) for a
    second camera (the 7 real left views split 3 + 4: W 21, p 0.003): the formal
    covariance is then scaled by the largest excess the jackknife shows in any direction
    (κ ≥ 1) first."""
    sel = np.ix_(COLUMNS, COLUMNS)
    f, j = formal[sel], jack[sel]
    if views < JACK_FULL:
        Li = np.linalg.inv(np.linalg.cholesky(f))
        f = f * max(1.0, float(np.linalg.eigvalsh(Li @ j @ Li.T).max()))
    return dominating(f, j)


def untested(n: int) -> dict:
    """The record of a calibration from too few views to test (one camera assumed)."""
    return {"tested": False, "one_camera": None,
            "parameters": [INTRINSICS[i] for i in COLUMNS],
            "why": f"{n} views: the test needs {MIN_VIEWS} (two groups of {MIN_GROUP})"}


def split_count(n: int) -> int:
    """Splits of n views into two groups of at least :data:`MIN_GROUP` (the search's
    number of tests, for the Bonferroni bound)."""
    return sum(math.comb(n, k) for k in range(MIN_GROUP, n - MIN_GROUP + 1)) // 2


def one_camera_check(pseudo: np.ndarray, names: Sequence[str],
                     view_rms: Callable[[np.ndarray], np.ndarray],
                     group_fit: Callable[[np.ndarray], list],
                     alpha: float = ALPHA) -> dict:
    """Whether the views look like one camera's (the record ``align camera`` saves as
    ``views_one_camera``).

    Splits are proposed by the pooled fit's pseudo-values (:func:`best_splits`) and refined
    by each view's reprojection under each group's own calibration; the split whose two
    groups' calibrations differ most is kept. They are compared on (fx, cx, cy) by the Wald
    statistic W = dᵀ (C₀ + C₁)⁻¹ d, each C the group's own covariance (the larger of formal
    and jackknife, :func:`imaging.camera_cov.dominating`: the views' real scatter, not only the
    corners' white noise). W of one split is χ²(3); the split was searched for, so its p is
    multiplied by the number of splits (Bonferroni: conservative, never liberal).

    Parameters
    ----------
    pseudo : ndarray
        (n, 9) the views' jackknife pseudo-values of :data:`INTRINSICS` in the pooled fit
        ([px], 1).
    names : sequence of str
        The views' names, in the rows' order.
    view_rms : callable
        Boolean group (n,) -> (n, 2) each view's RMS reprojection [px] under the
        calibration of the views outside the group and of those in it (pose re-fitted).
    group_fit : callable
        Boolean group (n,) -> [(θ, F, J) outside, (θ, F, J) inside]: each group's
        intrinsics (9,), formal and jackknife covariance (9, 9) in :data:`INTRINSICS`'
        order (:func:`group_cov` combines them).
    alpha : float
        Significance.

    Returns
    -------
    dict
        ``tested`` (False below :data:`MIN_VIEWS` views, with ``why``), ``one_camera``,
        ``W`` (dimensionless), ``p`` (Bonferroni over ``splits``), ``alpha``,
        ``parameters``, ``groups`` (the two groups' view names), ``group_values`` (each
        group's fx, cx, cy [px]) and ``group_u`` (their u [px]).
    """
    n = len(names)
    params = [INTRINSICS[i] for i in COLUMNS]
    if n < MIN_VIEWS:
        return untested(n)
    tried: dict[tuple, tuple] = {}
    for start in _proposals(np.asarray(pseudo, float)[:, COLUMNS]):
        g = _classify(start, view_rms, rounds=3)
        g = g if not g[0] else ~g
        if tuple(g) in tried:
            continue
        (t0, f0, j0), (t1, f1, j1) = group_fit(g)
        c0, c1 = group_cov(f0, j0, int((~g).sum())), group_cov(f1, j1, int(g.sum()))
        d = np.asarray(t1)[list(COLUMNS)] - np.asarray(t0)[list(COLUMNS)]
        w = float(d @ np.linalg.lstsq(c0 + c1, d, rcond=None)[0])
        tried[tuple(g)] = (w, g, t0, c0, t1, c1)
    w, g, t0, c0, t1, c1 = max(tried.values(), key=lambda r: r[0])
    m = split_count(n)
    p = float(min(1.0, m * special.chdtrc(len(COLUMNS), w)))
    groups = [[str(names[i]) for i in np.flatnonzero(k)] for k in (~g, g)]
    return {"tested": True, "one_camera": bool(p >= alpha), "W": w, "p": p, "splits": m,
            "alpha": alpha, "parameters": params, "groups": groups,
            "group_values": [np.asarray(t)[list(COLUMNS)].tolist() for t in (t0, t1)],
            "group_u": [np.sqrt(np.diag(c)).tolist() for c in (c0, c1)]}


def not_one_camera_warning(check: dict) -> str | None:
    """The warning when the views are not of one camera, naming the two groups; else None."""
    if not check or check.get("one_camera") is not False:
        return None
    (a, b), (ma, mb) = check["groups"], check["group_values"]
    mean = ", ".join(f"{k} {va:.1f} vs {vb:.1f}" for k, va, vb in zip(
        check["parameters"], ma, mb, strict=True))
    return (f"NOT OK: the views are not of one camera (split test W = {check['W']:.1f}, "
            f"p = {check['p']:.2g} < {check['alpha']:g}): [{' '.join(a)}] and "
            f"[{' '.join(b)}] disagree ({mean} px); "
            "calibrate each camera from its own views")
