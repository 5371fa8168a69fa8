"""Pulse faults decided by the face pattern: which pulse is which face, from the ring-laser counts.

The ring laser counts table angle, whatever the table's speed: the position of a pulse (the
cumulative count from an anchor pulse) is the angle at which it fired, to +-1 count (the
floor of a continuous phase at each end) plus the autocollimator's jitter. So the faces sit
at predicted positions (the mean face-to-face counts of neighbouring clean revolutions, added
up from the last pulse that matched a face), and each pulse of an abnormal stretch is

* a face pulse when exactly one pulse lies within ``tol`` counts of a predicted face;
* ambiguous when two or more do (a double trigger closer than ``tol``: which one is the face
  cannot be known — the revolution is excluded);
* spurious otherwise (a glint, a double trigger farther than ``tol``): dropped, its count
  joins the interval it split — counts add exactly, so that repair is exact.

A face with no pulse is missing (its revolution is excluded). Times cannot help decide between
two pulses: a pulse's time and its count are two readings of the same instant, and the count
is the finer one (a count is ~1e-6 of a revolution; the time fraction of a revolution wanders
with the table's speed by ~1e-4). A reference mark tells which face is face 0; a mark on
another pulse, or none on a face-0 pulse, is a fault of the binding signal and is listed. When
the pattern is lost (a row lost from the log shifts every later position by one interval) the
walk re-anchors at the next reference mark.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SPURIOUS = -1
AMBIGUOUS = -2


@dataclass
class Walk:
    """The outcome of matching pulses to faces: ``face[i]``: the face number (1, 2, ...;
    face j is face j mod n of the pattern, face 0 the anchor) of pulse i, or SPURIOUS /
    AMBIGUOUS; ``missing``: (face number, index of the first pulse after it);
    ``reanchored``: pulse indices where the walk restarted at a reference mark;
    ``ambiguous``: (face number, pulse indices)."""

    face: np.ndarray
    missing: list = field(default_factory=list)
    ambiguous: list = field(default_factory=list)
    reanchored: list = field(default_factory=list)
    last_face: int = 0


def walk(x: np.ndarray, is_ref: np.ndarray, brk: np.ndarray, inc: np.ndarray,
         tol: float) -> Walk:
    """Match pulses at positions ``x`` [counts from the anchor, increasing] to faces.

    Parameters
    ----------
    x : positions of the pulses after the anchor (face 0 at 0) [counts].
    is_ref : reference marks of those pulses (used to re-anchor when the pattern is lost).
    brk : the counter id did not alternate at that pulse (a row may be lost before it).
    inc : predicted face-to-face counts, face k -> k+1 for k = 0..n-1 [counts].
    tol : match tolerance [counts].
    """
    n = len(inc)
    cum = np.concatenate([[0.0], np.cumsum(inc)])
    full = cum[-1]

    def S(j: int) -> float:
        return (j // n) * full + cum[j % n]

    L = len(x)
    face = np.full(L, SPURIOUS, dtype=np.int64)
    out = Walk(face)
    base_x, base_j = 0.0, 0
    j = 1
    lost = False  # a face was passed without its pulse, or a counter break, since the last match
    i = 0
    while i < L:
        xi = float(x[i])
        lost |= bool(brk[i])
        while base_x + S(j) - S(base_j) + tol < xi:
            out.missing.append((j, i))
            lost = True
            j += 1
        p = base_x + S(j) - S(base_j)
        if abs(xi - p) <= tol and not (is_ref[i] and lost and j % n):
            k = i + 1
            while k < L and abs(float(x[k]) - p) <= tol:
                k += 1
            if k - i > 1:
                face[i:k] = AMBIGUOUS
                out.ambiguous.append((j, list(range(i, k))))
                j += 1
                i = k
                continue
            face[i] = j
            base_x, base_j, j = xi, j, j + 1
            lost = False
        elif is_ref[i] and lost:
            # The pattern is lost (e.g. a row lost from the log shifted the positions): trust
            # the reference mark and start again from it as face 0 of a new revolution.
            j0 = -(-j // n) * n
            for m in range(j, j0):
                out.missing.append((m, i))
            face[i] = j0
            out.reanchored.append(i)
            base_x, base_j, j = xi, j0, j0 + 1
            lost = False
        i += 1
    out.last_face = base_j
    return out


def revolutions_of(w: Walk, n: int) -> tuple[list, list]:
    """Complete revolutions of a walk: a list of (r, pulse indices of faces r n .. (r+1) n,
    with -1 for the anchor) and the incomplete ones as (r, reason)."""
    pulse_of = {0: -1}
    for i, f in enumerate(w.face):
        if f > 0:
            pulse_of[int(f)] = i
    bad_faces = {m for m, _ in w.missing} | {m for m, _ in w.ambiguous}
    top = max(pulse_of)
    good, bad = [], []
    for r in range(top // n + 1):
        faces = range(r * n, (r + 1) * n + 1)
        if (r + 1) * n > top:
            break
        if all(f in pulse_of for f in faces):
            good.append((r, [pulse_of[f] for f in faces]))
        else:
            why = [f for f in faces if f in bad_faces or f not in pulse_of]
            bad.append((r, why))
    return good, bad
