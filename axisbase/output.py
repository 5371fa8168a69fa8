"""Every file the tool writes goes through here: strict JSON and outputs that are never lost.

* :func:`dumps` is the one JSON writer: numpy numbers and arrays become plain JSON, a
  non-finite float (NaN, ±inf) becomes ``null`` — never the bare ``NaN`` token that other JSON
  readers refuse (``allow_nan=False`` guards it).
* :class:`OutputPlan` checks every output of a command *before* anything is computed: no two
  outputs with the same path, none that is one of the inputs, none that exists already (unless
  ``force``), and its folder writable (a file is actually created there and removed).
* :func:`write_atomic` writes to a temporary name in the same folder and renames it into
  place. Without ``force`` the rename is exclusive (a hard link, which fails if the name
  appeared meanwhile, e.g. another run writing the same output): no run ever replaces a file
  it did not check. ``-`` as a JSON output means standard output.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from axisbase.errors import InputError
from axisbase.stop import stops_held

STDOUT = "-"


class OutputError(InputError):
    """An output cannot be written as asked (exists, collides, folder not writable, the disk
    full, the reader of a pipe gone)."""


def write_failed(where: str | Path, exc: OSError) -> OutputError:
    """The one-line error of a write that the system refused (ENOSPC, EPIPE, EACCES, EIO...):
    the path and the system's reason, for the CLI's exit status 2."""
    name = "standard output" if str(where) == STDOUT else str(where)
    reason = exc.strerror or type(exc).__name__
    if isinstance(exc, BrokenPipeError):
        reason = "its reader closed the pipe before the end"
    return OutputError(f"{name}: cannot be written ({reason}); the output is incomplete")


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON types: numpy scalars/arrays unwrapped, non-finite floats -> None,
    tuples -> lists, paths -> str."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    # exact built-in types out (subclasses such as numpy.float64 are not JSON to orjson)
    if obj is None or isinstance(obj, bool):
        return None if obj is None else bool(obj)
    if isinstance(obj, str):
        return str(obj)
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    tolist = getattr(obj, "tolist", None)  # numpy arrays and scalars (no numpy import here)
    if tolist is not None:
        return jsonable(tolist())
    if isinstance(obj, set | frozenset):
        return [jsonable(v) for v in sorted(obj)]
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def dumps(data: Any) -> str:
    """The tool's one JSON encoder (strict: no NaN/Infinity tokens; see :func:`jsonable`),
    indented, UTF-8 text. orjson, not the standard library: with ``indent`` the stdlib falls
    back to its pure-Python encoder, ~15x slower on a lot's or a session's result.

    Parameters
    ----------
    data : any
        Dicts, lists, tuples, sets, strings, numbers (non-finite: null), numpy arrays and
        scalars, paths (see :func:`jsonable`).

    Returns
    -------
    str
        The JSON text.
    """
    import orjson

    return orjson.dumps(jsonable(data), option=orjson.OPT_INDENT_2).decode() + "\n"


def _resolved(p: Path) -> Path | None:
    try:
        return p.resolve()
    except OSError:
        return None


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


class OutputPlan:
    """The outputs of one command, checked before the computation starts.

    Parameters
    ----------
    inputs : iterable of str or Path
        Files the command reads (an output may never be one of them).
    force : bool
        Existing outputs may be replaced.
    """

    def __init__(self, inputs: Iterable[str | Path] = (), force: bool = False):
        self.inputs = [Path(p) for p in inputs]
        self.force = force
        self.paths: dict[str, Path] = {}
        self.folders: set[str] = set()
        self._inputs_resolved: set[Path] | None = None

    def _resolved_inputs(self) -> set[Path]:
        """The inputs' real paths, resolved once (a lot has 10⁴ inputs and three outputs)."""
        if self._inputs_resolved is None:
            self._inputs_resolved = {r for r in map(_resolved, self.inputs) if r is not None}
        return self._inputs_resolved

    def add(self, flag: str, path: str | Path | None, stdout_ok: bool = False,
            folder: bool = False) -> Path | None:
        """Check one output (``flag`` names it in messages); returns its path, None when not
        asked for, or ``Path('-')`` for standard output. ``folder``: the output is a folder
        of per-item files (a batch), created if missing."""
        if path is None:
            return None
        if str(path) == STDOUT:
            if not stdout_ok:
                raise OutputError(f"{flag} -: standard output is only for --json")
            if any(str(p) == STDOUT for p in self.paths.values()):
                raise OutputError(f"{flag} -: another output already goes to standard output")
            self.paths[flag] = Path(STDOUT)
            return Path(STDOUT)
        if not folder and str(path).endswith(("/", os.sep)):
            raise OutputError(f"{flag} {path}: ends with '/', so it names a folder; give a "
                              "file name")
        p = Path(path)
        for other_flag, other in self.paths.items():
            # Folders of per-item files may be shared (the files' names differ).
            if folder and other_flag in self.folders:
                continue
            if str(other) != STDOUT and _same(p, other):
                raise OutputError(f"{flag} {p}: the same path as {other_flag}; each output "
                                  "needs its own file")
        if _resolved(p) in self._resolved_inputs():
            raise OutputError(f"{flag} {p}: is one of the inputs; refusing to write over it")
        if folder:
            if p.exists() and not p.is_dir():
                raise OutputError(f"{flag} {p}: exists and is not a folder")
            target_dir = p
        else:
            if p.is_dir():
                raise OutputError(f"{flag} {p}: is a folder; give a file name")
            if _is_special(p):  # /dev/stdout, a FIFO: written straight through
                self.paths[flag] = p
                return p
            if p.exists() and not self.force:
                raise OutputError(f"{flag} {p}: exists; choose a new name or pass --force")
            target_dir = p.parent
        _check_folder(flag, p, target_dir)
        self.paths[flag] = p
        if folder:
            self.folders.add(flag)
        return p


