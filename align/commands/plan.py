"""``align plan``: what to measure next, from a session result."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.common import plan, say, settings, wrote
from align.commands.parents import examples


def cmd_plan(args: argparse.Namespace) -> int:
    from align.contract import document
    from align.plan import plan_from_result
    from align.session_json import LoadedSession
    from axisbase.output import dumps, write_atomic

    p = plan_from_result(LoadedSession.load(args.result))
    out = plan(args, [args.result]).add("--json", args.json, stdout_ok=True)
    say(p.lines())
    if out is not None:
        doc = document("plan", p.to_dict(), settings(args), [args.result])
        wrote(write_atomic(out, dumps(doc), args.force))
    return 0


def add_plan(add: Callable[..., argparse.ArgumentParser]) -> None:
    pl = add("plan", "what to measure next: the measurement that lowers u of the critical "
             "angle most per minute of work", epilog=examples(
                 "align plan result.json", "align plan result.json --json plan.json"))
    pl.add_argument("result", help="session result JSON ('align run --json')")
    pl.add_argument("--json", help="the plan as JSON ('-': stdout)")
    pl.set_defaults(func=cmd_plan)
