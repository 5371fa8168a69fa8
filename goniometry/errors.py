"""Errors for bad counter logs (the CLI turns them into exit status 2)."""

from axisbase.errors import InputError


class LogError(InputError):
    """A log that cannot be used: the message names the file, the line and the problem."""


class FaceCountError(LogError):
    """The log's reference marks are ``found`` rows apart, not the ``named`` faces given.

    Parameters
    ----------
    path : str or Path
        The log.
    found : int
        Rows between most pairs of successive reference marks (pulses per revolution).
    named : int
        Faces the user named.
    share : int
        Revolutions that have ``found`` rows.
    revolutions : int
        Revolutions looked at.
    """

    def __init__(self, path, found: int, named: int, share: int, revolutions: int) -> None:
        self.path, self.found, self.named = path, found, named
        super().__init__(f"{path}: the log has {found} pulses per revolution (its reference "
                         f"marks are {found} rows apart in {share} of {revolutions} "
                         f"revolutions), but {named} faces are named")
