"""The groove's depth profile across a mark and its extent along it, seen through the
optics' Gaussian point-spread function (the renders' :mod:`synth.marks` evaluate them at every
supersampled point).

Across: a ``box`` profile blurred is a difference of two error functions; ``v`` and ``round``
are convolved with the PSF numerically and tabulated once per (profile, width, blur). Along:
the groove's two ends, each an error function. Units: px.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.special import erf

from axisbase.interp import interp_uniform
from synth.specs import PROFILES

ERF_ONE = 6.0
"""Beyond this |z| scipy's erf is exactly +-1 in double precision (from 5.92 on)."""


def saturating_erf(z: np.ndarray) -> np.ndarray:
    """erf(z), bit for bit, evaluated only where |z| < :data:`ERF_ONE` (+-1 exactly beyond).

    A mark's profile along it is flat over most of its length and its tails across it
    reach zero: most supersampled points of a render are where erf is +-1 to the last bit
    (the along-profile's erf was ~12 s of the default test run's CPU, over whole marks)."""
    z = np.asarray(z, float)
    out = np.sign(z)
    near = np.abs(z) < ERF_ONE
    out[near] = erf(z[near])
    return out


def blurred_profile(profile: str, width: float, sigma: float):
    """Depth profile across the groove convolved with the Gaussian PSF, as a function of e."""
    if profile not in PROFILES:
        raise ValueError(f"unknown groove profile {profile!r}; use one of {PROFILES}")
    half = width / 2
    if profile == "box" and sigma > 0:
        s2 = np.sqrt(2) * sigma
        return lambda e: 0.5 * (saturating_erf((e + half) / s2)
                                - saturating_erf((e - half) / s2))

    if sigma <= 0:
        return functools.partial(_depth, profile, half)
    grid, blurred = _blurred_table(profile, float(width), float(sigma))
    # (np.interp's values, to the last bit, without its binary search per point)
    return lambda e: interp_uniform(e, grid, (blurred,))[0]


def _depth(profile: str, half: float, e: np.ndarray) -> np.ndarray:
    """The groove's depth profile (0..1) at ``e`` [px] across it, half-width ``half``."""
    z = np.clip(np.abs(e) / half, 0, 1)
    inside = np.abs(e) <= half
    if profile == "box":
        d = np.ones_like(e)
    elif profile == "v":
        d = 1 - z
    else:
        d = np.sqrt(1 - z * z)
    return np.where(inside, d, 0.0)


@functools.lru_cache(maxsize=64)
def _blurred_table(profile: str, width: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """The depth profile convolved with the PSF, tabulated (grid [px], value), read-only:
    kept for the next render of the same (profile, width, sigma), which every call depends
    on alone (a table is a ~2 M-term convolution, ~8 ms: the renders' CRLB asks for it 13
    times a mark, the tests' renders for a handful of grooves)."""
    half = width / 2
    step = min(0.004, width / 400, sigma / 20)
    reach = half + 7 * sigma
    grid = np.arange(-reach, reach + step / 2, step)
    kx = np.arange(-6 * sigma, 6 * sigma + step / 2, step)
    kern = np.exp(-0.5 * (kx / sigma) ** 2)
    kern /= kern.sum()
    # depth() sampled at cell midpoints integrates the discontinuity of the box/round edge.
    blurred = np.convolve(_depth(profile, half, grid), kern, mode="same")
    grid.setflags(write=False)
    blurred.setflags(write=False)
    return grid, blurred


def along_profile(length: float, sigma: float | np.ndarray):
    half = length / 2
    if np.ndim(sigma) == 0 and sigma <= 0:
        return lambda t: (np.abs(t) <= half).astype(float)
    s2 = np.sqrt(2) * sigma
    return lambda t: 0.5 * (saturating_erf((t + half) / s2) - saturating_erf((t - half) / s2))
