"""A table format: its columns and rules (what :func:`axisbase.table.read_table` reads)."""

from __future__ import annotations

from dataclasses import dataclass

KINDS = ("float", "int", "label")
"""The kinds of a column."""


@dataclass(frozen=True)
class Column:
    """One column of a format.

    Attributes
    ----------
    name : str
        Canonical name (what the code and the messages call it).
    kind : str
        'float', 'int' or 'label'.
    required : bool
        Whether a file without it is refused.
    aliases : tuple of str
        Other header spellings accepted for it.
    """

    name: str
    kind: str = "float"
    required: bool = True
    aliases: tuple[str, ...] = ()


@dataclass(frozen=True)
class TableSpec:
    """A table format.

    Attributes
    ----------
    what : str
        What it is called in messages ("static poses", "counter log").
    columns : tuple of Column
        Its columns.
    time : str or None
        The column that must increase strictly (and that ``rate_hz`` may supply).
    distinct_rows : bool
        Refuse a file whose rows are each written twice, or which holds the same block of
        rows twice (see :func:`axisbase.repeats.check_repeats`).
    rate_hz_range : tuple of float, or None
        Plausible sample rates of the sensor [Hz] (see :func:`rate_warning`).
    temperature : str or None
        The temperature column: a unit in its header (``temp [degC]``) is converted to kelvin,
        an unknown one refused naming the column.
    """

    what: str
    columns: tuple[Column, ...]
    time: str | None = None
    distinct_rows: bool = False
    rate_hz_range: tuple[float, float] | None = None
    """Plausible sample rates of the sensor [Hz]: a median interval outside is a warning
    naming the likely time unit (see :func:`rate_warning`)."""
    temperature: str | None = None

    def column(self, name: str) -> Column:
        return next(c for c in self.columns if c.name == name)

    @property
    def layout(self) -> str:
        """The header a user should write, e.g. ``pose,ux,uy,uz[,t][,temp]``."""
        req = ",".join(c.name for c in self.columns if c.required)
        return req + "".join(f"[,{c.name}]" for c in self.columns if not c.required)
