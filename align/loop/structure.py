"""Tests for structure left in fit residuals beyond noise.

Each test returns a p-value under the hypothesis "the residuals are independent noise of the
stated size". A report is *structured* when the smallest p-value is below ``alpha`` divided
by the number of tests (Bonferroni), so a clean fit is flagged with probability <= alpha.

When the residuals were whitened with a noise covariance *estimated* on ``nu`` degrees of
freedom (textured marks: from replicas of the band), they are independent only up to that
estimate's error, and each test takes it into its null distribution:

* chi2/dof against F(dof, nu) (the ratio of the residual's and the estimate's variances);
* a regressor correlation's t against Student t with min(n - 2, nu) dof (the residual's
  variance along a smooth regressor is the estimated spectrum's at low frequency, off by a
  chi2_nu / nu factor);
* a periodogram ordinate over the estimated spectrum: exp(-s) becomes (1 + 2 s / nu)^(-nu/2)
  (exponential over chi2_nu / nu);
* autocorrelations (Ljung–Box, runs): the whitening error adds to each residual
  autocorrelation a variance ~ (2 / nu) x the lag window's bandwidth (1.86 / M for a Parzen
  window of span M ~ n), i.e. their variance grows by 1 + 1.86 / nu (a Bartlett-type factor).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy import special  # (not scipy.stats: 1 s to import; the same functions)


@dataclass(frozen=True)
class StructureTest:
    name: str
    statistic: float
    p_value: float
    detail: str = ""


@dataclass(frozen=True)
class StructureReport:
    tests: tuple[StructureTest, ...]
    alpha: float

    @property
    def structured(self) -> bool:
        return bool(self.tests) and min(t.p_value for t in self.tests) < self.alpha / len(
            self.tests)

    @property
    def worst(self) -> StructureTest | None:
        return min(self.tests, key=lambda t: t.p_value) if self.tests else None


def _finite(nu: float | None) -> bool:
    return nu is not None and bool(np.isfinite(nu))


def chi2_test(z: np.ndarray, dof: int, nu: float | None = None) -> StructureTest:
    """Excess of sum(z^2) over its chi2(dof) distribution (z = residual / sigma); F(dof, nu)
    for chi2/dof when sigma was estimated on ``nu`` dof."""
    c = float(np.sum(z**2))
    k = max(dof, 1)
    p = special.fdtrc(k, nu, c / k) if _finite(nu) else special.chdtrc(k, c)
    return StructureTest("chi2", c / k, float(p), f"chi2/dof = {c / k:.3f} (dof {dof})")


def autocorrelation_inflation(nu: float | None) -> float:
    """Variance factor of residual autocorrelations whitened with a covariance estimated on
    ``nu`` dof (1 when the covariance is known; see the module's notes)."""
    return 1.0 + 1.86 / nu if _finite(nu) else 1.0


def runs_test(z: np.ndarray, inflation: float = 1.0) -> StructureTest:
    """Wald–Wolfowitz runs of signs: too few runs means residuals come in stretches."""
    s = z > np.median(z)
    n1, n2 = int(s.sum()), int((~s).sum())
    n = n1 + n2
    if n1 == 0 or n2 == 0:
        return StructureTest("runs", 0.0, 1.0)
    runs = 1 + int(np.count_nonzero(s[1:] != s[:-1]))
    mu = 2 * n1 * n2 / n + 1
    var = 2 * n1 * n2 * (2 * n1 * n2 - n) / (n * n * (n - 1))
    zz = (runs - mu) / np.sqrt(max(var * inflation, 1e-12))
    return StructureTest("runs", float(zz), float(special.ndtr(zz)),
                         f"{runs} runs, {mu:.1f} expected")


def ljung_box(z: np.ndarray, lags: int | None = None, inflation: float = 1.0
              ) -> StructureTest:
    """Ljung–Box portmanteau test of autocorrelation up to ``lags``."""
    n = len(z)
    h = lags or max(1, min(10, n // 5))
    x = z - z.mean()
    den = float(x @ x)
    if den == 0 or n < 4:
        return StructureTest("autocorrelation", 0.0, 1.0)
    rho = np.array([x[k:] @ x[:-k] / den for k in range(1, h + 1)])
    q = n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, h + 1))) / inflation
    return StructureTest("autocorrelation", float(q), float(special.chdtrc(h, q)),
                         f"lag-1 r = {rho[0]:+.3f}, Ljung-Box over {h} lags")


