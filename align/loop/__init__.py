"""The shared residual loop: structure tests, candidate effects, selection, report."""

from align.loop.loop import (
    Candidate,
    EffectReport,
    LoopReport,
    LoopSummary,
    RefusedEffect,
    SkippedCandidate,
    Stage,
    StageFit,
    Term,
    bic,
    f_test,
    optimistic_fit,
    run_loop,
)
from align.loop.structure import StructureReport, StructureTest, check_structure, periodogram_test

__all__ = [
    "Candidate", "EffectReport", "LoopReport", "LoopSummary", "RefusedEffect",
    "SkippedCandidate", "Stage", "StageFit",
    "StructureReport", "StructureTest", "Term", "bic", "f_test", "optimistic_fit",
    "periodogram_test", "run_loop", "check_structure",
]
