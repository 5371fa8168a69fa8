"""The slow path of the pass: stretches of rows that are not clean revolutions.

A stretch (rows between two reference marks that fail the fast path's checks) is walked
pulse by pulse from its face-0 anchor by :func:`goniometry.faults.walk`, with the face
intervals predicted from the neighbouring clean revolutions; a drop-out cuts it (the
revolution it breaks is excluded). The head (rows before the first reference mark: the log
may be armed on any face) is walked backwards from that mark, the tail (rows after the last)
forwards. Every decision is listed with its line in the pass's exclusions.
"""

from __future__ import annotations

import numpy as np

from goniometry.dropouts import phase_break
from goniometry.exclusions import (
    R_AMBIGUOUS,
    R_DROPOUT,
    R_LABEL,
    R_LOST,
    R_MISSING,
    R_NOPATTERN,
    R_REANCHOR,
    R_REF_FAILED,
    R_REF_WRONG,
    R_SCREEN,
    R_SPURIOUS,
    SCREENED_KEPT,
    Exclusions,
)
from goniometry.faults import SPURIOUS, revolutions_of, walk
from goniometry.pattern import FacePattern


class Walker(FacePattern):
    """The walks of the pass's faulty stretches, head and tail (a base of
    :class:`goniometry.revolutions._Pass`, which sets the attributes)."""

    exc: Exclusions
    excluded: int
    screened: list[tuple[int, float]]
    neigh: np.ndarray
    head: int
    tail: int
    armed: int | None

    def _inc(self, nb: np.ndarray) -> np.ndarray | None:
        """Predicted face-to-face counts: the mean of the neighbouring clean revolutions."""
        if len(nb) < 4:
            nb = np.concatenate([nb, self.neigh])
        if not len(nb):
            return None
        return np.asarray(nb, float).mean(0)

    def _stretch(self, cur: dict, X: np.ndarray, brk: np.ndarray, anchor: int, end: int,
                 nb: np.ndarray, line0: int, tail: bool = False) -> list:
        """Rows anchor+1 .. end, walked forward from the face-0 pulse of row ``anchor``.

        A drop-out (a row whose time spans lost rows, see ``dropouts``) cuts the stretch:
        the revolutions before it are walked, the rows from it to the next reference mark
        (the revolution it broke) are excluded and listed, and the walk starts again there.
        Stitched, the revolution's counts would fit the pattern (whole revolutions lost) but
        its time would carry the gap into the Earth-rate sensitivity.
        """
        gap = cur.get("gap")
        cut = (np.flatnonzero(gap[anchor + 1:end + 1]) + anchor + 1 if gap is not None
               else np.zeros(0, int))
        if cut.size:
            g = int(cut[0])
            out = []
            if g - 1 > anchor:
                out += self._stretch(cur, X, brk, anchor, g - 1, nb, line0, tail)
            elif tail:
                self.tail = 0
            self.exc.add(R_DROPOUT, line0 + g)
            self.excluded += 1
            later = np.flatnonzero(cur["ref"][g:end + 1]) + g
            if later.size and int(later[0]) < end:
                return out + self._stretch(cur, X, brk, int(later[0]), end, nb, line0, tail)
            if tail:
                self.tail += end - g + 1
            return out
        rows = np.arange(anchor + 1, end + 1)
        inc = self._inc(nb)
        if inc is None:
            self.exc.add(R_NOPATTERN, line0 + int(rows[0]))
            self.excluded += max(1, round(len(rows) / self.n))
            return []
        if gap is not None and cur["dt"] is None:
            g = phase_break(np.asarray(cur["count"][anchor + 1:end + 1], float), inc,
                            self.tol, not tail)
            if g is not None:
                gap[anchor + 1 + g] = True  # (cur is this chunk's: the mark stays with it)
                return self._stretch(cur, X, brk, anchor, end, nb, line0, tail)
        w = walk(X[rows] - X[anchor], cur["ref"][rows] > 0, brk[rows], inc, self.tol)
        good, bad = revolutions_of(w, self.n)
        pulse_rows = np.append(rows, anchor)  # index -1 -> the anchor row
        out = self._report(w, good, bad, rows, cur, brk, line0, tail)
        for _, pulses in good:
            r = pulse_rows[pulses]
            out.append(self._revolution(cur, X, r, line0))
        if tail:
            done = max((p[-1] for _, p in good), default=-1)
            self.tail = len(rows) - (done + 1)
        return [u for u in out if u is not None]

    def _head(self, cur: dict, X: np.ndarray, brk: np.ndarray, a0: int, nb: np.ndarray,
              line0: int) -> list:
        """Rows 0..a0 (before the first reference mark), walked backwards from it: the log
        may be armed on any face; the arming pulse (row -1, position 0) closes the head."""
        inc = self._inc(nb)
        if inc is None:
            self.head = a0 + 1
            self.armed = None
            return []
        Xe = np.concatenate([[0], X])  # Xe[r + 1]: position of the pulse ending row r
        gap = cur.get("gap")
        if gap is not None and cur["dt"] is None and a0 > 0:
            # Backwards from the anchor: the first row off the faces' sequence is the one
            # before the gap.
            i = phase_break(np.asarray(cur["count"][a0::-1], float), inc[::-1].copy(),
                            self.tol, False)
            if i is not None:
                gap[a0 - i + 1] = True
        cut = np.flatnonzero(gap[:a0 + 1]) if gap is not None else np.zeros(0, int)
        if cut.size:
            # A drop-out in the head: the pulses before its row are at unknown positions
            # (the lost rows took their counts); walk back to the drop-out's row only.
            g = int(cut[-1])
            self.exc.add(R_DROPOUT, line0 + g)
            rows = np.arange(a0 - 1, g - 1, -1)
            if not rows.size:
                self.head, self.armed = a0 + 1, None
                return []
            isref = cur["ref"][rows] > 0
            bk = brk[rows + 1]
        else:
            rows = np.arange(a0 - 1, -2, -1)  # pulses before the anchor, the arming one last
            isref = np.append(cur["ref"][rows[:-1]] > 0, False)
            # Going backwards, the counter break between rows r and r+1 belongs to pulse r.
            bk = np.append(brk[rows[:-1] + 1], False)
        x = Xe[a0 + 1] - Xe[rows + 1]
        w = walk(x, isref, bk, inc[::-1].copy(), self.tol)
        good, bad = revolutions_of(w, self.n)
        arm = w.face[-1]
        self.armed = int((-arm) % self.n) if arm > 0 and not cut.size else None
        out = self._report(w, good, bad, rows, cur, brk, line0, tail=True, backward=True,
                           armed=not cut.size)
        pulse_rows = np.append(rows, a0)
        for _, pulses in good:
            r = pulse_rows[pulses][::-1]
            out.append(self._revolution(cur, X, r, line0))
        # Rows up to the earliest face pulse of a complete revolution are not used.
        q = max((p[-1] for _, p in good), default=None)
        self.head = a0 + 1 if q is None else int(pulse_rows[q]) + 1
        return [u for u in out if u is not None]

    def _revolution(self, cur: dict, X: np.ndarray, r: np.ndarray, line0: int):
        """One revolution from the rows of its n+1 face pulses (row -1: the arming pulse),
        screened against the pattern."""
        Xe = np.concatenate([[0], X])
        c = np.diff(Xe[r + 1]).astype(float)[None]
        if not self._screen(c)[0]:
            self.exc.add(R_SCREEN, line0 + int(r[-1]))
            self.excluded += 1
            if len(self.screened) < SCREENED_KEPT:
                dev = np.abs(c[0] - self.pattern * c.sum()).max()
                self.screened.append((line0 + int(r[-1]),
                                      float(dev / (self.sigma or np.sqrt(1 / 6)))))
            return None
        d = te = None
        if cur["t"] is not None:
            te_all = np.concatenate([[np.nan], cur["t"]])
            tr = te_all[r + 1]
            d = np.diff(tr)[None]
            te = tr[-1:]
        return (int(r[-1]), c, d, te, np.array([[int(r[0]), int(r[-1])]]))

    def _report(self, w, good, bad, rows, cur, brk, line0, tail, backward=False,
                armed=True) -> list:
        """List every fault of a walk with its line (row -1: the arming pulse, line0 - 1)."""
        n = self.n
        line = (lambda i: line0 + int(rows[i])) if not backward else (
            lambda i: line0 + max(int(rows[i]), 0))
        in_good = set()
        for _, pulses in good:
            in_good.update(p for p in pulses if p >= 0)
        for i, f in enumerate(w.face):
            r = int(rows[i])
            isref = r >= 0 and cur["ref"][r] > 0
            if f == SPURIOUS and backward and armed and i == len(rows) - 1:
                # The arming pulse fits no face: the log was armed between faces (the lead-in
                # to the first face is not a revolution, and not a fault: incomplete_head).
                continue
            if f == SPURIOUS:
                self.exc.add(R_SPURIOUS, line(i))
                if isref:
                    self.exc.add(R_REF_WRONG, line(i))
            elif (f > 0 and f % n == 0 and not isref
                  and not (backward and armed and i == len(rows) - 1)):
                self.exc.add(R_REF_FAILED, line(i))
            elif f > 0 and f % n and isref:
                self.exc.add(R_REF_WRONG, line(i))
        for _, idx in w.ambiguous:
            self.exc.add(R_AMBIGUOUS, line(idx[-1]))
        for _, i in w.missing:
            self.exc.add(R_MISSING, line(i))
        for i in w.reanchored:
            self.exc.add(R_REANCHOR, line(i))
        # Counter breaks: a mislabelled row when its revolution is complete, else a lost row.
        # (break b: rows b - 1 and b carry the same counter; a walked row r owns break r, or
        # walking backward r + 1)
        label: dict[int, int] = {}
        for i in range(len(rows)):
            r = int(rows[i])
            if r < 0:
                continue
            if (brk[r] if not backward else (r + 1 < len(brk) and brk[r + 1])):
                if i in in_good:
                    label[r + backward] = i
                else:
                    self.exc.add(R_LOST, line(i))
        # One flipped label makes three equal labels in a row: breaks b and b + 1, and only
        # row b is wrong (nothing was lost: its revolution is complete). In a run of breaks
        # the 1st, 3rd, ... are flipped rows, each next one their consequence.
        flipped: list[int] = []
        for b in sorted(label):
            if not (flipped and flipped[-1] == b - 1):
                flipped.append(b)
        for b in flipped:
            # row b itself: walked forward as the owner of break b, backward of b + 1
            self.exc.add(R_LABEL, line(label[b + 1] if backward and b + 1 in label
                                       else label[b]))
        if not tail:
            self.excluded += len(bad)
        else:
            self.excluded += sum(1 for _, why in bad if why)
        return []

