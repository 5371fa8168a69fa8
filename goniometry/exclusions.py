"""What a pass over a counter log excluded or repaired, and why: one reason string per kind
of fault (the keys of ``LogSummary.exclusions``, read by the warnings and the report), and the
record of each with its line numbers (the first ``LINES_KEPT``).

A revolution off the face pattern by more than ``SCREEN_SIGMA`` is excluded; whether it counts
as a fault or as the noise's own tail in a log this long is :func:`noise_reach`'s decision.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

SCREEN_SIGMA = 5.0
LINES_KEPT = 1000

R_SPURIOUS = "spurious pulse (fits no face of the pattern): dropped, its intervals merged"
R_AMBIGUOUS = ("double trigger: two pulses within the match tolerance of one face (which is "
               "the face cannot be known): revolution excluded")
R_MISSING = "missing autocollimator pulse: revolution excluded"
R_REF_FAILED = "reference signal failed (face 0 found by the count pattern): repaired"
R_REF_WRONG = "reference mark on a pulse that is not face 0: mark ignored"
R_LOST = ("a row is missing from the log (counter did not alternate, the counts do not fit): "
          "revolution excluded")
R_LABEL = ("counter id did not alternate but no row is missing (the counts fit the face "
           "pattern): mislabelled, revolution kept")
R_REANCHOR = "face pattern lost: restarted at the next reference mark"
R_SCREEN = "face angles off the pattern by more than 5 sigma: revolution excluded"
R_TAIL = ("face angles off the pattern by more than 5 sigma, but no further than the noise "
          "reaches somewhere in a log this long: revolution excluded, not counted as a fault")

# Which screened revolutions are faults. A log of R revolutions of n faces has n R deviations
# from the pattern; Gaussian noise alone puts one in 1.7e6 beyond 5 sigma, so a long clean log
# has some (2 of 12 clean 60 000-revolution logs were once warned of "pulse faults"). A
# revolution excluded by the screen counts as a fault only beyond the deviation the noise
# exceeds with probability TAIL_ALPHA anywhere in the log (look-elsewhere); 1e-4 rather than
# 1e-3 because the tails measured on jittered logs run ~7x above Gaussian at 5 sigma.
TAIL_ALPHA = 1e-4
# Screened revolutions remembered with their deviation (beyond that, all count as faults).
SCREENED_KEPT = 10000


def noise_reach(samples: int) -> float:
    """The deviation [sigma] that Gaussian noise exceeds with probability ``TAIL_ALPHA``
    somewhere among ``samples`` deviations (never below the screen's 5 sigma)."""
    from statistics import NormalDist

    if samples <= 0:
        return SCREEN_SIGMA
    return max(SCREEN_SIGMA, -NormalDist().inv_cdf(TAIL_ALPHA / (2 * samples)))


R_DROPOUT = ("communication drop-out: rows missing from the log (the time of a row spans more "
             "than its counts' face interval, or the sequence of faces jumps): the revolutions "
             "it spans excluded, not stitched")
R_NOPATTERN = "no clean revolution nearby to predict the face pattern: stretch excluded"


CODES = {
    R_SPURIOUS: "spurious_pulse", R_AMBIGUOUS: "double_trigger", R_MISSING: "missing_pulse",
    R_REF_FAILED: "reference_failed", R_REF_WRONG: "reference_misplaced",
    R_LOST: "row_missing", R_LABEL: "counter_mislabelled", R_REANCHOR: "pattern_lost",
    R_SCREEN: "off_pattern", R_TAIL: "noise_tail", R_DROPOUT: "dropout",
    R_NOPATTERN: "no_pattern",
}
"""Reason (the sentence a reader sees) -> its stable machine code (the JSON's ``code``: a
program tests the code, never the sentence, whose wording may change)."""


def code_of(reason: str) -> str:
    """The machine code of an exclusion's reason (:data:`CODES`).

    Parameters
    ----------
    reason : str
        One of the ``R_*`` sentences.

    Returns
    -------
    str
        Its code, e.g. ``"missing_pulse"``; ``"other"`` for a sentence not in the table.
    """
    return CODES.get(reason, "other")


@dataclass
class Exclusions:
    """What was excluded or repaired, by reason, with line numbers.

    Attributes
    ----------
    counts : Counter
        Reason (one of the ``R_*`` strings) -> how many times.
    lines : dict of str to list of int
        Reason -> the file lines where it happened (the first ``LINES_KEPT``).
    """

    counts: Counter = field(default_factory=Counter)
    lines: dict = field(default_factory=dict)

    def add(self, reason: str, line: int) -> None:
        self.counts[reason] += 1
        got = self.lines.setdefault(reason, [])
        if len(got) < LINES_KEPT:
            got.append(int(line))