def _pearson(x: np.ndarray, z: np.ndarray, nu: float | None = None,
             dof: int | None = None) -> tuple[float, float]:
    """Pearson's r and its two-sided p-value (t with n - 2 dof: scipy.stats.pearsonr's;
    min(n - 2, nu) when the residual was whitened with a covariance estimated on nu dof;
    at most ``dof`` - 1 when ``z`` is a fit's residual with ``dof`` degrees of freedom).

    A residual lies in the fit's ``dof``-dimensional residual space, where its correlation
    with the part of ``x`` the fit leaves, (I - H) x, is Student's with dof - 1; its
    correlation with ``x`` itself is that one times |(I - H) x| / |x| <= 1, so t with
    dof - 1 bounds its tail (exact when ``x`` is orthogonal to the model). With n - 2 instead,
    a fit of 9 parameters to 14 poses (dof 5) called a |r| of 0.89 p 2.6e-5 where its tail
    is 1.7e-2: clean calibrations from per-sample files were flagged 2 in 300
    (docs/decisions.md)."""
    xc, zc = x - x.mean(), z - z.mean()
    den = float(np.sqrt((xc @ xc) * (zc @ zc)))
    if den == 0:
        return float("nan"), float("nan")
    r = float(np.clip(xc @ zc / den, -1, 1))
    n = len(x)
    if abs(r) == 1:
        return r, 0.0
    df = float(n - 2)
    if _finite(nu):
        df = min(df, float(nu))
    if dof is not None:
        df = min(df, float(max(dof - 1, 1)))
    t = r * np.sqrt(df / (1 - r * r))
    return r, float(2 * special.stdtr(df, -abs(t)))


def regressor_tests(z: np.ndarray, regressors: Mapping[str, np.ndarray],
                    nu: float | None = None, dof: int | None = None) -> list[StructureTest]:
    """Linear and quadratic correlation of the residual with each regressor (``dof``: the
    fit's residual degrees of freedom, see :func:`_pearson`)."""
    out = []
    for name, x in regressors.items():
        x = np.asarray(x, float)
        if len(x) != len(z) or np.ptp(x) == 0 or len(z) < 5:
            continue
        xc = (x - x.mean()) / x.std()
        for label, col in ((name, xc), (f"{name}^2", xc**2 - np.mean(xc**2))):
            if np.ptp(col) == 0:
                continue
            r, p = _pearson(col, z, nu, dof)
            out.append(StructureTest(f"corr({label})", float(r), float(p)))
    return out


FFT_ABOVE = 200  # points: above this an evenly spaced series gets the FFT periodogram


@functools.lru_cache(maxsize=16)
def _lomb_scargle(x: bytes, z: bytes, f_lo: float, f_hi: float, m: int) -> np.ndarray:
    """scipy's normalised Lomb-Scargle power of z (float64 bytes) at x over ``m`` frequencies
    f_lo..f_hi [cycles per unit of x], cached by value: a mark's residuals go through the
    same test up to three times (the loop's structure check before and after it, and the
    wiggle term's period), each call ~0.9 ms at 60 points."""
    from scipy import signal  # (here only: importing it costs ~1 s)

    xa, za = np.frombuffer(x), np.frombuffer(z)
    freqs = 2 * np.pi * np.linspace(f_lo, f_hi, m)
    p = np.concatenate([
        signal.lombscargle(xa, za - za.mean(), freqs[i:i + 1024], normalize=True,
                           floating_mean=True) for i in range(0, len(freqs), 1024)])
    p.flags.writeable = False
    return p


