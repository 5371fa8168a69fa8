"""Alignment of an accelerometer triad: the residual loop, mark stage, CLI.

Public API::

    run_loop, Candidate, Term, StageFit, LoopReport   (align.loop: the shared residual loop)
    measure_file, measure_image, MarkResult           (scribe marks through the loop)
    measure_camera, LensRanges, solve_lens            (one lens per camera, docs/camera.md)
    with_grid_phase                                   (images blurred after the pixels, declared)
    measure_log                                       (a goniometer counter log's face angles)
    calibrate                                         (the triad from its static poses)
    load_session, run_session                         (a session folder, every stage, fused)

Each of ``measure_image``, ``measure_log``, ``calibrate`` and ``run_session`` carries a
runnable example (a doctest, run by ``tests/test_doctests.py``).

Names are loaded on first use (PEP 562): ``python -m align --help`` must not import numpy,
scipy or OpenCV.
"""

from importlib import import_module

_LAZY = {
    "Candidate": "align.loop", "LoopReport": "align.loop", "StageFit": "align.loop",
    "Term": "align.loop", "run_loop": "align.loop",
    "MarkResult": "align.marks", "MarkStage": "align.mark_stage", "loop_mark": "align.marks",
    "measure_file": "align.marks", "measure_image": "align.marks",
    "measure_camera": "align.marks", "LensRanges": "align.lens", "solve_lens": "align.lens",
    "with_grid_phase": "align.grid_phase",
    "measure_log": "align.gonio", "calibrate": "align.calibration",
    "load_session": "align.session", "run_session": "align.session",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'align' has no attribute {name!r}")
