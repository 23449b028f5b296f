"""Independent references for the measured-response waveforms (docs/design.md section 8).

Nothing here shares code with ``analytic``: the Gaussian from its
definition (math.erfc, mpmath), the EMG from the textbook density
(1/τ) e^{σ²/2τ² - u/τ} Φ(u/σ - σ/τ) and its cumulative in mpmath at 50
digits (where that form's cancellations are harmless), or SciPy's
``exponnorm`` for the fast QUADPACK references; the sampled response from
its trapezoids; the sech² pulse from its definition (math.cosh, mpmath's
tanh). Each is the *untruncated* pulse, unit peak.
"""

from __future__ import annotations

import functools
import math

import mpmath
import numpy as np
from scipy import optimize, stats

__all__ = ["sigma_of", "GaussianReference", "EmgReference", "Sech2Reference", "SampledReference", "reference_for"]

_DIGITS = 50


def sigma_of(fwhm: float) -> float:
    """σ of a Gaussian of that FWHM."""
    return fwhm / (2.0 * math.sqrt(2.0 * math.log(2.0)))


class GaussianReference:
    """s(t) = exp(-t²/2σ²)."""

    def __init__(self, fwhm: float):
        self.sigma = sigma_of(fwhm)
        self.peak_time = 0.0
        self.breakpoints = []

    def intensity(self, t):
        return math.exp(-t * t / (2 * self.sigma**2))

    def cumulative(self, u: float) -> float:
        """Fast (math.erfc): for QUADPACK references."""
        q = 1.0 / (self.sigma * math.sqrt(2.0))
        return self.sigma * math.sqrt(math.pi / 2) * math.erfc(-q * u)

    def kernel_mp(self, lower: float, upper: float):
        """∫_lower^upper s at 50 digits (erfc of each end's own sign: no cancellation)."""
        with mpmath.workdps(_DIGITS):
            s = mpmath.mpf(self.sigma)
            q = 1 / (s * mpmath.sqrt(2))
            c = s * mpmath.sqrt(mpmath.pi / 2)
            return c * (mpmath.erfc(-q * mpmath.mpf(upper)) - mpmath.erfc(-q * mpmath.mpf(lower)))


class EmgReference:
    """A Gaussian (σ, at 0) convolved with e^{-t/τ}/τ, divided by its peak."""

    def __init__(self, fwhm: float, tail: float):
        self.sigma = sigma_of(fwhm)
        self.tail = tail
        self.breakpoints = []
        shape = self.sigma / self.tail
        self._scipy = stats.exponnorm(1.0 / shape, scale=self.sigma) if shape < 30 else None
        # the mode: SciPy's density (another implementation) brackets it; the value at a flat top is exact
        found = optimize.minimize_scalar(lambda u: -self._density_mp(u), bounds=(-self.sigma, tail + self.sigma),
                                         method="bounded", options={"xatol": 1e-13 * (tail + self.sigma)})
        self.peak_time = float(found.x)
        with mpmath.workdps(_DIGITS):
            self.peak = self._density_mp(self.peak_time, float_result=False)

    def _density_mp(self, u, float_result=True):
        with mpmath.workdps(_DIGITS):
            s, tau, u = mpmath.mpf(self.sigma), mpmath.mpf(self.tail), mpmath.mpf(u)
            value = mpmath.exp(s**2 / (2 * tau**2) - u / tau) * mpmath.ncdf(u / s - s / tau) / tau
            return float(value) if float_result else value

    def _cdf_mp(self, u):
        s, tau, u = mpmath.mpf(self.sigma), mpmath.mpf(self.tail), mpmath.mpf(u)
        return mpmath.ncdf(u / s) - mpmath.exp(s**2 / (2 * tau**2) - u / tau) * mpmath.ncdf(u / s - s / tau)

    def intensity(self, t: float) -> float:
        with mpmath.workdps(_DIGITS):
            return float(self._density_mp(t, float_result=False) / self.peak)

    def cumulative_mp(self, u: float) -> float:
        with mpmath.workdps(_DIGITS):
            return float(self._cdf_mp(u) / self.peak)

    def kernel_mp(self, lower: float, upper: float):
        """∫_lower^upper s at 50 digits (the textbook cumulative's cancellations stay far below them)."""
        with mpmath.workdps(_DIGITS):
            return (self._cdf_mp(upper) - self._cdf_mp(lower)) / self.peak

    def cumulative(self, u: float) -> float:
        """Fast (SciPy's exponnorm, or the mpmath form when σ/τ is large): for QUADPACK references."""
        if self._scipy is None:
            return self.cumulative_mp(u)
        return float(self._scipy.cdf(u)) / float(self.peak)


