"""The shared residual loop: structure tests, candidate effects, selection, report."""

from align.loop.fit import Candidate, Stage, StageFit, Term
from align.loop.loop import bic, f_test, optimistic_fit, run_loop, sidak
from align.loop.report import (
    EffectReport,
    LoopReport,
    LoopSummary,
    RefusedEffect,
    SkippedCandidate,
)
from align.loop.structure import StructureReport, StructureTest, check_structure, periodogram_test

__all__ = [
    "sidak",
    "Candidate", "EffectReport", "LoopReport", "LoopSummary", "RefusedEffect",
    "SkippedCandidate", "Stage", "StageFit",
    "StructureReport", "StructureTest", "Term", "bic", "f_test", "optimistic_fit",
    "periodogram_test", "run_loop", "check_structure",
]
