"""One constant per unit. Inside the code everything is SI and radians; these convert at the
edges (CLI, reports, files): ``value_rad / ARCSEC`` is arc-seconds."""

import math

DEG = math.pi / 180.0
"""One degree [rad]."""
ARCMIN = DEG / 60.0
"""One arc-minute [rad]."""
ARCSEC = DEG / 3600.0
"""One arc-second [rad]."""
G0 = 9.80665
"""Standard gravity [m/s²] (the conventional value, used to convert g <-> m/s²)."""
MICRO_G = 1e-6
"""One micro-g [g]."""


# The one table of units that a file's header may declare (``t [ms]``, ``ux [mg]``): what a
# value in that unit is in the tool's own unit. Keys are lower case, without spaces.
TIME_UNITS = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3,
              "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "usec": 1e-6, "ns": 1e-9, "min": 60.0,
              "h": 3600.0, "hour": 3600.0}
"""A time unit -> seconds per unit."""

DECLARED_TIME_UNITS = ("s", "ms", "us", "ns", "min", "h")
"""The time units a user declares for a header that says none (``--time-unit``, the
session's ``time_unit``)."""

TEMPERATURE_UNITS = {
    **dict.fromkeys(("k", "kelvin"), (1.0, 0.0)),
    **dict.fromkeys(("degc", "°c", "℃", "c", "celsius", "deg_c"), (1.0, 273.15)),
    # °F: T [K] = (F + 459.67) · 5/9
    **dict.fromkeys(("degf", "°f", "℉", "f", "fahrenheit", "deg_f"), (5 / 9, 459.67 * 5 / 9))}
"""A temperature unit -> (kelvin per degree, offset [K]): T [K] = scale · value + offset."""

DECLARED_TEMPERATURE_UNITS = ("K", "degC", "degF")
"""The temperature units named in messages (each with its spellings in the table above)."""

VALUE_UNITS = {"g": ("g", 1.0), "mg": ("g", 1e-3), "ug": ("g", MICRO_G), "µg": ("g", MICRO_G),
               "μg": ("g", MICRO_G),
               "m/s2": ("m/s2", 1.0), "m/s^2": ("m/s2", 1.0), "m/s²": ("m/s2", 1.0),
               "ms-2": ("m/s2", 1.0), "mm/s2": ("m/s2", 1e-3), "mm/s^2": ("m/s2", 1e-3),
               "mm/s²": ("m/s2", 1e-3),
               "v": ("V", 1.0), "volt": ("V", 1.0), "volts": ("V", 1.0), "mv": ("V", 1e-3),
               "counts": ("counts", 1.0), "count": ("counts", 1.0), "lsb": ("counts", 1.0),
               "adc": ("counts", 1.0)}
"""An accelerometer output unit -> (the unit the tool computes in, its size in that unit)."""


def unit_key(text: str) -> str:
    """A header's unit as a key of the tables above: lower case, no spaces."""
    return text.strip().lower().replace(" ", "")


def time_scale(text: str) -> float | None:
    """Seconds per ``text`` (a time unit), None if it is not one."""
    return TIME_UNITS.get(unit_key(text))


def temperature_kelvin(text: str) -> tuple[float, float] | None:
    """``text`` (a temperature unit) as (kelvin per degree, offset [K]), None if it is not
    one: T [K] = scale · value + offset."""
    return TEMPERATURE_UNITS.get(unit_key(text))


def value_unit(text: str) -> tuple[str, float] | None:
    """``text`` (an output unit) as (the tool's unit, the size of one ``text`` in it)."""
    return VALUE_UNITS.get(unit_key(text))