class Sech2Reference:
    """s(t) = sech²(t/τ), τ = fwhm / (2 arccosh √2) (mpmath's acosh: not the model's constant)."""

    def __init__(self, fwhm: float):
        with mpmath.workdps(_DIGITS):
            self.tau_mp = mpmath.mpf(fwhm) / (2 * mpmath.acosh(mpmath.sqrt(2)))
        self.tau = float(self.tau_mp)
        self.peak_time = 0.0
        self.breakpoints = []

    def intensity(self, t):
        """sech²(x) = 4 e^{-2|x|} / (1 + e^{-2|x|})², which does not overflow far in the tails."""
        small = math.exp(-2.0 * abs(t) / self.tau)
        return 4.0 * small / (1.0 + small) ** 2

    def cumulative(self, u: float) -> float:
        """Fast (math.tanh of the end's own sign: no cancellation in either tail): for QUADPACK references."""
        if u <= 0.0:
            return self.tau * 2.0 / (1.0 + math.exp(-2.0 * u / self.tau))
        return 2.0 * self.tau - self.tau * 2.0 / (1.0 + math.exp(2.0 * u / self.tau))

    def cumulative_mp(self, u):
        with mpmath.workdps(_DIGITS):
            return self.tau_mp * (1 + mpmath.tanh(mpmath.mpf(u) / self.tau_mp))

    def kernel_mp(self, lower: float, upper: float):
        """∫_lower^upper s at 50 digits: τ (tanh(b/τ) - tanh(a/τ)), as e^{-2a/τ}-differences in the tails."""
        with mpmath.workdps(_DIGITS):
            t = self.tau_mp
            a, b = mpmath.mpf(lower) / t, mpmath.mpf(upper) / t
            # tanh(b) - tanh(a) = sinh(b - a) / (cosh a cosh b): no cancellation at either end
            return t * mpmath.sinh(b - a) / (mpmath.cosh(a) * mpmath.cosh(b))


class SampledReference:
    """Linear interpolation of samples, divided by the largest, 0 outside them."""

    def __init__(self, samples, width: float, start: float = 0.0):
        self.values = np.asarray(samples, dtype=np.float64) / np.max(samples)
        self.times = start + width * np.arange(len(samples))
        self.breakpoints = list(self.times)
        self.peak_time = float(self.times[np.argmax(self.values)])
        trapezoids = 0.5 * (self.values[1:] + self.values[:-1]) * np.diff(self.times)
        self.before = np.concatenate([[0.0], np.cumsum(trapezoids)])

    def intensity(self, t: float) -> float:
        return float(np.interp(t, self.times, self.values, left=0.0, right=0.0))

    def cumulative(self, u: float) -> float:
        if u <= self.times[0]:
            return 0.0
        if u >= self.times[-1]:
            return float(self.before[-1])
        i = int(np.searchsorted(self.times, u, side="right") - 1)
        return float(self.before[i] + 0.5 * (u - self.times[i]) * (self.values[i] + self.intensity(u)))


@functools.lru_cache(maxsize=32)
def _cached(name, key):
    if name == "gaussian":
        return GaussianReference(*key)
    if name == "emg":
        return EmgReference(*key)
    if name == "sech2":
        return Sech2Reference(*key)
    samples, width, start = key
    return SampledReference(np.array(samples), width, start)


def reference_for(illumination):
    """The reference pulse of an :class:`analytic.Illumination` of the three waveforms here."""
    if illumination.waveform == "gaussian":
        return _cached("gaussian", (illumination.fwhm,))
    if illumination.waveform == "emg":
        return _cached("emg", (illumination.fwhm, illumination.tail))
    if illumination.waveform == "sech2":
        return _cached("sech2", (illumination.fwhm,))
    width = (illumination.sample_width if illumination.sample_width is not None
             else illumination.sample_width_ps * 2.99792458e-4)
    return _cached("sampled", (tuple(illumination.samples), width,
                               0.0 if illumination.start is None else illumination.start))
