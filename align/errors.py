"""Errors for bad input in align (the CLI turns them into exit status 2)."""


class InputError(ValueError):
    """Input the user can fix: the message names the file/line/key and what is wrong."""
