"""Errors for bad counter logs (the CLI turns them into exit status 2)."""


class LogError(ValueError):
    """A log that cannot be used: the message names the file, the line and the problem."""
