"""Argument types and checks shared by the commands: numbers in a range, signs, lists of
faces and angles, files given twice, option values that start with '-'.

Each turns a flag's text into a value or raises :class:`UsageError` naming the flag. Imports
nothing heavy (``align --help`` stays fast).
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable, Sequence
from pathlib import Path

from axisbase.errors import InputError

UNITS = ("g", "m/s2", "counts", "V")


def tolerance_limits(text: str) -> list[float]:
    """``--tolerance-arcsec``: "T" (±T) or "LO,HI" [″] relative to the nominal."""
    from align.decision import limits_arcsec

    try:
        return list(limits_arcsec(text, "--tolerance-arcsec", text=True))
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def scale_stability(text: str) -> float:
    """``--scale-stability-ppm``: the rule session.toml's key goes through too
    (:func:`align.calibration.stability.stability_ppm`)."""
    from align.calibration.stability import FLAG, stability_ppm

    try:
        return stability_ppm(float(text) if _is_number(text) else text, FLAG)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def nonlinearity_bound(text: str) -> tuple[float | None, float | None]:
    """``--nonlinearity-bound K2,K3`` [µg/g², µg/g³] -> (K2 [1/g], K3 [1/g²]): the rule
    session.toml's keys go through too (:mod:`align.calibration.nonlinearity`)."""
    from align.calibration.nonlinearity import parse_flag

    try:
        return parse_flag(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def add_decision_flags(p: argparse.ArgumentParser) -> None:
    """The tolerance and decision-rule flags of 'align run' and 'align lot'."""
    p.add_argument("--tolerance-arcsec", type=tolerance_limits, metavar="T|LO,HI",
                   help="tolerance on every angle [″]: ±T, or LO,HI relative to the nominal "
                   "(overrides session.toml [tolerance])")
    p.add_argument("--decision", choices=["simple", "guarded"],
                   help="decision rule: simple acceptance, or guarded with w = k·u (default: "
                   "session.toml's, else guarded)")
    p.add_argument("--guard-k", type=number(0, 10), metavar="K",
                   help="guard-band factor k of the guarded rule (default 2)")
    p.add_argument("--fail-on-reject", action="store_true",
                   help="exit status 3 when a verdict is FAIL or INCONCLUSIVE")


def decision_keywords(args: argparse.Namespace) -> dict:
    """The decision flags given, as :func:`align.decision.resolve`'s keywords."""
    out = {"tolerance": args.tolerance_arcsec, "rule": args.decision, "k": args.guard_k}
    return {k: v for k, v in out.items() if v is not None}


class UsageError(InputError):
    """Bad input the user can fix (exit status 2)."""


def number(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
           hi_open: bool = False, integer: bool = False, what: str = "") -> Callable:
    """An argparse type: a finite number (or integer) in [lo, hi] (open ends as asked)."""

    def parse(text: str) -> float | int:
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {'a whole number' if integer else 'a number'}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        low = lo is not None and (v <= lo if lo_open else v < lo)
        high = hi is not None and (v >= hi if hi_open else v > hi)
        if low or high:
            rng = (("(" if lo_open else "[") + ("-inf" if lo is None else f"{lo:g}") + ", "
                   + ("inf" if hi is None else f"{hi:g}") + (")" if hi_open else "]"))
            raise argparse.ArgumentTypeError(f"{text} outside {rng}{what}")
        return v

    return parse


ALPHA = number(0, 1, lo_open=True, hi_open=True, what=": a significance level 0 < α < 1")
POSITIVE = number(0, None, lo_open=True)
NON_NEGATIVE = number(0, None)
SEED = number(0, 2**63 - 1, integer=True)
MAX_PIXELS = number(256, 10**12, integer=True, what=": pixels (default 100000000)")


def add_max_pixels(parser: argparse.ArgumentParser) -> None:
    """``--max-pixels``: the image pixel budget, checked on each file's header before
    decoding (imaging.io)."""
    parser.add_argument("--max-pixels", type=MAX_PIXELS, metavar="N",
                        help="refuse an image declaring more than N pixels before decoding it "
                        "(default 100000000; also $ALIGN_MAX_PIXELS)")


def unique(items: Sequence[str], flag: str, what: str = "file") -> None:
    """Refuse the same file (after resolving) or name given twice."""
    seen: dict[str, str] = {}
    for it in items:
        key = str(Path(it).resolve()) if what == "file" else it
        if key in seen:
            raise UsageError(f"{flag}: {it} is given twice" + (
                f" (as {seen[key]})" if seen[key] != it else ""))
        seen[key] = it


def signs(text: str) -> tuple[float, float, float]:
    """``--scale-sign``: +, - or three of them (one per axis)."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) == 1:
        parts = parts * 3
    if len(parts) != 3 or any(p not in ("+", "-") for p in parts):
        raise UsageError(f"--scale-sign {text!r}: give +, - or three of them, e.g. -,-,-")
    return tuple(-1.0 if p == "-" else 1.0 for p in parts)  # type: ignore[return-value]


_SIGNS = re.compile(r"^[+-](,[+-])+$")

# Options whose value may start with '-' (signs; lists of numbers: a southern latitude range,
# a region of interest or nominal angles written with a negative first number).
_DASH_VALUES = {"--scale-sign": _SIGNS, "--adc-range": re.compile(r"^-\d"),
                "--latitude-range": re.compile(r"^-\d"), "--roi": re.compile(r"^-\d"),
                "--nominal": re.compile(r"^-\d")}


def attach_signs(argv: list[str]) -> list[str]:
    """``--scale-sign -,-,-`` (the documented form) as ``--scale-sign=-,-,-``, and
    ``--latitude-range -40,-30`` as ``--latitude-range=-40,-30``: argparse takes any value
    starting with '-' that is not a single negative number for an option, and has no setting
    to accept it as a value (only the ``=`` form)."""
    out, i = [], 0
    while i < len(argv):
        pattern = _DASH_VALUES.get(argv[i])
        if (pattern is not None and i + 1 < len(argv)
                and pattern.match(argv[i + 1].replace(" ", ""))):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def pattern(text: str) -> tuple[int, int]:
    """``--pattern COLSxROWS``: the inner corners of a chessboard."""
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"--pattern {text!r}: expected COLSxROWS inner corners, "
                         "e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise UsageError(f"--pattern {text!r}: a chessboard has at least 2x2 inner corners")
    return cols, rows


def faces(text: str) -> list[str]:
    """``--faces ref,z,y,x``: at least two distinct, non-empty names."""
    names = [f.strip() for f in text.split(",")]
    if any(not f for f in names):
        raise UsageError(f"--faces {text!r}: an empty face name")
    if len(names) < 2:
        raise UsageError("--faces needs at least two names, e.g. ref,z,y,x")
    unique(names, "--faces", what="name")
    return names


def nominal(text: str | None, n: int) -> list[float] | None:
    """``--nominal`` [deg]: ``n`` angles in (0, 360) summing to 360 (None when not given)."""
    if not text:
        return None
    try:
        deg = [float(v) for v in text.split(",")]
    except ValueError:
        raise UsageError(f"--nominal {text!r}: numbers in degrees") from None
    if len(deg) != n:
        raise UsageError(f"--nominal has {len(deg)} values for {n} faces")
    if not all(math.isfinite(v) and 0 < v < 360 for v in deg):
        raise UsageError(f"--nominal {text!r}: each angle must be in (0, 360) degrees")
    if abs(sum(deg) - 360) > 1e-6:
        raise UsageError(f"--nominal {text!r}: the angles of a full turn must sum to 360, "
                         f"not {sum(deg):g}")
    return deg


def face_plan(faces_text: str, nominal_text: str | None, log: str = ""
              ) -> tuple[list[str], list[float] | None]:
    """``--faces`` and ``--nominal`` parsed, and checked by the rule session.toml's
    ``[goniometer]`` also follows (:func:`align.face_plan.check_face_plan`: the reference face
    is no housing, faces x and y 90° apart), the message naming the log and the flags."""
    import numpy as np

    from align.face_plan import check_face_plan

    names = faces(faces_text)
    deg = nominal(nominal_text, len(names))
    where = f"{log}: " if log else ""
    check_face_plan(names, None if deg is None else np.deg2rad(deg),
                    f"{where}--faces {faces_text}",
                    f"{where}--nominal {nominal_text}" if nominal_text else
                    f"{where}--faces {faces_text} (without --nominal: {len(names)} equal angles)")
    return names, deg


def latitude_range(text: str) -> list[float]:
    """argparse type of ``--latitude-range LO,HI`` [deg]."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: two latitudes LO,HI in degrees") from None
    if not all(math.isfinite(v) and -90 <= v <= 90 for v in (lo, hi)) or lo > hi:
        raise argparse.ArgumentTypeError(f"{text}: need -90 <= LO <= HI <= 90")
    return [lo, hi]


