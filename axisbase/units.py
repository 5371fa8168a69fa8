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
