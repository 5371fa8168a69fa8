"""``align init`` (a commented session.toml for the instruments named) and ``align check``
(sessions checked without computing: every problem at once)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from align.commands.parents import examples
from axisbase.errors import EXIT_INPUT, EXIT_OK


def cmd_init(args: argparse.Namespace) -> int:
    from align.session.template import session_template, write_template

    cams = [c.strip() for c in args.cameras.split(",")] if args.cameras else []
    out = write_template(args.folder, session_template(cams, args.gonio, args.tumble,
                                                       args.static), args.force)
    print(f"wrote {out}: fill in the values marked FILL IN, put the files beside it, then "
          f"'align check {args.folder}'")
    return EXIT_OK


def cmd_check(args: argparse.Namespace) -> int:
    from align.session.check import check_session

    bad = False
    for folder in args.sessions:
        problems = check_session(folder)
        bad |= bool(problems)
        for line in problems:
            print(line)
        print(f"{folder}: " + (f"{len(problems)} problem(s)" if problems else "ready to run"))
    return EXIT_INPUT if bad else EXIT_OK


def add_init(add: Callable[..., argparse.ArgumentParser]) -> None:
    p = add("init", "write a commented session.toml for the instruments named",
            epilog=examples("align init unit42 --cameras A,B --gonio --tumble --static",
                            "align init unit43 --gonio --tumble"))
    p.add_argument("folder", help="the session folder (made if absent)")
    p.add_argument("--cameras", metavar="A,B", help="camera names (standard layout: the first "
                   "looks along +Y, the second along -X)")
    p.add_argument("--gonio", action="store_true", help="a ring-laser goniometer log")
    p.add_argument("--tumble", action="store_true", help="static tumble poses (calibration)")
    p.add_argument("--static", action="store_true", help="static readings on the platform")
    p.set_defaults(func=cmd_init)


def add_check(add: Callable[..., argparse.ArgumentParser]) -> None:
    p = add("check", "check sessions without computing: keys, files, headers, images",
            epilog=examples("align check unit42", "align check lot7/unit*"))
    p.add_argument("sessions", nargs="+", metavar="FOLDER", help="session folders")
    p.set_defaults(func=cmd_check)
