"""Errors for bad counter logs (the CLI turns them into exit status 2)."""

from axisbase.errors import InputError


class LogError(InputError):
    """A log that cannot be used: the message names the file, the line and the problem."""
