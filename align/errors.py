"""Errors for bad input in align (the CLI turns them into exit status 2): the tool's one
hierarchy, from :mod:`axisbase.errors`."""

from axisbase.errors import AxisAlignError, InputError, InternalError, NotApplicable

__all__ = ["AxisAlignError", "InputError", "InternalError", "NotApplicable"]
