"""What each stage of a session decided: structure flagged, an effect added, refused.

The counts of these over clean synthetic sessions are the false-alarm rates of the decisions
(``benchmarks/clean_decisions.py``, ``tests/align/test_clean_decisions.py``); on real data
they say which stages called for something.
"""

from __future__ import annotations

STAGES = ("calibration", "goniometer", "marks", "fusion")


def decisions(res) -> dict[str, dict[str, bool]]:
    """Per stage of a ``SessionResult``: unexplained structure flagged, an effect added, the
    stage refused (a stage error; the fusion also when it did not run or grossly disagrees)
    and, for the fusion, a disagreeing source named."""
    failed = {e.stage for e in res.errors}
    marks = [r for _, r in res.marks]
    out = {
        "calibration": {
            "structure": bool(res.calibration and res.calibration.loop.unexplained_structure),
            "effect": bool(res.calibration and res.calibration.loop.effects),
            "refused": "calibration" in failed},
        "goniometer": {
            "structure": bool(res.gonio and res.gonio.loop
                              and res.gonio.loop.unexplained_structure),
            "effect": bool(res.gonio and res.gonio.loop and res.gonio.loop.effects),
            "refused": "goniometer" in failed},
        "marks": {
            "structure": any(r.loop is not None and r.loop.unexplained_structure
                             for r in marks),
            "effect": any(r.loop is not None and r.loop.effects for r in marks),
            "refused": any(s.startswith("mark") for s in failed)},
        "fusion": {
            "structure": bool(res.fusion and res.fusion.loop.unexplained_structure),
            "effect": bool(res.fusion and res.fusion.loop.effects),
            "refused": "fusion" in failed or res.fusion is None,
            "source named": bool(res.fusion and res.fusion.disagreement is not None)},
    }
    return out