def adc_range(text: str) -> tuple[float, float]:
    """argparse type of ``--adc-range LO,HI`` [the readings' unit]."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: two numbers LO,HI (the ADC's rails in "
                                         "the readings' unit)") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise argparse.ArgumentTypeError(f"{text}: need finite LO < HI")
    return lo, hi


def distinct_files(a: str, b: str, flag_a: str, flag_b: str) -> None:
    """Two inputs that must be different recordings: not the same file, not a copy."""
    from axisbase.provenance import sha256_file

    pa, pb = Path(a), Path(b)
    if pa.resolve() == pb.resolve():
        raise UsageError(f"{flag_b} {b}: is the same file as {flag_a}")
    try:
        same = (pa.stat().st_size == pb.stat().st_size and sha256_file(pa) == sha256_file(pb))
    except OSError:
        return  # the reader names the problem
    if same:
        raise UsageError(f"{flag_b} {b}: has the same contents as {flag_a} {a}; the other "
                         "direction is a different recording")


def effects(items: Sequence[str], flag: str, known: dict[str, tuple[str, str]]
            ) -> dict[str, float]:
    """``--effect NAME=VALUE`` (repeated): a value per effect ``known`` names."""
    out: dict[str, float] = {}
    for it in items:
        name, _, val = it.partition("=")
        if name not in known:
            raise UsageError(f"{flag} {name!r}: unknown effect; known: " + ", ".join(
                f"{k} [{u or '-'}] ({d})" for k, (u, d) in known.items()))
        if name in out:
            raise UsageError(f"{flag} {name}: given twice")
        try:
            out[name] = float(val)
        except ValueError:
            raise UsageError(f"{flag} {it!r}: expected NAME=NUMBER") from None
        if not math.isfinite(out[name]):
            raise UsageError(f"{flag} {it!r}: not a finite number")
    return out
