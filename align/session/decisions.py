"""What each stage decided: structure flagged, an effect added, u widened, refused.

Each stage's decisions are read from its own result (:func:`calibration_decisions`,
:func:`gonio_decisions`, :func:`mark_decisions`, :func:`fusion_decisions`), so a stage run
alone is judged as within a session (:func:`decisions`). The counts of these over clean
synthetic inputs are the false-alarm rates of the decisions (``docs/decisions.md``,
``tests/align/test_decision_rates.py``); on real data they say which stages called for
something. :func:`upper95` and :func:`alarm_limit` are the statistics of those counts.
"""

from __future__ import annotations

from collections.abc import Sequence

from scipy import special  # (not scipy.stats: 1 s to import; the same functions)

STAGES = ("calibration", "goniometer", "marks", "fusion")

EARTH_RATE = "earth_rate"
"""The goniometer loop's effect that every log taken on the Earth carries (not a false
effect when found)."""


def calibration_decisions(cal) -> dict[str, bool]:
    """A :class:`~align.calibration.Calibration`'s decisions: unexplained structure, an effect
    added (or the scale wander its poses' slopes show), u widened (structure or effect
    ambiguity), a significant effect refused by the physical checks (``refused effect``)."""
    return {"structure": bool(cal.loop.unexplained_structure),
            "effect": bool(cal.loop.effects) or _wander_found(cal),
            "widened": cal.widening is not None,
            "refused effect": bool(cal.loop.refused)}


def _wander_found(cal) -> bool:
    """The scale wander the poses' slopes showed (:mod:`align.calibration.wander`): an effect
    found in the data, corrected and carried in u."""
    w = (cal.stability or {}).get("wander")
    return bool(w and w["found"])


def gonio_decisions(run) -> dict[str, bool]:
    """A :class:`~align.gonio.GonioRun`'s decisions: unexplained structure in the revolution
    loop, an effect other than the Earth's rotation added, revolutions excluded as faulty
    (drop-outs, missing or spurious pulses: ``fault found``). (Its warnings are statements
    about the set-up — one direction on a table whose speed varies — not tests.)"""
    loop = run.loop
    return {"structure": bool(loop is not None and loop.unexplained_structure),
            "effect": bool(loop is not None
                           and any(e.name != EARTH_RATE for e in loop.effects)),
            "fault found": run.summary.excluded_revolutions > 0}


def mark_decisions(results: Sequence) -> dict[str, bool]:
    """Decisions over the :class:`~align.marks.MarkResult` of one image (or of a session's
    images): structure in a mark's line fit, an effect added, u inflated from the residual
    (``widened``), a mark not measured or more than the one expected (``refused``), and the
    lens's u over its limit (``lens-limited``: a statement about the declared lens, not a
    test on the data)."""
    found = [r for r in results if r.found]
    return {"structure": any(r.loop is not None and r.loop.unexplained_structure
                             for r in found),
            "effect": any(r.loop is not None and bool(r.loop.effects) for r in found),
            "widened": any(r.uncertainty_inflation > 1.0 for r in found),
            "refused": len(found) != len(results) or not found,
            "lens-limited": any(r.lens_limited for r in found)}


def fusion_decisions(fusion, refused: bool = False) -> dict[str, bool]:
    """A :class:`~align.fusion.FusionResult`'s decisions (None: it did not run): the
    residual's structure (chi2 or pattern; u then inflated), an effect added, refused (not
    run, ``refused`` given, or a gross disagreement) and a disagreeing source named."""
    if fusion is None:
        return {"structure": False, "effect": False, "refused": True,
                "source named": False}
    return {"structure": bool(fusion.loop.unexplained_structure),
            "effect": bool(fusion.loop.effects),
            "refused": refused or bool(fusion.gross),
            "source named": fusion.disagreement is not None}


def decisions(res) -> dict[str, dict[str, bool]]:
    """Per stage of a ``SessionResult``: unexplained structure flagged, an effect added, the
    stage refused (a stage error; the fusion also when it did not run or grossly disagrees)
    and, for the fusion, a disagreeing source named."""
    failed = {e.stage for e in res.errors}
    marks = [r for _, r in res.marks]
    cal = (calibration_decisions(res.calibration) if res.calibration is not None
           else {"structure": False, "effect": False})
    gon = (gonio_decisions(res.gonio) if res.gonio is not None
           else {"structure": False, "effect": False})
    mk = mark_decisions(marks) if marks else {"structure": False, "effect": False}
    return {
        "calibration": {"structure": cal["structure"], "effect": cal["effect"],
                        "refused": "calibration" in failed},
        "goniometer": {"structure": gon["structure"], "effect": gon["effect"],
                       "refused": "goniometer" in failed},
        "marks": {"structure": mk["structure"], "effect": mk["effect"],
                  "refused": any(s.startswith("mark") for s in failed)},
        "fusion": fusion_decisions(res.fusion, "fusion" in failed),
    }


def upper95(k: int, n: int) -> float:
    """One-sided 95 % Clopper-Pearson upper bound of a rate seen ``k`` times in ``n``."""
    return 1.0 if k >= n else float(special.betaincinv(k + 1, n - k, 0.95))


def alarm_limit(n: int, rate: float = 0.01, false_fail: float = 1e-3) -> int:
    """The most events in ``n`` cases a true ``rate`` shows but with probability below
    ``false_fail`` (one-sided binomial): a count above it says the rate exceeds ``rate``."""
    k = 0
    while special.bdtrc(k, n, rate) >= false_fail:  # P(X > k)
        k += 1
    return k
