"""The codes of a session result's ``problems`` (why a result that ran is not ok).

Each line of ``problems`` (the human text) has its code at the same index of
``problem_codes`` (session format version 5): a program tests the code, never the sentence.
Kept free of imports: the reader of session results and the decision both use it.
"""

from __future__ import annotations

CALIBRATION = "calibration_not_ok"
"""The triad calibration is not ok (effects its poses cannot tell apart, ...)."""
GONIOMETER = "goniometer_not_ok"
"""The goniometer's angles are not covered by their u."""
LENS_LIMITED = "lens_limited"
"""A mark's angle is limited by the camera's uncalibrated lens."""
DISAGREEMENT = "instruments_disagree"
"""The instruments disagree beyond their uncertainties (E's u inflated or widened)."""
ANGLE_UNDECIDED = "angle_undecided"
"""A toleranced angle's tolerance cannot be decided: a nuisance the data cannot determine sets
its u (:func:`align.decision.undecided`). It depends on the tolerance judged against: under
another tolerance the same result may have other such angles, or none."""
UNKNOWN = "unknown"
"""A problem whose code the file does not give (a result written before codes, version ≤ 4):
it makes the result not ok whatever the tolerance."""

CODES = (CALIBRATION, GONIOMETER, LENS_LIMITED, DISAGREEMENT, ANGLE_UNDECIDED, UNKNOWN)
"""Every code, as ``docs/formats.md`` lists them."""
TOLERANCE_DEPENDENT = frozenset({ANGLE_UNDECIDED})
"""Codes a result carries only for the tolerance it was judged against: a re-judgement under
another tolerance drops them and finds its own (:func:`align.decision.judge_result`)."""


def codes_of(problems: object, codes: object) -> tuple[str, ...]:
    """The code of each problem line, as a file gives them: ``codes`` when it is a list of
    known codes as long as ``problems``, else :data:`UNKNOWN` for every line (an older file,
    or an edited one: never read as fewer problems than it says)."""
    n = len(problems) if isinstance(problems, list | tuple) else 0
    if (isinstance(codes, list | tuple) and len(codes) == n
            and all(isinstance(c, str) and c in CODES for c in codes)):
        return tuple(codes)
    return (UNKNOWN,) * n
