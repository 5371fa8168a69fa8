"""Alignment of an accelerometer triad: the residual loop, mark stage, CLI.

Public API::

    run_loop, Candidate, Term, StageFit, LoopReport   (align.loop: the shared residual loop)
    measure_file, measure_image, MarkResult           (scribe marks through the loop)
"""

from align.loop import Candidate, LoopReport, StageFit, Term, run_loop
from align.marks import MarkResult, MarkStage, loop_mark, measure_file, measure_image

__all__ = [
    "Candidate", "LoopReport", "MarkResult", "MarkStage", "StageFit", "Term", "loop_mark",
    "measure_file", "measure_image", "run_loop",
]
