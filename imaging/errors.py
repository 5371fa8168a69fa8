"""Errors the imaging package raises for bad input (the CLI turns them into exit status 2)."""

from axisbase.errors import InputError


class ImageInputError(InputError):
    """An image that cannot be measured: the message names the file/region and the reason."""