def _check_folder(flag: str, p: Path, folder: Path) -> None:
    """Create the folder if missing and prove it writable by creating a file in it."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{flag} {p}: {folder} is a file, not a folder") from None
    except OSError as exc:
        raise OutputError(f"{flag} {p}: cannot create the folder {folder} "
                          f"({exc.strerror})") from None
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise OutputError(f"{flag} {p}: the folder {folder} is not writable "
                          f"({exc.strerror})") from None


def write_atomic(path: str | Path, data: str | bytes, force: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder.

    Without ``force`` the file is created exclusively: if ``path`` exists (or appeared since
    the outputs were checked) nothing is replaced and :class:`OutputError` is raised. ``path``
    ``-`` writes text to standard output.

    Parameters
    ----------
    path : str or Path
        Where (``-``: standard output).
    data : str or bytes
        The contents.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The file exists (without ``force``) or cannot be written.
    """
    if str(path) == STDOUT:
        # A file format's bytes (UTF-8), whatever the console's encoding: through the
        # stream's binary buffer when it has one.
        out = _real_stdout()
        try:
            out.flush()
            buf = getattr(out, "buffer", None)
            if buf is not None:
                buf.write(data.encode("utf-8") if isinstance(data, str) else data)
                buf.flush()
            else:
                out.write(data if isinstance(data, str) else data.decode("utf-8"))
                out.flush()
        except OSError as exc:
            _silence(out)
            raise write_failed(STDOUT, exc) from None
        return Path(STDOUT)
    if _is_special(path):
        # A device or a named pipe (/dev/stdout, a FIFO): written straight through, never
        # replaced by a temporary file renamed over it.
        try:
            with open(path, "wb") as f:
                f.write(data.encode("utf-8") if isinstance(data, str) else data)
        except OSError as exc:
            raise write_failed(path, exc) from None
        return Path(path)
    with OutputSet(force) as out:
        out.stage(path, data)
        return out.commit()[0]


class OutputSet:
    """Files that appear all together or not at all (a session's JSON, report and
    calibration).

    :meth:`stage` writes each file to a temporary name in its own folder; :meth:`commit` then
    renames them into place in the order staged — exclusively unless ``force``, as
    :func:`write_atomic` — and, should one of them fail (it appeared meanwhile), removes the
    ones it had already put in place. A stop (SIGINT/SIGTERM, :mod:`axisbase.stop`) is held
    back during the commit, while a temporary file is created and recorded, and while the
    temporary files are removed. Temporary files are removed by :meth:`discard` (``with`` does it),
    so a run that is stopped or fails leaves nothing behind.

    Parameters
    ----------
    force : bool
        Existing files may be replaced.
    """

    def __init__(self, force: bool = False):
        self.force = force
        self._staged: list[tuple[Path, str]] = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, *exc: object) -> None:
        self.discard()

    def stage(self, path: str | Path, data: str | bytes) -> None:
        p = Path(path)
        raw = data.encode("utf-8") if isinstance(data, str) else data
        # A stop between the file's creation and its record here would leave it behind.
        try:
            with stops_held():
                fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=p.parent)
                self._staged.append((p, tmp))
            with os.fdopen(fd, "wb") as f:
                os.fchmod(f.fileno(), 0o666 & ~_umask())  # mkstemp's 0600 is for secrets
                f.write(raw)
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            raise write_failed(p, exc) from None

    def commit(self) -> list[Path]:
        """Put every staged file in place; returns their paths (:class:`OutputError` and
        nothing in place if one of them cannot be)."""

        done: list[Path] = []
        with stops_held():
            try:
                for p, tmp in self._staged:
                    if self.force:
                        os.replace(tmp, p)
                    else:
                        _link_exclusive(tmp, p)
                    done.append(p)
            except OSError as exc:
                if not self.force:
                    for p in done:
                        p.unlink(missing_ok=True)
                raise write_failed(self._staged[len(done)][0], exc) from None
            except BaseException:
                if not self.force:
                    for p in done:
                        p.unlink(missing_ok=True)
                raise
            finally:
                self.discard()
        return done

    def discard(self) -> None:
        """Remove the temporary files (those not committed)."""

        with stops_held():  # a second stop (the parent's end, say) must not cut this short
            for _, tmp in self._staged:
                if os.path.exists(tmp):
                    os.unlink(tmp)
            self._staged = []