def periodogram_test(z: np.ndarray, x: np.ndarray, nu: float | None = None
                     ) -> tuple[StructureTest, float]:
    """Largest Lomb–Scargle peak against white noise, with the look-elsewhere correction
    (``nu``: dof of an estimated whitening covariance, see the module's notes).

    Returns the test and the peak's angular frequency [rad per unit of x].
    """
    n = len(z)
    span = float(np.ptp(x))
    if n < 8 or span == 0 or not np.ptp(z) > 0:  # (a constant residual has no spectrum)
        return StructureTest("periodogram", 0.0, 1.0), float("nan")
    spacing = span / (n - 1)
    dx = np.diff(x)
    if n > FFT_ABOVE and np.all(dx > 0) and np.ptp(dx) <= 0.25 * spacing:
        # Long, evenly spaced series: Lomb-Scargle costs n x 4n (and scipy's memory grows
        # with it — gigabytes at 10^4 points); on an even grid its normalised power is
        # 2 |X_k|^2 / (n sum (z - mean)^2), from an FFT (4x zero-padded).
        zc = z - z.mean()
        X = np.fft.rfft(zc, 4 * n)
        pw = 2 * np.abs(X) ** 2 / (n * float(zc @ zc))
        k0 = int(np.ceil(1.5 * 4 * n / (n - 1)))  # ~1.5 cycles over the span
        pw[:k0] = 0.0
        k = int(np.argmax(pw))
        power = float(np.clip(pw[k], 0, 1 - 1e-15))
        freq = 2 * np.pi * k / (4 * n * spacing)
    else:
        # From ~1.5 cycles over the span up to the Nyquist of the mean spacing.
        freqs = 2 * np.pi * np.linspace(1.5 / span, 0.5 / spacing, min(4 * n, 8192))
        p = _lomb_scargle(np.asarray(x, float).tobytes(), np.asarray(z, float).tobytes(),
                          1.5 / span, 0.5 / spacing, len(freqs))
        k = int(np.argmax(p))
        power = float(np.clip(p[k], 0, 1 - 1e-15))
        freq = float(freqs[k])
    s_exp = -0.5 * (n - 3) * np.log1p(-power)  # single-frequency tail exp(-s_exp)
    single = float(np.exp(-s_exp) if not _finite(nu) else
                   np.exp(-0.5 * nu * np.log1p(2 * s_exp / nu)))
    m_indep = max(1.0, (0.5 / spacing - 1.5 / span) * span)
    fap = float(-np.expm1(m_indep * np.log1p(-min(single, 1 - 1e-16))))
    return (StructureTest("periodogram", power, fap,
                          f"peak period {2 * np.pi / freq:.3g}, power {power:.3f}"),
            float(freq))


def check_structure(residuals: np.ndarray, sigma: np.ndarray | None, order: np.ndarray,
                   regressors: Mapping[str, np.ndarray], dof: int,
                   alpha: float = 1e-3, noise_dof: float | None = None,
                   sequence: bool = True) -> StructureReport:
    """Run every structure test on residuals ordered by the regressor ``order``.

    ``sigma`` None means the noise level is unknown: the chi2 test is skipped and the
    residuals are scaled by their RMS. ``noise_dof``: dof of an estimated whitening
    covariance (None: known). ``sequence`` False: the residuals are not independent in
    their order (the runs, Ljung–Box and periodogram tests would flag the fit's own
    correlations): those tests are left out.
    """
    r = np.asarray(residuals, float)
    if sigma is None:
        z = r / max(float(np.sqrt(np.mean(r**2))), 1e-300)
    else:
        z = r / np.asarray(sigma, float)
    idx = np.argsort(order, kind="stable")
    zs, xs = z[idx], np.asarray(order, float)[idx]
    nu = noise_dof
    infl = autocorrelation_inflation(nu)
    tests = [chi2_test(z, dof, nu)] if sigma is not None else []
    if sequence:
        tests += [runs_test(zs, infl), ljung_box(zs, inflation=infl),
                  periodogram_test(zs, xs, nu)[0]]
    tests += regressor_tests(z, regressors, nu, dof)
    return StructureReport(tuple(tests), alpha)
