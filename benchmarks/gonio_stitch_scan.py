"""Can the floors' pattern show a whole-revolution drop-out in a log without times? (No.)

The scan tried for ``docs/goniometer-dropouts.md`` ("Whole revolutions lost, without times"),
kept here so its figures can be reproduced; the pipeline does not use it. After a drop-out
of K whole revolutions the counters' floors step at a phase offset by frac(K N) from the
log's phase path: at every pulse, the likelihood ratio of the floors' steps (the model of
:func:`goniometry.beat.fit_pattern`) with the pulses after it (or before it) offset by one
of 63 fractions of a count, against the look-elsewhere over every pulse and offset
(Bonferroni at 1e-3); the pattern refitted on the longer side once a place is found;
``--refine`` first moves each face's phase to the steps' own likelihood maximum. Prints, on
the logs of ``tests/goniometry/stitch_cases.py`` without times, by steady / unsteady table:
stitches found at their revolution (+-2) and "stitches" found in the drop-out-free twins.

Run: ``python3 benchmarks/gonio_stitch_scan.py [--logs 20] [--refine]``
"""

from __future__ import annotations

import argparse
from collections import Counter

import benchpage
import numpy as np
from scipy.special import chdtri, ndtr

from goniometry import beat, read_revolutions
from tests.goniometry.stitch_cases import stitched_case

OFFSETS = 64
ALPHA = 1e-3


def _loglik(d: np.ndarray, y: np.ndarray, sigma: float) -> np.ndarray:
    p_up, p_dn = ndtr((y - 1) / sigma), ndtr(-y / sigma)
    like = np.where(d == 1, p_up, np.where(d == -1, p_dn,
                                           np.where(d == 0, 1 - p_up - p_dn, 0.0)))
    return np.log(np.maximum(like, 1e-300))


def _steps(v: np.ndarray, y: np.ndarray) -> np.ndarray:
    d = np.round(v + y - np.mean(v + y))
    return d - np.median(d)


def scan(counts, theta, turn, dk, phi, sigma, refine):
    """(most likely first pulse after the gap, log-likelihood ratio, threshold)."""
    n = counts.shape[1]
    v, ph, fc, _, rev = beat._chains(counts, theta, turn)  # (a benchmark: the private helper)
    grid = np.arange(OFFSETS) / OFFSETS
    phi = np.asarray(phi, float).copy()
    if refine:
        for f in range(n):
            m = fc == f
            tot = [_loglik(_steps(v[m], (ph[m] + dk * rev[m] + phi[f] + x) % 1.0),
                           (ph[m] + dk * rev[m] + phi[f] + x) % 1.0, sigma).sum()
                   for x in grid]
            phi[f] += grid[int(np.argmax(tot))]
    y = (ph + dk * rev + phi[fc]) % 1.0
    d = np.zeros(len(y))
    for f in range(n):
        d[fc == f] = _steps(v[fc == f], y[fc == f])
    ll0 = _loglik(d, y, sigma)
    yd = y[None, :] + grid[1:, None]
    wrap = yd >= 1.0
    yd = yd - wrap
    lls = np.stack([_loglik(d[None, :] - wrap + k, yd, sigma) for k in (0, 1)], axis=1)
    P = len(y)
    after = np.zeros((OFFSETS - 1, P + 1))
    before = np.zeros((OFFSETS - 1, P + 1))
    for f in range(n):
        x = np.where((fc == f)[None, None, :], lls, 0.0)
        zero = np.zeros((*x.shape[:2], 1))
        after += np.concatenate([np.cumsum(x[..., ::-1], -1)[..., ::-1], zero], -1).max(1)
        before += np.concatenate([zero, np.cumsum(x, -1)], -1).max(1)
    pre0 = np.concatenate([[0.0], np.cumsum(ll0)])
    suf0 = pre0[-1] - pre0
    ratio = np.maximum(after + pre0, before + suf0).max(0) - pre0[-1]
    ratio[[0, P]] = -np.inf
    q = int(np.argmax(ratio))
    return q, float(ratio[q]), 0.5 * float(chdtri(1, ALPHA / (2 * P * (OFFSETS - 1))))


def find(counts, refine):
    """The stitched revolution's index, or None."""
    R, n = counts.shape
    theta, turn = beat.phase_path(counts, None, None, 0.0)
    dk, phi, sig = beat.fit_pattern(counts, theta, turn)
    sigma = max(sig[2], 1e-3)
    q, lr, thr = scan(counts, theta, turn, dk, phi, sigma, refine)
    if lr <= thr:
        return None
    a = q // n
    lo, hi = (0, a) if a >= R - a else (min(a + 1, R), R)
    if hi - lo >= 16:
        dk2, phi2, _ = beat.fit_pattern(counts[lo:hi], theta[lo:hi], turn[lo:hi])
        q2, lr2, _ = scan(counts, theta, turn, dk2, (phi2 - dk2 * turn[lo]) % 1.0, sigma,
                          refine)
        if lr2 > thr:
            q = q2
    return (q - 1) // n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=20)
    ap.add_argument("--refine", action="store_true")
    a = ap.parse_args()
    got = Counter()
    for seed in range(a.logs):
        spec, twin, cut, k, r0 = stitched_case(seed)
        table = "unsteady" if spec.ripple else "steady"
        got[table, "logs"] += 1
        for key, sim in (("stitched", cut), ("twin", twin)):
            s = read_revolutions({c: v for c, v in sim["rows"].items() if c != "t"}, 4)
            counts = s.stats.kept()[0]
            lines = np.vstack(s.stats.kept_lines)
            at = find(counts, a.refine)
            if key == "twin":
                got[table, "false"] += at is not None
            else:
                true = int(np.flatnonzero(lines[:, 1] >= r0)[0])
                got[table, "found"] += at is not None and abs(at - true) <= 2
    print("| table | logs | stitches found at their revolution | 'stitches' in the twins |")
    print("| --- | --- | --- | --- |")
    for table in ("steady", "unsteady"):
        print(f"| {table} | {got[table, 'logs']} | {got[table, 'found']} | "
              f"{got[table, 'false']} |")


if __name__ == "__main__":
    benchpage.run(main, "Goniometer: a floors-pattern scan for stitches without times")
