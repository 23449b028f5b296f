"""Illumination waveforms s(t) and the sampling kernels κ_n they induce.

A waveform is causal with support [0, duration] (duration 0 for the Dirac
impulse). Its cumulative S(u) = ∫_{-∞}^u s(t) dt is known in closed form, so
the box-prefiltered sample of light that left the plane at path length τ is

    κ_n(τ) = ∫_{t_n}^{t_{n+1}} s(t - τ) dt = S(t_{n+1} - τ) - S(t_n - τ),

exactly, with t_n = start + n T. Between the waveform's breakpoints
(``Waveform.breakpoints``) shifted to the bin edges, every κ_n is smooth in τ;
the quadrature of the system matrix splits its integrals there.

The Butterworth pulse is written as a sum of damped exponentials,
s(t) = Re Σ_i r_i exp(p_i t) over the poles p_i, so that S(u) is a finite sum
of e^{a u} (b cos ωu + c sin ωu) terms: NumPy, Numba and Dr.Jit evaluate the
same closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from .scene import Illumination, Sampling

__all__ = ["Waveform", "WaveformTerms", "make_waveform", "cumulative_scalar", "IMPULSE", "SQUARE",
           "EXPONENTIAL_SUM"]

#: How S(u) is evaluated (``Waveform.kind``).
IMPULSE, SQUARE, EXPONENTIAL_SUM = 0, 1, 2


class WaveformTerms(NamedTuple):
    """A waveform's closed form as a record that compiled (Numba) code accepts.

    S(u) = 0 for u <= 0; for 0 < u: ``kind`` IMPULSE: 1; SQUARE: min(u,
    duration); EXPONENTIAL_SUM: with v = min(u, duration), the Taylor
    series Σ_m series[m] v^m when v < series_limit, else
    constant + Σ_i e^{decay_i v} (cos_coefficient_i cos(frequency_i v)
    + sin_coefficient_i sin(frequency_i v)).
    """

    kind: int
    duration: float
    constant: float
    decay: np.ndarray
    frequency: np.ndarray
    cos_coefficient: np.ndarray
    sin_coefficient: np.ndarray
    series: np.ndarray
    series_limit: float


@njit(cache=True)
def cumulative_scalar(terms, u):
    """S(u) of :class:`WaveformTerms` at one path length u (metres), compiled."""
    if terms.kind == IMPULSE:
        return 1.0 if u > 0.0 else 0.0
    if terms.kind == SQUARE:
        return min(max(u, 0.0), terms.duration)
    if u <= 0.0:
        return 0.0
    if u > terms.duration:
        u = terms.duration
    if u < terms.series_limit:   # Taylor series near 0, where the exponentials cancel
        value = 0.0
        for m in range(terms.series.size - 1, -1, -1):
            value = value * u + terms.series[m]
        return value
    value = terms.constant
    for i in range(terms.decay.size):
        value += math.exp(terms.decay[i] * u) * (terms.cos_coefficient[i] * math.cos(terms.frequency[i] * u)
                                                 + terms.sin_coefficient[i] * math.sin(terms.frequency[i] * u))
    return value


@dataclass(frozen=True, eq=False)
class Waveform:
    """An intensity waveform s(t) of unit peak amplitude (unit area for the impulse).

    Attributes
    ----------
    name : str
        "impulse", "square" or "butterworth".
    kind : int
        IMPULSE, SQUARE or EXPONENTIAL_SUM: how ``cumulative`` is evaluated.
    duration : float
        Support [0, duration], metres of path length (0 for the impulse).
    breakpoints : tuple of float
        Times in [0, duration] where s(t) or its derivatives jump, metres.
    decay, frequency, cos_coefficient, sin_coefficient : numpy.ndarray
        For EXPONENTIAL_SUM: S(u) = constant + Σ e^{decay u}
        (cos_coefficient cos(frequency u) + sin_coefficient sin(frequency u))
        on [0, duration]; decay in 1/m, frequency in rad/m.
    constant : float
        See above.
    series : numpy.ndarray
        Taylor coefficients of S at 0, used for u < ``series_limit`` where the
        exponential sum cancels to S ~ u^order.
    series_limit : float
        Metres of path length.
    description : str
        Parameters in words, for reports and file headers.
    """

    name: str
    kind: int
    duration: float
    breakpoints: tuple
    decay: np.ndarray
    frequency: np.ndarray
    cos_coefficient: np.ndarray
    sin_coefficient: np.ndarray
    constant: float
    description: str
    series: np.ndarray = None
    series_limit: float = 0.0

    def cumulative(self, u) -> np.ndarray:
        """S(u) = ∫_{-∞}^u s(t) dt, u in metres of path length."""
        u = np.asarray(u, dtype=np.float64)
        if self.kind == IMPULSE:
            return (u > 0).astype(np.float64)
        if self.kind == SQUARE:
            return np.clip(u, 0.0, self.duration)
        clipped = np.clip(u, 0.0, self.duration)
        value = np.full(clipped.shape, self.constant)
        for a, w, b, c in zip(self.decay, self.frequency, self.cos_coefficient, self.sin_coefficient):
            value = value + np.exp(a * clipped) * (b * np.cos(w * clipped) + c * np.sin(w * clipped))
        # Near u = 0 the exponentials cancel to S ~ u^order: use the Taylor series there.
        small = clipped < self.series_limit
        if np.any(small):
            value = np.where(small, np.polynomial.polynomial.polyval(clipped, self.series), value)
        return np.where(u <= 0, 0.0, value)

    @property
    def terms(self) -> WaveformTerms:
        """The closed form as a :class:`WaveformTerms` record for compiled code."""
        series = self.series if self.series is not None else np.zeros(0)
        return WaveformTerms(self.kind, float(self.duration), float(self.constant), self.decay,
                             self.frequency, self.cos_coefficient, self.sin_coefficient, series,
                             float(self.series_limit))

    def intensity(self, t) -> np.ndarray:
        """s(t), radiant intensity in W/sr per unit source (not defined for the impulse)."""
        if self.kind == IMPULSE:
            raise ValueError("the impulse has no pointwise intensity; use cumulative()")
        t = np.asarray(t, dtype=np.float64)
        inside = (t >= 0) & (t <= self.duration)
        if self.kind == SQUARE:
            return inside.astype(np.float64)
        value = np.zeros(t.shape)
        for a, w, b, c in zip(self.decay, self.frequency, self.cos_coefficient, self.sin_coefficient):
            # d/dt of e^{at}(b cos wt + c sin wt)
            value = value + np.exp(a * t) * ((a * b + w * c) * np.cos(w * t) + (a * c - w * b) * np.sin(w * t))
        return np.where(inside, value, 0.0)

    @property
    def energy(self) -> float:
        """∫ s(t) dt, metres (W/sr times path length)."""
        return float(self.cumulative(self.duration + 1.0))

    def kernel(self, tau, sampling: Sampling) -> np.ndarray:
        """κ_n(τ) for every bin: ``(N,) + tau.shape`` (dimensionless x metres).

        Parameters
        ----------
        tau : array_like
            Path length at the plane's exit, metres.
        sampling : Sampling
            The bins.
        """
        tau = np.asarray(tau, dtype=np.float64)
        edges = sampling.edges.reshape((-1,) + (1,) * tau.ndim)
        upper = self.cumulative(edges[1:] - tau)
        lower = self.cumulative(edges[:-1] - tau)
        return upper - lower

    def bins_touched(self, period: float) -> int:
        """How many consecutive bins one path length can contribute to."""
        return int(math.ceil(self.duration / period)) + 1 if self.duration > 0 else 1


def _empty() -> np.ndarray:
    array = np.zeros(0)
    array.setflags(write=False)
    return array


def make_waveform(illumination: Illumination, period: float) -> Waveform:
    """The waveform of an illumination, with defaults resolved against the period.

    Parameters
    ----------
    illumination : Illumination
        Scene's ``[illumination]`` table.
    period : float
        Sampling period T, metres; sets the defaults (square width T/5,
        Butterworth cutoff 1/(2T) cycles per metre, duration 3/cutoff).

    Returns
    -------
    Waveform
    """
    if illumination.waveform == "impulse":
        return Waveform("impulse", IMPULSE, 0.0, (0.0,), _empty(), _empty(), _empty(), _empty(),
                        0.0, "Dirac impulse (unit area)")
    if illumination.waveform == "square":
        width = illumination.width if illumination.width is not None else period / 5.0
        return Waveform("square", SQUARE, width, (0.0, width), _empty(), _empty(), _empty(), _empty(),
                        0.0, f"square pulse, unit amplitude, width {width:.6g} m")
    return _butterworth(illumination, period)


def _butterworth(illumination: Illumination, period: float) -> Waveform:
    from scipy import optimize, signal

    order = illumination.order if illumination.order is not None else 3
    cutoff = illumination.cutoff if illumination.cutoff is not None else 0.5 / period
    duration = illumination.duration if illumination.duration is not None else 3.0 / cutoff
    numerator, denominator = signal.butter(order, 2.0 * math.pi * cutoff, analog=True)
    residues, poles, _ = signal.residue(numerator, denominator)

    def response(t):
        t = np.asarray(t, dtype=np.float64)
        return np.real(np.sum(residues[:, None] * np.exp(np.outer(poles, t.ravel())), axis=0)).reshape(t.shape)

    # Unit peak amplitude: locate the maximum of h on a grid, then polish it.
    grid = np.linspace(0.0, duration, 2049)
    start = grid[np.argmax(response(grid))]
    step = grid[1] - grid[0]
    best = optimize.minimize_scalar(lambda t: -response(t), bounds=(max(0.0, start - step),
                                    min(duration, start + step)), method="bounded",
                                    options={"xatol": 1e-14 * max(duration, 1e-300)})
    peak = float(response(best.x))
    coefficients = residues / poles / peak          # S(u) = Re Σ c_i (e^{p_i u} - 1)
    decay = np.real(poles).copy()
    frequency = np.imag(poles).copy()
    cos_coefficient = np.real(coefficients).copy()
    sin_coefficient = -np.imag(coefficients).copy()
    for array in (decay, frequency, cos_coefficient, sin_coefficient):
        array.setflags(write=False)
    constant = float(-np.sum(np.real(coefficients)))
    # Taylor series of S at 0: S^(m)(0) = h^(m-1)(0) = Re Σ c_i p_i^m, exactly 0 for
    # m < order (an all-pole filter of that order starts as t^(order-1)).
    terms = order + 24
    moments = np.array([np.real(np.sum(coefficients * poles**m)) for m in range(terms)])
    moments[:order] = 0.0
    series = moments / np.array([math.factorial(m) for m in range(terms)], dtype=np.float64)
    series.setflags(write=False)
    # below this u the series' first omitted term is under 1e-17 of S
    series_limit = 0.25 / float(np.max(np.abs(poles)))
    description = (f"Butterworth low-pass, order {order}, cutoff {cutoff:.6g} cycles/m, "
                   f"truncated at {duration:.6g} m, unit peak")
    return Waveform("butterworth", EXPONENTIAL_SUM, float(duration), (0.0, float(duration)),
                    decay, frequency, cos_coefficient, sin_coefficient, constant, description,
                    series, min(series_limit, float(duration)))
