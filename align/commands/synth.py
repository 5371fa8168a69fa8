"""``align synth session`` (a synthetic session with known truth) and ``align demo`` (one
synthesised and run)."""

from __future__ import annotations

import argparse
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from align.commands.args import SEED, UsageError, effects
from align.commands.common import say, settings
from align.commands.parents import FMT, Parser, examples


def cmd_synth(args: argparse.Namespace) -> int:
    from synth.session import EFFECTS, write_session

    spec = _spec(args)
    out = Path(args.out)
    if args.force and out.exists() and any(out.iterdir()):
        remove_synth(out, "out")
    try:
        write_session(out, spec)
    except FileExistsError as exc:
        raise UsageError(f"{exc} (--force replaces a folder 'align synth' wrote)") from None
    except ValueError as exc:  # synth's refusal of an effect it cannot render
        raise UsageError(str(exc)) from None
    print(f"wrote session {args.out} (seed {args.seed}; truth in {out / 'truth.json'})")
    say(f"  effect {k} = {v} {EFFECTS[k][0]} "
        f"({'undeclared' if k in spec.undeclared else 'declared in session.toml'})"
        for k, v in spec.effects.items())
    return 0


def _spec(args: argparse.Namespace):
    """The session's effects from --effect and --undeclared."""
    from synth.session import EFFECTS, SessionSpec

    declared = effects(args.effect, "--effect", EFFECTS)
    undeclared = effects(args.undeclared, "--undeclared", EFFECTS)
    both = set(declared) & set(undeclared)
    if both:
        raise UsageError(f"--effect and --undeclared both name {', '.join(sorted(both))}")
    return SessionSpec(seed=args.seed, effects={**declared, **undeclared},
                       undeclared=frozenset(undeclared))


def remove_synth(folder: Path, flag: str) -> None:
    """--force replaces a synthetic session folder only if synth wrote it (it holds the
    truth.json synth writes): a folder of the user's own is never deleted."""
    if not (folder / "truth.json").is_file():
        raise UsageError(f"{flag} {folder}: not a session written by 'align synth' (no "
                         "truth.json); --force replaces only those — choose a new folder")
    shutil.rmtree(folder)


ROLL_ARCSEC = 30.0
"""The demo's undeclared roll of camera A [″]."""


def cmd_demo(args: argparse.Namespace) -> int:
    """Synthesise a session with known truth, run it, print the matrix and its error."""
    from align.commands.run import run_here, show_session
    from align.present import truth_lines
    from align.session import SessionJob, truth_errors
    from axisbase.errors import EXIT_INPUT, EXIT_OK

    folder = _demo_folder(args)
    truth = _write_demo(folder / "session", args.seed)
    out = run_here(SessionJob(str(folder / "session"), str(folder / "result.json"),
                              str(folder / "report.html"),
                              str(folder / "platform_calibration.json"), 1e-3, args.force,
                              settings=settings(args), keep_result=True))
    print()
    show_session({**out, "outputs": {}})
    if out["result"].fusion is not None:
        say(truth_lines(*truth_errors(out["result"].fusion, truth)))
    print()
    say(f"{k}: {v}" for k, v in out["outputs"].items())
    return EXIT_OK if out["ok"] else EXIT_INPUT


def _demo_folder(args: argparse.Namespace) -> Path:
    """--out (a previous demo's session replaced with --force), else a new temp folder."""
    folder = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="align-demo-"))
    if args.out and folder.exists() and any(folder.iterdir()):
        if not args.force:
            raise UsageError(f"--out {folder}: exists and is not empty; choose a new folder "
                             "or pass --force (a previous demo's session/ and outputs are "
                             "replaced)")
        if (folder / "session").exists():
            remove_synth(folder / "session", "--out")
    return folder


def _write_demo(session: Path, seed: int):
    from synth.session import SessionSpec, write_session

    print(f"demo: writing a synthetic session to {session} (seed {seed}): 8 mark images "
          "from two cameras (each with a reversal), a ring-laser counter log, a 14-pose "
          f"tumble and 8 platform poses; camera A rolled by {ROLL_ARCSEC:.0f}″, NOT declared")
    truth = write_session(session, SessionSpec(seed=seed,
                                               effects={"camera_roll_A": ROLL_ARCSEC},
                                               undeclared=frozenset({"camera_roll_A"})))
    with open(session / "session.toml", "a", encoding="utf-8") as f:  # the unit's identity
        f.write(f'\n[metadata]\nserial = "DEMO-{seed:04d}"\noperator = "align demo"\n')
    return truth


def add_synth(sub, parents: list[argparse.ArgumentParser]) -> None:
    sy = sub.add_parser("synth", help="write synthetic data with known truth",
                        description="write synthetic data with known truth",
                        formatter_class=FMT, epilog=examples(
                            "align synth session demo1 --seed 3 --effect camera_roll_A=30"))
    sy_sub = sy.add_subparsers(dest="what", required=True, parser_class=Parser)
    ss = sy_sub.add_parser("session", help="a complete synthetic session folder",
                           description="a complete synthetic session folder (images, "
                           "goniometer log, tumble, platform poses, session.toml, truth.json)",
                           formatter_class=FMT, parents=parents, epilog=examples(
                               "align synth session demo1 --seed 3 --effect camera_roll_A=30",
                               "align synth session demo2 --undeclared table_tilt_x=5"))
    ss.add_argument("out", help="new folder (must not exist or be empty)")
    ss.add_argument("--seed", type=SEED, default=0,
                    help="random seed (the same seed gives the same session)")
    ss.add_argument("--effect", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data and declared in session.toml (e.g. "
                    "camera_roll_A=30 [arcsec]; an unknown name lists them all)")
    ss.add_argument("--undeclared", action="append", default=[], metavar="NAME=VALUE",
                    help="an effect put into the data but not declared")
    ss.set_defaults(func=cmd_synth)


def add_demo(add: Callable[..., argparse.ArgumentParser]) -> None:
    d = add("demo", "synthesise a session with known truth and run it",
            epilog=examples("align demo", "align demo --out demo/ --seed 2"))
    d.add_argument("--out", help="folder for the session and outputs (default: a new temp folder)")
    d.add_argument("--seed", type=SEED, default=1, help="random seed")
    d.set_defaults(func=cmd_demo)
