"""The one exception hierarchy of the tool.

* :class:`InputError` — input the user can fix (a file, a flag, a key); its message names
  where (``file:line: column``, ``--flag``, ``session.toml: [key]``, an image region) and what
  is wrong. The CLI prints it as one line and exits with status 2.
* :class:`InternalError` — a state the code should never reach; the CLI reports it as a bug
  (exit status 1).
* :class:`NotApplicable` — an effect that does not apply to these data; the residual loop
  skips that candidate and records why (anything else a candidate raises is a bug).

Each package derives its own input errors from :class:`InputError` (``LogError`` for counter
logs, ``ImageInputError`` for images), so one ``except InputError`` catches them all.
``InputError`` is also a ``ValueError`` for callers written against the older classes.
"""


EXIT_OK = 0
"""Exit status: success."""
EXIT_INTERNAL = 1
"""Exit status: an internal error (a bug to report)."""
EXIT_INPUT = 2
"""Exit status: bad input or usage, or a result that cannot be trusted (written, ``ok``
false)."""
EXIT_REJECTED = 3
"""Exit status with ``--fail-on-reject``: a verdict FAIL or INCONCLUSIVE (the result is
written and trustworthy; the unit does not conform, or cannot be shown to)."""
EXIT_INTERRUPTED = 130
"""Exit status: interrupted (Ctrl-C, SIGINT); a SIGTERM gives 143."""


class AxisAlignError(Exception):
    """Base of every error this tool raises on purpose."""


class InputError(AxisAlignError, ValueError):
    """Input the user can fix: the message names the file/line/key and what is wrong."""


class InternalError(AxisAlignError, RuntimeError):
    """A state the code should never reach (a bug to report)."""


class NotApplicable(AxisAlignError):
    """This effect does not apply to these data (no temperature column for a temperature
    term, more parameters than observations, a distortion that folds the image): a candidate
    of the residual loop that is skipped, with this message as the reason. Not a
    ``ValueError``: a defect raising one is not mistaken for a skipped effect."""


def internal_error(exc: BaseException) -> InternalError:
    """The :class:`InternalError` a defect ``exc`` becomes where one item (an image, a
    session's stage) is isolated so that the others go on: "internal error — please report
    (<type>: <message>)", caused by ``exc`` (its traceback goes to the log)."""
    bug = InternalError(f"internal error — please report ({type(exc).__name__}: {exc})")
    bug.__cause__ = exc
    return bug