def _link_exclusive(tmp: str, p: Path) -> None:
    """Rename ``tmp`` to ``p`` only if ``p`` does not exist (a hard link is atomic and
    exclusive; on a file system without them, check then rename)."""
    try:
        os.link(tmp, p)
    except FileExistsError:
        raise OutputError(f"{p}: appeared while this run was computing (another run writing "
                          "the same output?); not replaced — pass --force to replace it") from None
    except OSError:
        if p.exists():
            raise OutputError(f"{p}: appeared while this run was computing; not replaced — "
                              "pass --force to replace it") from None
        os.replace(tmp, p)
        return
    os.unlink(tmp)


def _is_special(path: str | Path) -> bool:
    """An existing output that is not a regular file (a character device, a FIFO)."""
    import stat

    try:
        return not stat.S_ISREG(os.stat(path).st_mode) and not os.path.isdir(path)
    except OSError:
        return False


def _silence(stream) -> None:
    """Send whatever ``stream`` still holds, and any later write, to the null device (a full
    or closed standard output must not fail again at exit)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
    except (OSError, ValueError, AttributeError):
        pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, data: Any, force: bool = False) -> Path:
    """Strict JSON (:func:`dumps`) written by :func:`write_atomic`.

    Parameters
    ----------
    path : str or Path
        Where (``-``: standard output).
    data : any
        What :func:`dumps` takes.
    force : bool
        Replace an existing file.

    Returns
    -------
    Path
        ``path``.
    """
    return write_atomic(path, dumps(data), force)


_STDOUT_STREAM: list = []


def set_real_stdout(stream) -> None:
    """Where ``-`` outputs go when the CLI has redirected its messages to stderr (None, at
    the end of its run: ``sys.stdout`` again)."""
    _STDOUT_STREAM[:] = [] if stream is None else [stream]


def _real_stdout():
    return _STDOUT_STREAM[0] if _STDOUT_STREAM else sys.stdout


def csv_text(names: Iterable[str], columns: Iterable, fmt: str = "%.10g",
             exact: Iterable[str] = ()) -> str:
    """A CSV table (header line + rows) of equal-length numeric columns, for
    :func:`write_atomic`; a column given as None is left blank on every row (a quantity the
    input did not have, e.g. times: never invented). Columns named in ``exact`` (times) are
    written as the shortest text that reads back to the very same float64 (``repr``), not with
    ``fmt``: a carried-through input value is never rounded (Unix-epoch times need 16 digits
    to keep microseconds; ``%.10g`` would merge 10 s of readings into one instant)."""
    import numpy as np

    names, columns, exact = list(names), list(columns), set(exact)
    if len(names) != len(columns):
        raise ValueError(f"{len(names)} names for {len(columns)} columns")
    texts: list = []
    n = None
    for name, c in zip(names, columns, strict=True):
        if c is None:
            texts.append(None)
            continue
        v = np.asarray(c, float).ravel()
        n = len(v) if n is None else n
        if len(v) != n:
            raise ValueError(f"column {name}: {len(v)} values, expected {n}")
        # float(x) first: repr of a numpy scalar is 'np.float64(...)' in numpy 2
        texts.append([repr(x) for x in map(float, v.tolist())] if name in exact else
                     [fmt % x for x in v.tolist()])
    blank = [""] * (n or 0)
    rows = zip(*(blank if t is None else t for t in texts), strict=True)
    return "\n".join([",".join(names), *(",".join(r) for r in rows)]) + "\n"
